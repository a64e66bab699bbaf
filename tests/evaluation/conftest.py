"""Fixtures of the evaluation tests: a tiny motion model file and a fresh policy checkpoint that fits it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
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


@pytest.fixture(scope="session")
def eval_files(tmp_path_factory, tiny_model) -> dict[str, Path]:
    """``motion``: the tiny model saved as a file; ``policy``: a PPO checkpoint trained 'on' it (iteration 0)."""
    from latentrl.motion.checkpoint import file_sha256, save_motion_model
    from latentrl.ppo.checkpoint import make_checkpoint, save_checkpoint

    root = tmp_path_factory.mktemp("eval_files")
    motion = save_motion_model(tiny_model, root / "tiny_motion.pt")
    policy = fresh_policy(tiny_model)
    state = make_checkpoint(trainer="native", iteration=0, env_steps=0, elapsed_s=0.0, policy=policy,
                            optimizer=torch.optim.Adam(policy.parameters()), config={"test": True},
                            motion={"path": str(motion), "sha256": file_sha256(motion)})
    return {"motion": motion, "policy": save_checkpoint(state, root / "policy.pt")}


def write_paths(folder: Path, data, name: str = "paths.json") -> Path:
    path = folder / name
    path.write_text(data if isinstance(data, str) else json.dumps(data))
    return path


NEAR = {"goal_location": [[0.0, 0.0, 0.0]], "goal_text": ["walk"]}
"""A waypoint at the start pelvis: reached in the first step (within 0.3 m at one of its 8 frames)."""
FAR = {"goal_location": [[0.0, 0.0, 0.0], [0.0, 40.0, 0.0]], "goal_text": ["walk", "run"]}
"""The first waypoint at the start, the last 40 m away: never reached within a few steps (a timeout)."""
