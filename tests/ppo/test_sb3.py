import io

import numpy as np
import pytest
import torch
from stable_baselines3 import PPO

from latentrl.errors import CheckpointError, ConfigError
from latentrl.monitor import EvalReport
from latentrl.ppo import ActorCritic, load_policy, train
from latentrl.ppo.checkpoint import read_checkpoint
from latentrl.ppo.sb3 import IterationLinearSchedule, LatentActorCriticPolicy, Sb3Trainer, sb3_ppo_kwargs
from tests.ppo.conftest import tiny_policy, tiny_ppo
from tests.ppo.envs import REACH_LAYOUT, NumpyVecEnv, ReachVecEnv
from tests.ppo.helpers import OUR_SCALARS, SB3_SCALARS, scalars


def venv():
    return NumpyVecEnv(ReachVecEnv(8, max_episode_steps=6))


def test_two_iterations_write_the_same_tags_as_native(tmp_path):
    run = tmp_path / "run"
    result = train(venv(), run, tiny_ppo(), tiny_policy(), trainer="sb3", progress=False)
    assert (result.iterations, result.env_steps) == (2, 128)
    found = scalars(run)
    for tag in SB3_SCALARS + OUR_SCALARS:
        assert [step for step, _ in found[tag]] == [64, 128], tag
    # the native schedule lr_k = (1 - k/K) lr_0, k = 0, 1
    assert [v for _, v in found["train/learning_rate"]] == pytest.approx([1e-3, 5e-4])
    assert not any(tag.startswith("time/iterations") for tag in found)
    for name in ("config.yaml", "train.log", "final.pt", "final.sb3.zip", "checkpoints/iter_1.pt",
                 "checkpoints/iter_1.sb3.zip"):
        assert (run / name).is_file(), name
    model = PPO.load(run / "final.sb3.zip", device="cpu")  # SB3 users can load the zip directly
    assert isinstance(model.policy, LatentActorCriticPolicy)


def test_policy_reproduces_the_actor_critic():
    kwargs = sb3_ppo_kwargs(tiny_ppo(), tiny_policy(), tiny_ppo().plan(8), REACH_LAYOUT)
    model = PPO(LatentActorCriticPolicy, venv(), **kwargs)
    policy = model.policy
    assert isinstance(policy.net, ActorCritic) and policy.net.layout == REACH_LAYOUT
    assert {id(p) for p in policy.parameters()} == {id(p) for p in policy.net.parameters()}
    obs = torch.randn(4096, 13)
    with torch.no_grad():
        actions, values, log_prob = policy(obs)
        assert actions.shape == (4096, 4) and values.shape == (4096, 1) and log_prob.shape == (4096,)
        assert abs(actions.std() - 1.0) < 0.02  # zero init: the prior N(0, I)
        assert torch.equal(policy.log_std, torch.zeros(1, 4))
        v, lp, ent = policy.evaluate_actions(obs, actions)
        ev = policy.net.evaluate(obs, actions)
        assert torch.allclose(lp, log_prob, atol=1e-5) and torch.equal(lp, ev.log_prob) and torch.equal(ent, ev.entropy)
        assert torch.equal(policy.predict_values(obs), v)
        policy.net.actor_logstd.fill_(3.0)
        assert torch.equal(policy.log_std, torch.ones(1, 4))  # clamped to log_std_bounds
        dist = policy.get_distribution(obs[:3])
        assert torch.allclose(dist.distribution.stddev, torch.full((3, 4), np.e))
    mean, _ = policy.predict(obs[:3].numpy(), deterministic=True)
    assert np.abs(mean).max() <= 4.0


def test_config_mapping():
    cfg = tiny_ppo(clip_vloss=False, target_kl=0.03, anneal_lr=False)
    kwargs = sb3_ppo_kwargs(cfg, tiny_policy(), cfg.plan(8))
    assert (kwargs["n_steps"], kwargs["batch_size"], kwargs["n_epochs"]) == (8, 32, 2)
    assert kwargs["clip_range_vf"] is None and kwargs["target_kl"] == 0.03 and kwargs["learning_rate"] == 1e-3
    assert kwargs["vf_coef"] == 0.25 and kwargs["max_grad_norm"] == cfg.max_grad_norm
    schedule = IterationLinearSchedule(1.0, total_steps=100, batch_size=10, num_iterations=10)
    assert [schedule(1.0 - (k + 1) / 10) for k in range(3)] == pytest.approx([1.0, 0.9, 0.8])


def test_same_seed_same_first_iteration_losses(tmp_path):
    def first(name):
        return train(venv(), tmp_path / name, tiny_ppo(total_steps=64), tiny_policy(), trainer="sb3",
                     progress=False).train

    assert first("a") == first("b")


def test_resume_continues_and_refuses_the_other_trainer(tmp_path):
    run, cfg = tmp_path / "run", tiny_ppo(total_steps=256)
    train(venv(), run, cfg, tiny_policy(), trainer="sb3", progress=False)
    (run / "final.pt").unlink()
    (run / "checkpoints" / "iter_3.pt").unlink()
    result = train(venv(), run, cfg, tiny_policy(), trainer="sb3", resume=True, progress=False)
    assert (result.iterations, result.env_steps) == (4, 256)
    assert [s for s, _ in scalars(run)["train/approx_kl"]] == [64, 128, 192, 256]
    state = read_checkpoint(run / "final.pt")
    assert state["trainer"] == "sb3" and state["extra"]["num_timesteps"] == 256
    with pytest.raises(CheckpointError, match="--trainer sb3"):
        train(ReachVecEnv(8, max_episode_steps=6), run, cfg, tiny_policy(), resume=True, progress=False)


def test_final_checkpoint_is_our_format(tmp_path):
    trainer = Sb3Trainer(venv(), tmp_path, tiny_ppo(), tiny_policy(obs_norm=True), progress=False)
    trainer.train()
    loaded = load_policy(tmp_path / "final.pt")
    assert int(loaded.policy.obs_normalizer.count) == 128  # folded after each update, as natively
    obs = torch.randn(3, 13)
    with torch.no_grad():
        assert torch.equal(loaded.policy(obs).mean, trainer.model.policy.net(obs).mean)
    buf = io.BytesIO((tmp_path / "final.sb3.zip").read_bytes())
    assert PPO.load(buf, device="cpu").num_timesteps == 128


def test_wrong_env_kind_is_explained(tmp_path):
    with pytest.raises(ConfigError, match="Sb3VecEnv"):
        train(ReachVecEnv(8), tmp_path, tiny_ppo(), tiny_policy(), trainer="sb3", progress=False)
    with pytest.raises(ConfigError, match="not an SB3 VecEnv"):
        train(venv(), tmp_path, tiny_ppo(), tiny_policy(), trainer="native", progress=False)
    with pytest.raises(ConfigError, match="trainer: expected one of"):
        train(venv(), tmp_path, tiny_ppo(), tiny_policy(), trainer="jax", progress=False)


def test_evaluation_can_stop_the_run(tmp_path):
    seen = []

    def evaluate(policy):
        seen.append(type(policy).__name__)
        return EvalReport({"success_rate": 0.95}, stop=True)

    result = train(venv(), tmp_path, tiny_ppo(total_steps=256, eval_every=2), tiny_policy(), trainer="sb3",
                   evaluate=evaluate, progress=False)
    assert (result.iterations, result.env_steps, result.stopped_early) == (2, 128, True)
    assert seen == ["ActorCritic"] and len(result.times) == 2
    assert read_checkpoint(result.final_checkpoint)["extra"]["num_timesteps"] == 128
    assert [s for s, _ in scalars(tmp_path)["eval/success_rate"]] == [128]
