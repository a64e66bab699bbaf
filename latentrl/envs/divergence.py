"""Which envs' motion diverged in a step, and their state kept from before it.

A diverged env is terminated with reward 0 and keeps its last finite state, so observations never
hold NaN. The checks are pure tensor code (they run inside a compiled step).
"""

from __future__ import annotations

import torch

from latentrl.motion.canonical import WorldTransform
from latentrl.motion.rollout import RolloutState

DIVERGENCE_DEPTH_M = 1.0
"""A joint this far under the floor means the motion diverged (feet dip a few centimetres at most)."""
DIVERGENCE_SIGMAS = 1000.0
"""A history feature this many of the data's standard deviations from its mean means the motion diverged."""


def feature_range(motion) -> tuple[torch.Tensor, torch.Tensor] | None:
    """The motion prior's ``(mean, std)`` of its features (``MotionPrior.mean``/``std``), or None if it has none."""
    mean, std = getattr(motion, "mean", None), getattr(motion, "std", None)
    return None if mean is None or std is None else (mean, std)


def diverged(joints_world: torch.Tensor, new_state: RolloutState, limit: float, floor_height: float,
             features: tuple[torch.Tensor, torch.Tensor] | None) -> torch.Tensor:
    """(N,) envs whose new frames or state are non-finite, beyond ``limit`` metres or deep under the floor.

    With ``features`` (the data's mean and std), a history feature more than :data:`DIVERGENCE_SIGMAS`
    standard deviations from the mean counts too.
    """
    ok = (joints_world.abs() <= limit).flatten(1).all(1)  # False for NaN as well
    ok &= (joints_world[..., 2] >= floor_height - DIVERGENCE_DEPTH_M).flatten(1).all(1)  # metres underground
    if features is not None:
        scaled = (new_state.history - features[0]) / features[1]
        ok &= (scaled.abs() <= DIVERGENCE_SIGMAS).flatten(1).all(1)
    for value in (new_state.history, new_state.world.rotation, new_state.world.translation):
        ok &= torch.isfinite(value).flatten(1).all(1)
    return ~ok


def keep_finite(new: RolloutState, old: RolloutState, diverged: torch.Tensor) -> RolloutState:
    """The new state, except that diverged envs keep their old one (never NaN in observations)."""
    d = diverged[:, None, None]
    return RolloutState(
        torch.where(d, old.history, new.history),
        WorldTransform(
            torch.where(d, old.world.rotation, new.world.rotation),
            torch.where(diverged[:, None], old.world.translation, new.world.translation),
        ),
        torch.where(diverged, old.airborne_flags(), new.airborne_flags()),
    )
