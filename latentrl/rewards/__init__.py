"""Reward terms (pure tensor kernels) and their weighted composition."""

from latentrl.rewards.compose import DEFAULT_WEIGHTS, TERM_NAMES, RewardComposer, RewardConfig, RewardInputs, RewardTerm

__all__ = ["DEFAULT_WEIGHTS", "TERM_NAMES", "RewardComposer", "RewardConfig", "RewardInputs", "RewardTerm"]
