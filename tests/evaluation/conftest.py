"""Helpers of the evaluation tests: a fresh policy for the tiny model, path files (``eval_files``: root conftest)."""

from __future__ import annotations

import json
from pathlib import Path

import torch


def fresh_policy(model, observe_next: bool = False):
    """A freshly initialised DART-architecture policy (small) with the FollowPath observation layout."""
    from latentrl.envs.path import FollowPathEnv, WaypointPath
    from latentrl.ppo.config import PolicyConfig
    from latentrl.ppo.policy import ActorCritic

    env = FollowPathEnv(1, motion=model, paths=[WaypointPath(((0.0, 1.0, 0.0),), ("walk",))], observe_next=observe_next)
    torch.manual_seed(0)
    return ActorCritic(env.single_observation_space.shape[0], env.single_action_space.shape[0],
                       PolicyConfig(latent_dim=32), env.metadata["observation_layout"])


def write_paths(folder: Path, data, name: str = "paths.json") -> Path:
    path = folder / name
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return path


NEAR = {"goal_location": [[0.0, 0.0, 0.0]], "goal_text": ["walk"]}
"""A waypoint at the start pelvis: reached in the first step (within 0.3 m at one of its 8 frames)."""
FAR = {"goal_location": [[0.0, 0.0, 0.0], [0.0, 40.0, 0.0]], "goal_text": ["walk", "run"]}
"""The first waypoint at the start, the last 40 m away: never reached within a few steps (a timeout)."""
