"""Reward terms (pure tensor kernels) and their weighted composition."""

from latentrl.rewards.compose import (
    COMMON_TERMS,
    DART_TERMS,
    DEFAULT_WEIGHTS,
    REWARD_TERMS,
    SCENE_TERMS,
    TERM_NAMES,
    RewardComposer,
    RewardConfig,
    RewardInputs,
    RewardTerm,
    reward_term,
)

__all__ = ["COMMON_TERMS", "DART_TERMS", "DEFAULT_WEIGHTS", "REWARD_TERMS", "SCENE_TERMS", "TERM_NAMES",
           "RewardComposer", "RewardConfig", "RewardInputs", "RewardTerm", "reward_term"]
