import torch

from latentrl.monitor import TRAIN_STATS
from latentrl.ppo import ActorCritic, RolloutBuffer
from latentrl.ppo.update import explained_variance, ppo_loss, ppo_update
from tests.ppo.conftest import tiny_policy, tiny_ppo
from tests.ppo.envs import REACH_LAYOUT


def rollout(seed: int = 0):
    """A policy and a buffer in which actions with a positive first component have advantage +1, others -1."""
    torch.manual_seed(seed)
    policy = ActorCritic(13, 4, tiny_policy(), REACH_LAYOUT)
    buf = RolloutBuffer(8, 16, 13, 4)
    with torch.no_grad():
        for t in range(8):
            obs = torch.randn(16, 13)
            step = policy.act(obs)
            zeros = torch.zeros(16, dtype=torch.bool)
            buf.insert(t, obs, step.action, step.log_prob, step.value, torch.zeros(16), zeros, zeros)
    buf.advantages[:] = torch.where(buf.actions[..., 0] > 0, 1.0, -1.0)
    buf.returns[:] = buf.values + 0.5
    return policy, buf


def test_first_minibatch_has_unit_ratio():
    policy, buf = rollout()
    terms = ppo_loss(policy, buf.flat(), tiny_ppo())
    assert abs(float(terms.approx_kl)) < 1e-6 and float(terms.clip_fraction) == 0.0
    assert abs(float(terms.policy_loss)) < 1e-5  # -mean(normalized advantages) with ratio 1
    assert torch.allclose(terms.value_loss, torch.tensor(0.25))  # (V - (V + 0.5))^2


def test_update_moves_the_policy_toward_positive_advantages():
    policy, buf = rollout()
    cfg = tiny_ppo(update_epochs=4, learning_rate=3e-3, max_grad_norm=1.0)
    obs = buf.flat().obs
    before_mean = policy(obs).mean[:, 0].mean().item()
    before_loss = ppo_loss(policy, buf.flat(), cfg).loss.item()
    stats = ppo_update(policy, torch.optim.Adam(policy.parameters(), lr=3e-3, eps=1e-5), buf, cfg, 64)
    assert policy(obs).mean[:, 0].mean().item() > before_mean + 0.01
    assert ppo_loss(policy, buf.flat(), cfg).loss.item() < before_loss
    assert set(TRAIN_STATS) - {"learning_rate"} <= set(stats)
    assert 0.0 <= stats["clip_fraction"] <= 1.0 and stats["approx_kl"] >= 0.0
    assert stats["epochs"] == 4 and stats["early_stop"] == 0.0 and stats["entropy_loss"] < 0


def test_large_steps_clip_and_target_kl_stops_early():
    policy, buf = rollout()
    cfg = tiny_ppo(update_epochs=10, learning_rate=3e-2, max_grad_norm=10.0)
    stats = ppo_update(policy, torch.optim.Adam(policy.parameters(), lr=3e-2), buf, cfg, 32)
    assert stats["clip_fraction"] > 0.05
    policy, buf = rollout()
    cfg = tiny_ppo(update_epochs=10, learning_rate=3e-2, max_grad_norm=10.0, target_kl=1e-4)
    stats = ppo_update(policy, torch.optim.Adam(policy.parameters(), lr=3e-2), buf, cfg, 32)
    assert stats["early_stop"] == 1.0 and stats["epochs"] < 10


def test_grad_norm_clipping_limits_the_step():
    def change(max_grad_norm: float) -> float:
        policy, buf = rollout()
        before = [p.detach().clone() for p in policy.parameters()]
        cfg = tiny_ppo(update_epochs=1, max_grad_norm=max_grad_norm)
        stats = ppo_update(policy, torch.optim.Adam(policy.parameters(), lr=1e-3, eps=1e-5), buf, cfg, 128)
        assert stats["grad_norm"] > 0
        return max((p.detach() - b).abs().max().item() for p, b in zip(policy.parameters(), before))

    assert change(1e-9) < 1e-5 < change(10.0)


def test_explained_variance():
    returns = torch.tensor([1.0, 2.0, 3.0, 4.0])
    assert explained_variance(returns, returns) == 1.0
    assert explained_variance(torch.full((4,), 2.5), returns) == 0.0
    assert torch.isnan(explained_variance(returns, torch.ones(4)))
