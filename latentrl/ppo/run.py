"""Entry point the CLI calls: set up a run directory and train with the native or the SB3 trainer.

Run directory::

    <run_dir>/config.yaml                 resolved config (written on a fresh start)
    <run_dir>/events.out.tfevents.*       TensorBoard (x-axis: env steps; tags in latentrl.monitor)
    <run_dir>/checkpoints/iter_<N>.pt     every ppo.checkpoint_every iterations, newest ppo.keep_checkpoints kept
    <run_dir>/checkpoints/iter_<N>.sb3.zip   (sb3 trainer) SB3's own zip beside each checkpoint
    <run_dir>/final.pt                    at the end (+ final.sb3.zip for sb3)
    <run_dir>/train.log                   one line per logged iteration, appended across resumes
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from latentrl.errors import ConfigError
from latentrl.ppo.checkpoint import plain_config
from latentrl.ppo.config import PolicyConfig, PPOConfig
from latentrl.ppo.trainer import Evaluator, NativeTrainer, TrainResult
from latentrl.safe_io import atomic_write_text

TRAINERS = ("native", "sb3")
CONFIG_FILE = "config.yaml"


def write_config(run_dir: str | Path, config: Any) -> Path:
    """Save the resolved config as ``<run_dir>/config.yaml`` (atomically)."""
    if dataclasses.is_dataclass(config):
        from latentrl.config import to_yaml

        text = to_yaml(config)
    else:
        import yaml

        text = yaml.safe_dump(plain_config(config), sort_keys=False)
    return atomic_write_text(Path(run_dir) / CONFIG_FILE, text)


def make_trainer(env: Any, run_dir: str | Path, ppo: PPOConfig, policy: PolicyConfig, *, trainer: str = "native",
                 config: Any = None, motion: Mapping[str, Any] | None = None, evaluate: Evaluator | None = None,
                 layout: Mapping[str, Any] | None = None, progress: bool = True):
    """Build a :class:`NativeTrainer` (torch ``VectorEnv``) or an ``Sb3Trainer`` (SB3 ``VecEnv``)."""
    if trainer not in TRAINERS:
        raise ConfigError(f"trainer: expected one of {TRAINERS}, got '{trainer}'")
    kwargs = dict(config=config, motion=motion, evaluate=evaluate, layout=layout, progress=progress)
    if trainer == "native":
        if hasattr(env, "step_async"):
            raise ConfigError("trainer 'native' needs the torch VectorEnv itself, not an SB3 VecEnv adapter")
        return NativeTrainer(env, run_dir, ppo, policy, **kwargs)
    from stable_baselines3.common.vec_env import VecEnv

    from latentrl.ppo.sb3 import Sb3Trainer

    if not isinstance(env, VecEnv):
        raise ConfigError(f"trainer 'sb3' needs an SB3 VecEnv (wrap the env: latentrl.envs.Sb3VecEnv(env)), "
                          f"got {type(env).__name__}")
    return Sb3Trainer(env, run_dir, ppo, policy, **kwargs)


def train(env: Any, run_dir: str | Path, ppo: PPOConfig, policy: PolicyConfig, *, trainer: str = "native",
          config: Any = None, resume: bool = False, motion: Mapping[str, Any] | None = None,
          evaluate: Evaluator | None = None, layout: Mapping[str, Any] | None = None,
          allow_motion_mismatch: bool = False, progress: bool = True) -> TrainResult:
    """Train a policy in ``run_dir``; with ``resume`` continue from its newest readable checkpoint.

    Args:
        env: torch ``VectorEnv`` for 'native'; SB3 ``VecEnv`` adapter of it for 'sb3'.
        run_dir: run directory (created if needed).
        ppo: the ``ppo:`` config section.
        policy: the ``policy:`` config section.
        trainer: 'native' or 'sb3'.
        config: the full resolved config (dataclass or dict) saved as ``config.yaml`` and in every
            checkpoint; resume refuses a checkpoint whose config differs (default: the two sections).
        resume: continue the run in ``run_dir`` (a run killed before its first checkpoint restarts).
        motion: ``{"path": str, "sha256": str}`` of the env's motion model (stored, checked on resume).
        evaluate: evaluation hook ``policy -> EvalReport``, called every ``ppo.eval_every`` iterations.
        layout: observation layout when the env's ``metadata`` does not carry ``observation_layout``.
        allow_motion_mismatch: resume onto a different motion model (experts only).
        progress: show the progress bar.
    """
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    config = config if config is not None else {"ppo": ppo, "policy": policy}
    runner = make_trainer(env, run_dir, ppo, policy, trainer=trainer, config=config, motion=motion,
                          evaluate=evaluate, layout=layout, progress=progress)
    if resume:
        runner.resume(allow_motion_mismatch=allow_motion_mismatch)
    if not resume or not (run_dir / CONFIG_FILE).is_file():
        write_config(run_dir, config)
    return runner.train()
