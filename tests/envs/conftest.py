import pytest
import torch

from latentrl.envs.reach import ReachLocationEnv


@pytest.fixture
def make_reach(tiny_model):
    """Factory of small ReachLocation envs over the shared tiny model."""

    def make(num_envs: int = 3, **kwargs) -> ReachLocationEnv:
        return ReachLocationEnv(num_envs, motion=tiny_model, **kwargs)

    return make


def actions(num_envs: int, seed: int = 0, dim: int = 16) -> torch.Tensor:
    return torch.randn(num_envs, dim, generator=torch.Generator().manual_seed(seed))


# --------------------------------------------------------------------------- every task, every id
TASK_IDS = {
    "latentrl/ReachLocation-v0": ({}, 4),
    "latentrl/FollowPath-v0": ({"random_waypoints": 3}, 4),
    "latentrl/Joystick-v0": ({"heading_change_seconds": (0.3, 0.6)}, 3),  # commands change every 1-2 steps
    "latentrl/TimedPath-v0": ({"random_waypoints": 3}, 5),
}


@pytest.fixture(params=list(TASK_IDS))
def make_task(request, tiny_model):
    """Factory of small envs of each registered id, through gymnasium.make_vec, over the tiny model."""
    import gymnasium as gym

    import latentrl  # noqa: F401  (registers the ids)

    env_id = request.param
    extra, goal_size = TASK_IDS[env_id]

    def make(num_envs: int = 3, **kwargs):
        env = gym.make_vec(env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", motion=tiny_model,
                           texts=("walk", "run"), **{**extra, **kwargs})
        assert env.observation_layout["goal"] == (0, goal_size)
        return env

    return make
