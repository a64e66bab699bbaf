import math

import pytest
import torch

from latentrl.errors import ConfigError
from latentrl.ppo import ActorCritic
from latentrl.ppo.normalizer import RunningNormalizer
from latentrl.ppo.policy import group_layout
from tests.ppo.conftest import tiny_policy
from tests.ppo.envs import REACH_LAYOUT

DART_LAYOUT = {"goal_dir": [0, 3], "goal_dist": [3, 4], "goal_text_embedding": [4, 516], "motion": [516, 1068],
               "scene": [1068, 1069]}


def test_dart_layout_groups_and_encoder_sizes():
    groups = group_layout(DART_LAYOUT, 1069)
    assert groups == {"goal": [(0, 4)], "text": [(4, 516)], "motion": [(516, 1068)], "scene": [(1068, 1069)]}
    policy = ActorCritic(1069, 256, tiny_policy(latent_dim=512, n_blocks=2), DART_LAYOUT)
    shapes = {k: tuple(v.shape) for k, v in policy.state_dict().items()}
    assert shapes["trunk.goal_encoder.layers.0.weight"] == (512, 4)
    assert shapes["trunk.text_encoder.layers.0.weight"] == (512, 512)
    assert shapes["trunk.motion_encoder.layers.0.weight"] == (512, 552)
    assert shapes["trunk.scene_encoder.layers.0.weight"] == (512, 1)
    assert shapes["trunk.embedding_encoder.layers.0.weight"] == (512, 2048)
    assert shapes["actor.layers.1.layers.1.weight"] == (512, 512)
    assert shapes["actor.out_fc.weight"] == (256, 512) and shapes["critic.out_fc.weight"] == (1, 512)
    assert shapes["actor_logstd"] == (1, 256)


def test_layout_fallbacks_and_errors():
    assert group_layout(None, 7) == {"obs": [(0, 7)]}
    assert group_layout({"goal": [0, 2], "extra": [2, 3], "goal_next": [3, 5]}, 5) == {
        "goal": [(0, 2), (3, 5)], "extra": [(2, 3)]}
    with pytest.raises(ConfigError, match="dim 4 is not covered"):
        group_layout({"goal": [0, 4]}, 5)
    with pytest.raises(ConfigError, match="covered twice"):
        group_layout({"goal": [0, 3], "text": [2, 5]}, 5)
    with pytest.raises(ConfigError, match="does not lie in"):
        group_layout({"goal": [0, 9]}, 5)


def test_non_contiguous_group_reads_its_dims():
    policy = ActorCritic(5, 2, tiny_policy(), {"goal": [0, 2], "extra": [2, 3], "goal_next": [3, 5]})
    obs = torch.randn(3, 5)
    changed = obs.clone()
    changed[:, 2] += 1.0  # only the 'extra' group sees dim 2
    enc = policy.trunk.goal_encoder
    assert torch.equal(enc(policy.trunk._take(obs, "goal")), enc(policy.trunk._take(changed, "goal")))
    assert policy.trunk._take(obs, "goal").shape == (3, 4)


@pytest.mark.parametrize("architecture", ["dart", "mlp"])
def test_shapes(architecture):
    policy = ActorCritic(13, 6, tiny_policy(architecture=architecture, mlp_hidden=[16, 16]), REACH_LAYOUT)
    obs = torch.randn(5, 13)
    step = policy.act(obs)
    assert step.action.shape == (5, 6) and step.log_prob.shape == (5,) and step.value.shape == (5,)
    ev = policy.evaluate(obs, step.action)
    assert ev.log_prob.shape == (5,) and ev.entropy.shape == (5,) and ev.value.shape == (5,)
    assert torch.allclose(ev.log_prob, step.log_prob)
    assert policy.value(obs).shape == (5,)


@pytest.mark.parametrize("architecture", ["dart", "mlp"])
def test_zero_init_samples_the_prior(architecture):
    torch.manual_seed(0)
    policy = ActorCritic(13, 64, tiny_policy(architecture=architecture), REACH_LAYOUT)
    obs = torch.randn(4096, 13) * 3
    with torch.no_grad():
        out = policy(obs)
    assert out.mean.abs().mean() < 0.02 and out.mean.abs().max() < 0.1  # 0.01-scaled layers: mean ~ 0
    assert torch.equal(out.log_std.exp(), torch.ones(1, 64))
    actions = policy.act(obs).action
    assert abs(actions.mean()) < 0.01 and abs(actions.std() - 1.0) < 0.01
    for m in policy.actor.modules():
        if isinstance(m, torch.nn.Linear):
            assert torch.all(m.bias == 0) and m.weight.abs().max() < 0.01


def test_without_zero_init_mean_is_not_small():
    torch.manual_seed(0)
    policy = ActorCritic(13, 64, tiny_policy(use_zero_init=False), REACH_LAYOUT)
    assert policy(torch.randn(256, 13) * 3).mean.abs().mean() > 0.05


def test_log_std_clamped_and_mean_bounded():
    policy = ActorCritic(13, 8, tiny_policy(), REACH_LAYOUT)
    with torch.no_grad():
        policy.actor_logstd[0, :4] = 5.0
        policy.actor_logstd[0, 4:] = -5.0
        policy.actor.out_fc.weight.normal_(0, 100.0)
    out = policy(torch.randn(64, 13) * 10)
    assert torch.equal(out.log_std, torch.tensor([[1.0] * 4 + [-1.0] * 4]))
    assert out.mean.abs().max() <= 4.0 and out.mean.abs().max() > 3.9
    deterministic = policy.act(torch.randn(3, 13), deterministic=True)
    assert deterministic.action.abs().max() <= 4.0


def test_log_prob_and_entropy_match_torch_normal():
    policy = ActorCritic(13, 5, tiny_policy(log_std_init=-0.3), REACH_LAYOUT)
    obs, actions = torch.randn(7, 13), torch.randn(7, 5) * 2
    with torch.no_grad():
        ev, out = policy.evaluate(obs, actions), policy(obs)
    ref = torch.distributions.Normal(out.mean, out.log_std.exp().expand_as(out.mean))
    assert torch.allclose(ev.log_prob, ref.log_prob(actions).sum(-1), atol=1e-5)
    assert torch.allclose(ev.entropy, ref.entropy().sum(-1), atol=1e-5)
    assert math.isclose(float(ev.entropy[0]), 5 * (0.5 + 0.5 * math.log(2 * math.pi) - 0.3), rel_tol=1e-5)


def test_spec_round_trip():
    policy = ActorCritic(13, 6, tiny_policy(obs_norm=True), REACH_LAYOUT)
    policy.update_normalizer(torch.randn(50, 13) * 2 + 1)
    clone = ActorCritic.from_spec(policy.spec())
    clone.load_state_dict(policy.state_dict())
    obs = torch.randn(4, 13)
    assert torch.equal(clone(obs).mean, policy(obs).mean) and torch.equal(clone.value(obs), policy.value(obs))


def test_normalizer_running_moments_and_frozen_forward():
    norm = RunningNormalizer(3, clip=100.0)
    chunks = [torch.randn(n, 3) * 4 + 2 for n in (10, 37, 5)]
    for chunk in chunks:
        norm.update(chunk)
    every = torch.cat(chunks)
    assert torch.allclose(norm.mean, every.mean(0), atol=1e-5)
    assert torch.allclose(norm.var, every.var(0, unbiased=False), atol=1e-4)
    assert int(norm.count) == 52
    before = {k: v.clone() for k, v in norm.state_dict().items()}
    out = norm(every)
    assert torch.allclose(out.mean(0), torch.zeros(3), atol=1e-5)
    assert all(torch.equal(before[k], v) for k, v in norm.state_dict().items())


def test_policy_forward_never_updates_normalizer():
    policy = ActorCritic(13, 6, tiny_policy(obs_norm=True, obs_norm_clip=5.0), REACH_LAYOUT)
    obs = torch.randn(8, 13) * 50
    policy.act(obs)
    policy.evaluate(obs, torch.zeros(8, 6))
    assert int(policy.obs_normalizer.count) == 0
    assert policy.normalize(obs).abs().max() <= 5.0
    assert "obs_normalizer.mean" in policy.state_dict()
