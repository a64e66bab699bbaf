"""Reward terms (pure tensor kernels) and their weighted composition."""

from latentrl.rewards.compose import (
    DART_TERMS,
    DEFAULT_WEIGHTS,
    TERM_NAMES,
    RewardComposer,
    RewardConfig,
    RewardInputs,
    RewardTerm,
)

__all__ = ["DART_TERMS", "DEFAULT_WEIGHTS", "TERM_NAMES", "RewardComposer", "RewardConfig", "RewardInputs",
           "RewardTerm"]
