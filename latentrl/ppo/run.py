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
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from latentrl.errors import ConfigError
from latentrl.ppo import checkpoint as ckpt
from latentrl.ppo import distributed
from latentrl.ppo.checkpoint import plain_config
from latentrl.ppo.config import PolicyConfig, PPOConfig
from latentrl.ppo.runner import Evaluator, Runner, TrainResult
from latentrl.ppo.trainer import NativeTrainer
from latentrl.preflight import MIB, NewOutput, check_free_space, check_writable
from latentrl.runlock import RunLock
from latentrl.safe_io import atomic_write_text

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


def _native(env: Any) -> type:
    if hasattr(env, "step_async"):
        raise ConfigError("trainer 'native' needs the torch VectorEnv itself, not an SB3 VecEnv adapter")
    return NativeTrainer


def _sb3(env: Any) -> type:
    from stable_baselines3.common.vec_env import VecEnv

    from latentrl.ppo.sb3 import Sb3Trainer

    if distributed.launched():
        raise ConfigError("trainer 'sb3' runs in one process only; use trainer 'native' under torchrun")
    if not isinstance(env, VecEnv):
        raise ConfigError(f"trainer 'sb3' needs an SB3 VecEnv (wrap the env: latentrl.envs.Sb3VecEnv(env)), "
                          f"got {type(env).__name__}")
    return Sb3Trainer


TRAINERS: dict[str, Callable[[Any], type]] = {"native": _native, "sb3": _sb3}
"""Trainer name -> a function of the env that checks it fits and returns the :class:`Runner` subclass."""


def register_trainer(name: str, select: Callable[[Any], type]) -> None:
    """Make ``trainer=name`` available: ``select(env)`` returns a :class:`Runner` subclass (or raises ConfigError)."""
    TRAINERS[name] = select


def make_trainer(env: Any, run_dir: str | Path, ppo: PPOConfig, policy: PolicyConfig, *, trainer: str = "native",
                 config: Any = None, motion: Mapping[str, Any] | None = None, evaluate: Evaluator | None = None,
                 layout: Mapping[str, Any] | None = None, progress: bool = True) -> Runner:
    """Build the trainer named ``trainer`` in :data:`TRAINERS` (native: torch ``VectorEnv``; sb3: SB3 ``VecEnv``)."""
    if trainer not in TRAINERS:
        raise ConfigError(f"trainer: expected one of {tuple(TRAINERS)}, got '{trainer}'")
    cls = TRAINERS[trainer](env)
    return cls(env, run_dir, ppo, policy, config=config, motion=motion, evaluate=evaluate, layout=layout,
               progress=progress)


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
        resume: continue the run in ``run_dir`` (a run killed before its first checkpoint restarts);
            temporary files a killed write left behind are removed.
        motion: ``{"path": str, "sha256": str}`` of the env's motion model (stored, checked on resume).
        evaluate: evaluation hook ``policy -> EvalReport``, called every ``ppo.eval_every`` iterations.
        layout: observation layout when the env's ``metadata`` does not carry ``observation_layout``.
        allow_motion_mismatch: resume onto a different motion model (experts only).
        progress: show the progress bar.

    Before anything is written, the run directory must be writable and its disk must hold
    :func:`disk_estimate` bytes (``ConfigError`` otherwise); a run directory this call creates is
    removed again if setting it up fails.
    """
    run_dir = Path(run_dir)
    config = config if config is not None else {"ppo": ppo, "policy": policy}
    check_writable(run_dir, "run directory")
    runner = make_trainer(env, run_dir, ppo, policy, trainer=trainer, config=config, motion=motion,
                          evaluate=evaluate, layout=layout, progress=progress)
    if not distributed.current().is_main:  # under torchrun rank 0 sets up (and locks) the run directory
        if not resume or runner.resume(allow_motion_mismatch=allow_motion_mismatch) is None:
            runner.warm_start()
        return runner.train()
    lock = RunLock(run_dir)
    with NewOutput(run_dir) as output:  # nothing is written before this point
        try:
            lock.acquire()  # before reading checkpoints: a live writer makes this fail at once
        except ConfigError:
            output.keep()  # the folder belongs to the process holding the lock
            raise
        try:
            if not resume or runner.resume(allow_motion_mismatch=allow_motion_mismatch) is None:
                runner.warm_start()  # ppo.init_from, for a run that starts at step 0
            check_free_space(run_dir, disk_estimate(runner), "run directory")
            if resume:
                ckpt.remove_temporaries(run_dir)
            if not resume or not (run_dir / CONFIG_FILE).is_file() or runner.extended_from is not None:
                write_config(run_dir, config)  # an extended run's config.yaml holds its new budget
        except BaseException:
            lock.release()
            raise
        output.keep()
    with lock:
        return runner.train()


def disk_estimate(runner: Any) -> int:
    """Bytes a run may still need: every kept checkpoint, ``final.pt`` and one write in flight, plus logs.

    A checkpoint holds the weights and Adam's two moments (3 x the parameters) plus about 1 MiB of
    RNG states and config; the SB3 trainer writes its own zip of the same size beside each.
    """
    cfg, plan = runner.cfg, runner.plan
    weights = sum(p.numel() * p.element_size() for p in runner.policy.parameters())
    per_file = 3 * weights + MIB
    if runner.name == "sb3":
        per_file *= 2
    remaining = plan.num_iterations - getattr(runner, "iteration", 0)
    saves = remaining // cfg.checkpoint_every if cfg.checkpoint_every else 0
    kept = min(saves, cfg.keep_checkpoints) if cfg.keep_checkpoints else saves
    # checkpoints already on disk (a resume) are pruned or replaced as the run goes on: their bytes count as free
    folder = Path(runner.run_dir)
    on_disk = sum(p.stat().st_size for p in [*ckpt.iteration_checkpoints(folder), folder / ckpt.FINAL] if p.is_file())
    return max((kept + 2) * per_file - on_disk, per_file) + 16 * MIB
