"""Reward terms (pure tensor kernels) and their weighted composition."""

from latentrl.rewards.compose import (
    COMMON_TERMS,
    DART_TERMS,
    DEFAULT_WEIGHTS,
    TERM_NAMES,
    RewardComposer,
    RewardConfig,
    RewardInputs,
    RewardTerm,
)

__all__ = ["COMMON_TERMS", "DART_TERMS", "DEFAULT_WEIGHTS", "TERM_NAMES", "RewardComposer", "RewardConfig",
           "RewardInputs", "RewardTerm"]
