import pytest

from latentrl.ppo import PolicyConfig, PPOConfig


def tiny_ppo(**overrides) -> PPOConfig:
    """8 envs x 8 steps = 64 transitions per iteration, 2 minibatches, 2 epochs, 2 iterations."""
    values = dict(total_steps=128, num_steps=8, num_minibatches=2, update_epochs=2, learning_rate=1e-3,
                  checkpoint_every=1, keep_checkpoints=10, seed=3)
    values.update(overrides)
    return PPOConfig(**values)


def tiny_policy(**overrides) -> PolicyConfig:
    values = dict(latent_dim=32, n_blocks=1)
    values.update(overrides)
    return PolicyConfig(**values)


@pytest.fixture
def ppo_cfg() -> PPOConfig:
    return tiny_ppo()


@pytest.fixture
def policy_cfg() -> PolicyConfig:
    return tiny_policy()
