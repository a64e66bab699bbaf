"""Gymnasium vector envs whose action is a frozen motion model's latent noise.

Names are imported lazily, so ``import latentrl`` (which registers the Gymnasium ids) stays
cheap: torch and the env modules load when a name below is first used.
"""

from __future__ import annotations

import importlib
from typing import Any

_EXPORTS = {
    "LatentMotionVectorEnv": "latentrl.envs.base",
    "goal_features": "latentrl.envs.goal",
    "ReachLocationEnv": "latentrl.envs.reach",
    "FollowPathEnv": "latentrl.envs.path",
    "WaypointPath": "latentrl.envs.path",
    "load_paths": "latentrl.envs.path",
    "parse_paths": "latentrl.envs.path",
    "JoystickEnv": "latentrl.envs.joystick",
    "CommandTimeline": "latentrl.envs.joystick",
    "load_timelines": "latentrl.envs.joystick",
    "parse_timelines": "latentrl.envs.joystick",
    "TimedPathEnv": "latentrl.envs.timed",
    "TimedPath": "latentrl.envs.timed",
    "load_timed_paths": "latentrl.envs.timed",
    "parse_timed_paths": "latentrl.envs.timed",
    "Sb3VecEnv": "latentrl.envs.sb3",
    "SingleEnv": "latentrl.envs.single",
    "TaskSpec": "latentrl.envs.tasks",
    "Evaluator": "latentrl.envs.tasks",
    "register_task": "latentrl.envs.tasks",
    "task_spec": "latentrl.envs.tasks",
    "ENV_IDS": "latentrl.envs.registration",
    "register_envs": "latentrl.envs.registration",
}

__all__ = sorted(_EXPORTS)


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'latentrl.envs' has no attribute '{name}'")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
