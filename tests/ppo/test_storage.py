import pytest
import torch

from latentrl.ppo import RolloutBuffer
from tests.ppo.envs import CountingVecEnv

GAMMA, LAM = 0.9, 0.8


def fill(env: CountingVecEnv, num_steps: int, value: float = 0.0) -> RolloutBuffer:
    """Roll the counting env with a zero action and a constant value estimate."""
    buf = RolloutBuffer(num_steps, env.num_envs, 2, 1)
    obs, _ = env.reset()
    for t in range(num_steps):
        zeros = torch.zeros(env.num_envs)
        next_obs, reward, terminated, truncated, infos = env.step(torch.zeros(env.num_envs, 1))
        buf.insert(t, obs, zeros[:, None], zeros, zeros + value, reward, terminated, truncated, infos["final_obs"])
        obs = next_obs
    return buf


def expected_advantages(buf: RolloutBuffer, episode_length: int, last_step_delta: torch.Tensor) -> torch.Tensor:
    """V = 0, reward only at the episode's last step: A_t = (gamma lambda)^(steps to that end) * delta_end, or 0
    when the episode ends after the rollout."""
    T = buf.num_steps
    tau = buf.obs[..., 0]  # steps into the episode before step t
    to_end = episode_length - 1 - tau
    t = torch.arange(T)[:, None].expand_as(tau)
    inside = (t + to_end) < T
    return torch.where(inside, (GAMMA * LAM) ** to_end * last_step_delta, torch.zeros(()))


def test_gae_analytic_terminations():
    env = CountingVecEnv(num_envs=4, episode_length=5)
    buf = fill(env, 12)
    calls = []
    buf.compute_returns(torch.zeros(4), lambda o: calls.append(o) or torch.zeros(len(o)), GAMMA, LAM)
    assert not calls  # nothing truncated: the critic is not called
    assert buf.dones.sum() == int((buf.obs[..., 0] == 4).sum())
    assert torch.allclose(buf.advantages, expected_advantages(buf, 5, torch.ones(())))
    assert torch.allclose(buf.returns, buf.advantages)  # V = 0


def test_gae_constant_value_matches_hand_recursion():
    env = CountingVecEnv(num_envs=3, episode_length=4)
    c = 0.5
    buf = fill(env, 9, value=c)
    buf.compute_returns(torch.full((3,), c), lambda o: torch.full((len(o),), c), GAMMA, LAM)
    expected = torch.zeros(9, 3)
    for n in range(3):
        adv, next_value = 0.0, c
        for t in reversed(range(9)):
            not_done = 0.0 if buf.dones[t, n] else 1.0
            delta = float(buf.rewards[t, n]) + GAMMA * next_value * not_done - c
            adv = delta + GAMMA * LAM * not_done * adv
            expected[t, n], next_value = adv, c
    assert torch.allclose(buf.advantages, expected, atol=1e-6)
    assert torch.allclose(buf.returns, expected + c, atol=1e-6)


def test_truncation_bootstraps_final_obs_in_one_call():
    env = CountingVecEnv(num_envs=4, episode_length=5, truncate=True)
    buf = fill(env, 12)
    calls = []

    def value_fn(final_obs):
        calls.append(final_obs.clone())
        return 10.0 + final_obs[:, 1]  # identifiable: 10 + env index

    buf.compute_returns(torch.zeros(4), value_fn, GAMMA, LAM)
    assert len(calls) == 1 and len(calls[0]) == int(buf.time_outs.sum()) > 0
    assert torch.all(calls[0][:, 0] == 5)  # the observation that ended the episode, not the reset one
    delta_end = 1.0 + GAMMA * (10.0 + torch.arange(4.0))
    assert torch.allclose(buf.advantages, expected_advantages(buf, 5, delta_end), atol=1e-5)

    buf.compute_returns(torch.zeros(4), value_fn, GAMMA, LAM, bootstrap_truncated=False)  # DART: like terminal
    assert len(calls) == 1
    assert torch.allclose(buf.advantages, expected_advantages(buf, 5, torch.ones(())))


def test_missing_final_obs_disables_bootstrap():
    buf = RolloutBuffer(1, 2, 2, 1)
    zeros, true = torch.zeros(2), torch.ones(2, dtype=torch.bool)
    buf.insert(0, torch.zeros(2, 2), zeros[:, None], zeros, zeros, zeros, ~true, true, None)
    assert buf.dones.all() and not buf.time_outs.any()


@pytest.mark.parametrize("minibatch_size", [6, 8])
def test_minibatches_cover_each_transition_once_and_stay_aligned(minibatch_size):
    T, N = 4, 6
    buf = RolloutBuffer(T, N, 2, 1)
    t, n = torch.meshgrid(torch.arange(T), torch.arange(N), indexing="ij")
    ident = (100 * t + n).float()
    buf.obs[..., 0], buf.obs[..., 1] = t.float(), n.float()
    buf.actions[..., 0], buf.log_probs[:], buf.values[:] = ident, ident + 0.5, ident + 0.25
    buf.advantages[:], buf.returns[:] = -ident, ident + 0.75
    for _ in range(2):
        seen = []
        for batch in buf.minibatches(minibatch_size):
            key = 100 * batch.obs[:, 0] + batch.obs[:, 1]
            assert len(key) <= minibatch_size
            assert torch.equal(batch.actions[:, 0], key) and torch.equal(batch.log_probs, key + 0.5)
            assert torch.equal(batch.values, key + 0.25) and torch.equal(batch.advantages, -key)
            assert torch.equal(batch.returns, key + 0.75)
            seen += key.tolist()
        assert sorted(seen) == sorted(ident.flatten().tolist())
