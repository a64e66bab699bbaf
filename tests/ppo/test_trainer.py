import numpy as np
import pytest
import torch

from latentrl.errors import CheckpointError
from latentrl.monitor import EVAL_TRAJECTORIES, EvalReport
from latentrl.ppo import ActorCritic, NativeTrainer, load_policy, train
from latentrl.ppo.checkpoint import read_checkpoint
from tests.ppo.conftest import tiny_policy, tiny_ppo
from tests.ppo.envs import ReachVecEnv
from tests.ppo.helpers import OUR_SCALARS, SB3_SCALARS, scalars, tags

MOTION = {"path": "models/default.pt", "sha256": "a" * 64}


def env():
    return ReachVecEnv(8, max_episode_steps=6)


def test_two_iterations_write_sb3_tags_on_env_steps(tmp_path):
    run = tmp_path / "run"
    result = train(env(), run, tiny_ppo(), tiny_policy(), progress=False)
    assert (result.iterations, result.env_steps) == (2, 128)
    found = scalars(run)
    for tag in SB3_SCALARS + OUR_SCALARS:
        assert [step for step, _ in found[tag]] == [64, 128], tag
    assert found["train/learning_rate"][0][1] == pytest.approx(1e-3)  # annealed: (1 - k/K) lr
    assert found["train/learning_rate"][1][1] == pytest.approx(5e-4)
    assert "hyperparameters/text_summary" in tags(run)["tensors"]
    for name in ("config.yaml", "train.log", "final.pt", "checkpoints/iter_1.pt"):
        assert (run / name).is_file(), name
    assert "iter 2 | steps 128" in (run / "train.log").read_text()
    assert "learning_rate: 0.001" in (run / "config.yaml").read_text()


def test_same_seed_same_first_iteration_losses(tmp_path):
    def first(seed, name):
        return train(env(), tmp_path / name, tiny_ppo(total_steps=64, seed=seed), tiny_policy(), progress=False).train

    a, b, c = first(3, "a"), first(3, "b"), first(4, "c")
    assert a == b
    assert a["policy_gradient_loss"] != c["policy_gradient_loss"]


def test_resume_continues_step_count_and_curves(tmp_path):
    run, cfg = tmp_path / "run", tiny_ppo(total_steps=256)
    train(env(), run, cfg, tiny_policy(), progress=False)
    (run / "final.pt").unlink()  # as if killed during iteration 4, after iter_3.pt...
    (run / "checkpoints" / "iter_3.pt").unlink()  # ...or during iteration 3
    result = train(env(), run, cfg, tiny_policy(), resume=True, progress=False)
    assert (result.iterations, result.env_steps) == (4, 256)
    assert "start at iteration 2, 128 env steps" in (run / "train.log").read_text()
    assert [s for s, _ in scalars(run)["train/approx_kl"]] == [64, 128, 192, 256]  # killed run's 192, 256 purged
    assert read_checkpoint(run / "final.pt")["env_steps"] == 256


def test_corrupt_latest_checkpoint_falls_back_to_previous(tmp_path):
    run, cfg = tmp_path / "run", tiny_ppo(total_steps=256)
    train(env(), run, cfg, tiny_policy(), progress=False)
    (run / "final.pt").unlink()
    latest = run / "checkpoints" / "iter_3.pt"
    latest.write_bytes(latest.read_bytes()[:1000])  # truncated
    with pytest.raises(CheckpointError, match="corrupt or truncated"):
        read_checkpoint(latest)
    trainer = NativeTrainer(env(), run, cfg, tiny_policy(), progress=False)
    with pytest.warns(UserWarning, match="skipping unusable checkpoint.*iter_3.pt"):
        path = trainer.resume()
    assert path.name == "iter_2.pt" and (trainer.iteration, trainer.env_steps) == (2, 128)
    assert trainer.train().env_steps == 256


def test_resume_refuses_other_config_and_other_motion_model(tmp_path):
    run = tmp_path / "run"
    train(env(), run, tiny_ppo(), tiny_policy(), motion=MOTION, progress=False)
    with pytest.raises(CheckpointError, match=r"config differs.*ppo.learning_rate: 0.001 -> 0.0005"):
        NativeTrainer(env(), run, tiny_ppo(learning_rate=5e-4), tiny_policy(), motion=MOTION).resume()
    with pytest.raises(CheckpointError, match=r"policy.latent_dim: 32 -> 64"):
        NativeTrainer(env(), run, tiny_ppo(), tiny_policy(latent_dim=64), motion=MOTION).resume()
    NativeTrainer(env(), run, tiny_ppo(log_every=2), tiny_policy(), motion=MOTION).resume()  # harmless change
    other = {"path": "models/other.pt", "sha256": "b" * 64}
    with pytest.raises(CheckpointError, match="trained on motion model models/default.pt.*allow_motion_mismatch"):
        NativeTrainer(env(), run, tiny_ppo(), tiny_policy(), motion=other).resume()
    NativeTrainer(env(), run, tiny_ppo(), tiny_policy(), motion=other).resume(allow_motion_mismatch=True)
    with pytest.raises(CheckpointError, match="motion model"):
        load_policy(run / "final.pt", motion=other)
    assert load_policy(run / "final.pt", motion=other, allow_motion_mismatch=True).checkpoint["motion"] == MOTION


def test_checkpoint_contents_and_policy_reload(tmp_path):
    run = tmp_path / "run"
    trainer = NativeTrainer(env(), run, tiny_ppo(keep_checkpoints=1, total_steps=192), tiny_policy(obs_norm=True),
                            motion=MOTION, progress=False)
    trainer.train()
    assert sorted(p.name for p in (run / "checkpoints").iterdir()) == ["iter_2.pt"]  # keep the newest 1
    state = read_checkpoint(run / "final.pt")
    assert {"policy", "optimizer", "rng", "config", "config_hash", "motion", "iteration", "env_steps"} <= set(state)
    assert state["config"]["ppo"]["total_steps"] == 192 and state["motion"] == MOTION and "env" in state["rng"]
    assert state["policy"]["obs_normalizer.count"] == 192  # folded after each update
    loaded = load_policy(run / "final.pt")
    assert isinstance(loaded.policy, ActorCritic) and not loaded.policy.training
    obs = torch.randn(5, 13)
    with torch.no_grad():
        assert torch.equal(loaded.policy(obs).mean, trainer.policy(obs).mean)


def test_evaluation_hook_logs_and_keeps_training_stream(tmp_path):
    seen = []

    def evaluate(policy):
        seen.append(policy.training)
        torch.randn(100)  # consumes randomness: must not change training
        image = np.zeros((8, 8, 3), np.uint8)
        return EvalReport({"success_rate": 0.5, "reach_time_s": 2.0}, {EVAL_TRAJECTORIES: image})

    with_eval = train(env(), tmp_path / "a", tiny_ppo(eval_every=1), tiny_policy(), evaluate=evaluate, progress=False)
    without = train(env(), tmp_path / "b", tiny_ppo(eval_every=1), tiny_policy(), progress=False)
    assert seen == [False, False] and with_eval.train == without.train
    found = scalars(tmp_path / "a")
    assert [s for s, _ in found["eval/success_rate"]] == [64, 128]
    assert EVAL_TRAJECTORIES in tags(tmp_path / "a")["images"]
    assert with_eval.eval.metrics["reach_time_s"] == 2.0


def test_evaluation_can_stop_the_run_and_timings_are_reported(tmp_path):
    def evaluate(policy):
        return EvalReport({"success_rate": 0.95}, stop=True)

    result = train(env(), tmp_path, tiny_ppo(total_steps=256, eval_every=2), tiny_policy(), evaluate=evaluate,
                   progress=False)
    assert (result.iterations, result.env_steps, result.stopped_early) == (2, 128, True)
    assert read_checkpoint(result.final_checkpoint)["iteration"] == 2
    assert len(result.times) == 2 and all(t.collection_s > 0 and t.update_s > 0 for t in result.times)


def test_exported_policy_loads_without_optimizer(tmp_path):
    import torch

    from latentrl.ppo.checkpoint import export_policy, load_policy
    from latentrl.ppo.config import PolicyConfig, PPOConfig
    from latentrl.ppo.run import train
    from tests.ppo.envs import ReachVecEnv

    env = ReachVecEnv(num_envs=4)
    res = train(env, tmp_path / "run", PPOConfig(total_steps=64, num_steps=8, num_minibatches=2, update_epochs=1),
                PolicyConfig(latent_dim=16), progress=False)
    out = export_policy(res.final_checkpoint, tmp_path / "policy.pt")
    assert out.stat().st_size < res.final_checkpoint.stat().st_size
    loaded = load_policy(out)
    obs = torch.zeros(2, loaded.policy.obs_dim)
    action = loaded.policy.act(obs, deterministic=True).action
    assert action.shape == (2, loaded.policy.action_dim) and torch.isfinite(action).all()
    assert "optimizer" not in torch.load(out, weights_only=True)


def test_a_half_export_stores_weight_matrices_in_float16_and_acts_as_its_rounded_weights(tmp_path):
    import torch

    from latentrl.ppo.checkpoint import export_policy, load_policy
    from latentrl.ppo.config import PolicyConfig, PPOConfig
    from latentrl.ppo.run import train
    from tests.ppo.envs import ReachVecEnv

    env = ReachVecEnv(num_envs=4)
    res = train(env, tmp_path / "run", PPOConfig(total_steps=64, num_steps=8, num_minibatches=2, update_epochs=1),
                PolicyConfig(latent_dim=64), progress=False)
    full = export_policy(res.final_checkpoint, tmp_path / "full.pt")
    half = export_policy(res.final_checkpoint, tmp_path / "half.pt", half=True)
    assert half.stat().st_size < 0.7 * full.stat().st_size
    stored = torch.load(half, weights_only=True)["policy"]
    kinds = {(v.dtype, v.dim() == 2) for v in stored.values() if v.is_floating_point()}
    assert (torch.float16, True) in kinds and (torch.float32, False) in kinds and (torch.float32, True) not in kinds
    a, b = load_policy(full).policy, load_policy(half).policy  # the half copy's sha256 is its own: it loads
    assert all(p.dtype == torch.float32 for p in b.parameters())
    for name, p in b.state_dict().items():  # exactly the float32 weights rounded to float16
        assert torch.equal(p, a.state_dict()[name].half().float() if p.dim() == 2 else a.state_dict()[name])
    obs = torch.randn(8, a.obs_dim)
    ours, theirs = b.act(obs, deterministic=True).action, a.act(obs, deterministic=True).action
    assert 0 < (ours - theirs).abs().max() < 1e-2 * theirs.abs().max()
