import pytest
import torch

from latentrl.envs.reach import ReachLocationEnv


@pytest.fixture(autouse=True)
def one_thread():
    """Tiny batches run fastest on one thread; two threads on the shared 2-core machine contend
    badly (PPO's 2 iterations took 12 s instead of 0.2 s under load). Restored after each test."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


@pytest.fixture
def make_reach(tiny_model):
    """Factory of small ReachLocation envs over the shared tiny model."""

    def make(num_envs: int = 3, **kwargs) -> ReachLocationEnv:
        return ReachLocationEnv(num_envs, motion=tiny_model, **kwargs)

    return make


def actions(num_envs: int, seed: int = 0, dim: int = 16) -> torch.Tensor:
    return torch.randn(num_envs, dim, generator=torch.Generator().manual_seed(seed))
