"""What a policy checkpoint says about how it was trained: its env config and its motion model.

``latentrl eval``, ``latentrl play`` and ``latentrl export onnx`` all read these, so a policy trained on
any motion model runs without its ``--motion`` repeated.
"""

from __future__ import annotations

from pathlib import Path


def stored_env(policy: str | Path):
    """The ``EnvConfig`` stored in a policy checkpoint, or None (no config, or a file the loaders will refuse)."""
    from latentrl.envs.config import stored_env_config
    from latentrl.errors import LatentRLError
    from latentrl.ppo.checkpoint import read_checkpoint

    try:
        return stored_env_config(read_checkpoint(policy, map_location="cpu").get("config"))
    except (LatentRLError, OSError):
        return None


def motion_of(env) -> str:
    """The motion model a stored ``EnvConfig`` names ('default' when there is none)."""
    return (env.motion if env is not None else None) or "default"


def trained_motion(policy: str | Path, given: str | None = None) -> str:
    """``given`` when the user named a motion model; else the one the policy's stored env names, else 'default'."""
    return given if given is not None else motion_of(stored_env(policy))
