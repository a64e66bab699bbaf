"""Foot contact and DART's skate weighting as pure tensor functions: the one kernel of rewards, metrics and data.

DART (``calc_skate`` of its evaluation scripts, the ``skate`` reward of its policy training) weights
the displacement of each foot joint (:data:`FOOT_JOINTS`: left, right) between two frames by

    ``w = 2 - 2 ** clamp(max(h_t, h_t-1) / threshold, 0, 1)``

with ``h`` the joint's height above the floor and ``threshold`` :data:`CONTACT_HEIGHT_M` (3 cm): weight 1
on the floor, 0 at the threshold or above in either frame, DART's exponential ramp between. A foot is
*in contact* in a frame when its weight there would be positive, i.e. ``h < threshold`` (the rule of the
``contacts`` field of motion files, :mod:`latentrl.motion.clip`).

Callers: :func:`latentrl.rewards.terms.foot_skate` (reward, negated mean), the skate metric of
:mod:`latentrl.evaluation.metrics` (x fps, cm/s) and :func:`latentrl.datasets.locomotion.foot_skate`
(numpy, converted here and back).
"""

from __future__ import annotations

import torch

from latentrl.constants import CONTACT_HEIGHT_M
from latentrl.motion.skeleton import FOOT_JOINTS


def foot_positions(joints: torch.Tensor) -> torch.Tensor:
    """(..., 22, 3) joints -> (..., 2, 3) the left and right foot joints DART uses for contact."""
    return torch.stack([joints[..., j, :] for j in FOOT_JOINTS], dim=-2)  # no index tensor from host data


def skate_weights(heights: torch.Tensor, threshold: float = CONTACT_HEIGHT_M) -> torch.Tensor:
    """(..., T, 2) foot heights above the floor -> (..., T-1, 2) contact weights in [0, 1] (1 = on the floor)."""
    highest = torch.maximum(heights[..., 1:, :], heights[..., :-1, :])
    return 2.0 - torch.pow(2.0, (highest / threshold).clamp(0.0, 1.0))


def weighted_foot_slide(
    feet: torch.Tensor, floor: float | torch.Tensor = 0.0, threshold: float = CONTACT_HEIGHT_M,
    horizontal: bool = False
) -> torch.Tensor:
    """(..., T, 2, 3) world foot joints -> (..., T-1, 2) contact-weighted displacement per transition, metres.

    ``horizontal`` measures the xy displacement only (sliding without lift-off and touch-down); the weight
    always uses the heights above ``floor`` (a number, or (..., T, 2) the terrain under each foot).
    """
    delta = feet[..., 1:, :, :] - feet[..., :-1, :, :]
    step = torch.linalg.vector_norm(delta[..., :2] if horizontal else delta, dim=-1)
    return step * skate_weights(feet[..., 2] - floor, threshold)


def contact_shares(heights: torch.Tensor, threshold: float) -> dict[str, torch.Tensor]:
    """(..., T, 2) left and right foot heights above the floor -> shares of the T frames by feet down.

    A foot is down within ``threshold`` (inclusive). Returns ``{"left_only", "right_only", "both", "none"}``,
    each (...). The skill rule's kernel: the evaluation judges segments with it, the ``skill`` reward pays by it.
    """
    left, right = heights[..., 0] <= threshold, heights[..., 1] <= threshold
    return {
        "left_only": (left & ~right).float().mean(dim=-1),
        "right_only": (right & ~left).float().mean(dim=-1),
        "both": (left & right).float().mean(dim=-1),
        "none": (~left & ~right).float().mean(dim=-1),
    }


def foot_contacts(joints: torch.Tensor, floor: float = 0.0, threshold: float = CONTACT_HEIGHT_M) -> torch.Tensor:
    """(..., T, 22, 3) world joints -> (..., T, 2) bool: left and right foot joint lower than ``threshold``."""
    return foot_positions(joints)[..., 2] - floor < threshold
