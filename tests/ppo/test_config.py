from dataclasses import dataclass, field

import pytest

from latentrl.config import load_config, to_dict
from latentrl.errors import ConfigError
from latentrl.ppo import PolicyConfig, PPOConfig


@dataclass
class _Train:
    ppo: PPOConfig = field(default_factory=PPOConfig)
    policy: PolicyConfig = field(default_factory=PolicyConfig)


def test_defaults_are_darts():
    p, q = PPOConfig(), PolicyConfig()
    assert (p.num_steps, p.num_minibatches, p.update_epochs, p.learning_rate, p.anneal_lr) == (32, 8, 10, 3e-4, True)
    assert (p.gamma, p.gae_lambda, p.clip_coef, p.clip_vloss, p.ent_coef, p.vf_coef) == (0.99, 0.95, 0.2, True, 0, 0.5)
    assert (p.max_grad_norm, p.target_kl, p.norm_adv, p.adam_eps, p.seed) == (0.1, None, True, 1e-5, 1)
    assert (q.architecture, q.latent_dim, q.n_blocks, q.use_zero_init, q.action_scale) == ("dart", 512, 2, True, 4.0)
    assert (q.log_std_init, tuple(q.log_std_bounds), q.obs_norm) == (0.0, (-1.0, 1.0), False)


def test_dart_plan():
    plan = PPOConfig().plan(256)
    assert (plan.batch_size, plan.minibatch_size, plan.num_minibatches, plan.num_iterations) == (8192, 1024, 8, 24415)
    assert PPOConfig(minibatch_size=512).plan(256).num_minibatches == 16


def test_plan_errors_name_value_and_fix():
    with pytest.raises(ConfigError, match="num_envs: must be > 0, got 0"):
        PPOConfig().plan(0)
    with pytest.raises(ConfigError, match=r"num_minibatches: 7 does not divide .* = 8192; try 8"):
        PPOConfig(num_minibatches=7).plan(256)
    with pytest.raises(ConfigError, match=r"minibatch_size: 1000 does not divide"):
        PPOConfig(minibatch_size=1000).plan(256)


@pytest.mark.parametrize(("cls", "kwargs", "message"), [
    (PPOConfig, {"learning_rate": -1e-3}, "learning_rate: must be > 0, got -0.001"),
    (PPOConfig, {"gamma": 1.5}, "gamma: must lie in"),
    (PPOConfig, {"target_kl": 0.0}, "target_kl"),
    (PolicyConfig, {"architecture": "transformer"}, "architecture: expected one of"),
    (PolicyConfig, {"log_std_bounds": (1.0, -1.0)}, "log_std_bounds"),
    (PolicyConfig, {"log_std_init": 2.0}, "log_std_init"),
])
def test_validate_messages(cls, kwargs, message):
    with pytest.raises(ConfigError, match=message):
        cls(**kwargs).validate()


def test_nested_yaml_and_overrides(tmp_path):
    path = tmp_path / "run.yaml"
    path.write_text("ppo:\n  learning_rate: 1.0e-4\n  target_kl: 0.02\npolicy:\n  architecture: mlp\n"
                    "  log_std_bounds: [-2.0, 0.5]\n")
    cfg = load_config(_Train, path, ["ppo.num_steps=16", "policy.mlp_hidden=[64,64]"])
    assert cfg.ppo.learning_rate == 1e-4 and cfg.ppo.target_kl == 0.02 and cfg.ppo.num_steps == 16
    assert cfg.policy.architecture == "mlp" and tuple(cfg.policy.log_std_bounds) == (-2.0, 0.5)
    assert to_dict(cfg)["policy"]["mlp_hidden"] == [64, 64]
    with pytest.raises(ConfigError, match="learning_rat"):
        load_config(_Train, path, ["ppo.learning_rat=1"])
    with pytest.raises(ConfigError, match="ppo.learning_rate: must be > 0"):
        load_config(_Train, path, ["ppo.learning_rate=-1"])
