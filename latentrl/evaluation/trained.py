"""What a policy checkpoint says about how it was trained: its env config and its motion model.

``latentrl eval``, ``latentrl play`` and ``latentrl export onnx`` all read these, so a policy trained on
any motion model runs without its ``--motion`` repeated, and a command refuses a task it cannot run by name.
"""

from __future__ import annotations

from pathlib import Path

from latentrl.envs.settings import StepSettings


def stored_env(policy: str | Path):
    """The ``EnvConfig`` stored in a policy checkpoint, or None (no config, or a file the loaders will refuse)."""
    from latentrl.envs.config import stored_env_config
    from latentrl.errors import LatentRLError
    from latentrl.ppo.checkpoint import read_checkpoint

    try:
        state = read_checkpoint(policy, map_location="cpu")
        env = stored_env_config(state.get("config"))
    except (LatentRLError, OSError):
        return None
    return _with_trained_file(env, (state.get("motion") or {}).get("sha256"))


def _with_trained_file(env, sha256: str | None):
    """The stored env, its embedded motion name swapped for the one now holding the file it was trained on.

    "default" was v2 until 2026-11-26 and is v5 since; a policy that stored "default" with v2's hash runs on
    "default-v2" (by hash, so no name has to be remembered). Files and names that still match are kept.
    """
    import dataclasses

    from latentrl.motion.checkpoint import EMBEDDED_MODELS, embedded_name_for, embedded_sha256

    name = motion_of(env)
    if env is None or not sha256 or name not in EMBEDDED_MODELS or embedded_sha256(name) in (None, sha256):
        return env
    moved = embedded_name_for(sha256)
    return dataclasses.replace(env, motion=moved) if moved else env


def stored_step_settings(config) -> StepSettings:
    """How a checkpoint's training env stepped the motion (its ``config``; defaults where it stores no env).

    ``latentrl play`` and ``latentrl export onnx`` read it here, ``latentrl eval`` through
    :meth:`~latentrl.evaluation.config.EvalSettings.take_training_env`: one reading for all.
    """
    from latentrl.envs.config import stored_env_config

    return StepSettings.of(stored_env_config(config))


EVAL_CHOICES = ("foot_lock_min_weight", "refine", "refine_horizon", "refine_skate", "refine_start", "refine_pace",
                "refine_land", "avoid", "avoid_horizon", "avoid_margin", "avoid_samples", "sit_plan",
                "sit_plan_samples", "sit_plan_getup", "sit_plan_approach", "route")
"""The ``eval:`` settings a checkpoint stores that ``latentrl eval`` takes as its defaults (flags override)."""


def stored_eval_choices(policy: str | Path) -> dict:
    """The evaluation settings a policy's card figures were taken with (its stored ``eval:`` section; None left out).

    A policy trained with the foot lock at 0.5 but judged with it at 0.05 stores ``eval.foot_lock_min_weight``,
    so ``latentrl eval POLICY`` reproduces the card without the flag. A file the loaders refuse gives ``{}``.
    """
    from latentrl.errors import LatentRLError
    from latentrl.ppo.checkpoint import read_checkpoint

    try:
        section = (read_checkpoint(policy, map_location="cpu").get("config") or {}).get("eval") or {}
    except (LatentRLError, OSError, AttributeError):
        return {}
    return {name: section[name] for name in EVAL_CHOICES if isinstance(section, dict) and section.get(name) is not None}


def motion_of(env) -> str:
    """The motion model a stored ``EnvConfig`` names ('default' when there is none)."""
    return (env.motion if env is not None else None) or "default"


def stored_task(policy: str | Path) -> str:
    """The task a policy was trained on (its stored ``env.task``; 'path', DART's protocol, when it stores none)."""
    env = stored_env(policy)
    return env.task if env is not None else "path"


def trained_motion(policy: str | Path, given: str | None = None) -> str:
    """``given`` when the user named a motion model; else the one the policy's stored env names, else 'default'."""
    return given if given is not None else motion_of(stored_env(policy))
