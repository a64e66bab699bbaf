"""``latentrl physics train-tracker`` and ``physics track --tracker``: stage 2's learned tracker (docs/physics.md)."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from latentrl.errors import ConfigError


@dataclass
class TrainTrackerRequest:
    """``latentrl physics train-tracker``: a config (or a run to resume) and the run directory."""

    config: str | None = None
    run_dir: str | None = None
    resume: str | None = None
    total_steps: int | None = None


def policy_actor(policy):
    """Observation (D,) -> deterministic action (A,) of a trained ``ActorCritic``."""
    import torch

    def act(obs: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            x = torch.as_tensor(obs, dtype=torch.float32)[None]
            return policy.act(x, deterministic=True).action[0].double().numpy()

    return act


def train_tracker_command(req: TrainTrackerRequest) -> int:
    """Train (or resume) a tracker with the native PPO runner; evaluate on held-out motions every ``eval_every``."""
    from latentrl.config import load_config, to_yaml
    from latentrl.monitor import EvalReport
    from latentrl.physics import require_mujoco
    from latentrl.physics.humanoid import build_humanoid
    from latentrl.physics.learned import TrackerTrainConfig, evaluate_tracker, evaluation_motions, training_motions
    from latentrl.physics.tracking_env import TrackingEnv
    from latentrl.ppo.trainer import NativeTrainer
    from latentrl.resources import config_file
    from latentrl.safe_io import atomic_write_text

    if req.resume:
        run_dir = Path(req.resume)
        if not (run_dir / "config.yaml").is_file():
            raise ConfigError(f"--resume {run_dir}: no config.yaml there; is it a train-tracker run directory?")
        overrides = [f"ppo.total_steps={req.total_steps}"] if req.total_steps else []
        cfg = load_config(TrackerTrainConfig, run_dir / "config.yaml", overrides)
    else:
        if not req.config:
            raise ConfigError("give a CONFIG file (e.g. physics/tracker) or --resume RUN_DIR")
        overrides = [f"ppo.total_steps={req.total_steps}"] if req.total_steps else []
        cfg = load_config(TrackerTrainConfig, config_file(req.config), overrides)
        run_dir = Path(req.run_dir or f"runs/tracker-{time.strftime('%Y%m%d-%H%M%S')}")
        if (run_dir / "config.yaml").is_file():
            raise ConfigError(f"--run-dir {run_dir} already holds a run; continue it with --resume {run_dir}")
    require_mujoco()
    run_dir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(run_dir / "config.yaml", to_yaml(cfg))
    t = cfg.tracking
    humanoid = build_humanoid(t.height)
    labels, motions = training_motions(t, humanoid)
    eval_labels, eval_motions = evaluation_motions(t, humanoid)
    env = TrackingEnv(humanoid, motions, t.num_envs, episode_frames=t.episode_frames,
                      terminate_distance=t.terminate_distance, action_scale=t.action_scale, assist_hz=t.assist_hz,
                      assist_final=t.assist_final, assist_anneal_steps=t.assist_anneal_steps)
    curve = run_dir / "eval.jsonl"
    trainer: NativeTrainer | None = None

    def evaluate(policy) -> EvalReport:
        res = evaluate_tracker(humanoid, eval_motions, eval_labels, policy_actor(policy), t, t.eval_assist)
        row = {"env_steps": trainer.env_steps if trainer else 0, "iteration": trainer.iteration if trainer else 0,
               "train_assist_scale": env.assist_scale, **{k: v for k, v in res.items() if k != "motions"},
               **({"episode_return": stats.ep_rew_mean, "episode_length": stats.ep_len_mean}
                  if (stats := trainer.rollout_stats()) else {})}
        with open(curve, "a", encoding="utf-8") as f:
            f.write(json.dumps(row, default=float) + "\n")
        return EvalReport({"success_rate": res["success"], "mpjpe_mm": res["mpjpe_mm"],
                           "assist_percent_body_weight": res["assist_percent_body_weight"],
                           "train_assist_scale": env.assist_scale})

    trainer = NativeTrainer(env, run_dir, cfg.ppo, cfg.policy, config=cfg, evaluate=evaluate, progress=False)
    if req.resume:
        trainer.resume()
        env.total_steps = trainer.env_steps  # the assist schedule continues where it stood
    result = trainer.train()
    print(f"trained {result.iterations} iterations ({result.env_steps} env steps) in {result.elapsed_s:.0f} s; "
          f"assist at {env.assist_scale:.2f} of full strength; wrote {result.final_checkpoint}; "
          f"held-out curve in {curve}")
    return 0


def load_tracker(path: str):
    """(policy, TrackerTrainConfig) of a train-tracker checkpoint; a one-line error when it is not one."""
    from latentrl.config import from_dict
    from latentrl.physics.learned import TrackerTrainConfig
    from latentrl.ppo.checkpoint import load_policy

    if not Path(path).is_file():
        raise ConfigError(f"--tracker {path}: no such checkpoint file")
    loaded = load_policy(path)
    saved = loaded.checkpoint.get("config") or {}
    if "tracking" not in saved:
        raise ConfigError(f"--tracker {path}: not a train-tracker checkpoint (its config has no 'tracking' section)")
    return loaded.policy, from_dict(TrackerTrainConfig, saved, f"--tracker {path}")


def track_with_tracker(clip, req, humanoid, ref):
    """Execute ``ref`` with the learned tracker of ``req.tracker``: a stage-1-shaped result and the report extra."""
    from latentrl.physics.learned import execute
    from latentrl.physics.reference import local_rotations
    from latentrl.physics.tracker import TrackResult
    from latentrl.physics.tracking_env import Character, Motion

    policy, cfg = load_tracker(req.tracker)
    t = cfg.tracking
    char = Character(humanoid, t.assist_hz, t.action_scale)
    motion = Motion.of(ref, humanoid)
    start = time.perf_counter()
    scale = req.assist_hz / t.assist_hz if t.assist_hz else 0.0
    run = execute(char, motion, policy_actor(policy), min(scale, 1.0))
    result = TrackResult(joints=run["joints"], rotations=local_rotations(run["world"]), soles=run["soles"],
                         fps=ref.fps, falls=run["falls"], assist_force=run["assist_force"], mass=humanoid.mass,
                         sim_seconds=time.perf_counter() - start)
    return result, {"tracker": str(req.tracker), "tracker_assist_scale": min(scale, 1.0)}
