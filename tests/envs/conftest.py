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
