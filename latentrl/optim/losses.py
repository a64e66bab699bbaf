"""The optimizer's losses and the metrics that score its result, from the same kernels.

Constraints: :func:`target_squared` picks each point target's joint at its frame and takes the squared
distance over the target's axes. The loss (:func:`constraint_loss`) is a pseudo-Huber of it (zero exactly
where a target is met, metres far from it, smooth near it, as DART's trajectory control uses a Huber loss);
the metric (:func:`goal_error_cm`) is its square root, averaged over the targets, in centimetres.

Regularizers use the evaluation's metric kernels (DART's definitions, :mod:`latentrl.evaluation.metrics`):
floor distance, foot skate and jerk, and the ``prior`` reward term's noise-shell penalty, so the number a
weight pushes down is the number the report prints.

Scenes: a problem with a scene adds DART's two scene costs to its constraint loss (:func:`scene_loss`), the
kernels the rewards use (:mod:`latentrl.scenes.contact`): joints kept their skin radius away from every object,
the lower foot on the terrain under it.
"""

from __future__ import annotations

import torch

from latentrl.evaluation.metrics import foot_floor_distance_cm, foot_skate_cm_s, jerk
from latentrl.optim.problems import Targets
from latentrl.rewards.terms import noise_prior
from latentrl.scenes.contact import collision_cost, contact_cost

HUBER_M = 0.01
"""Pseudo-Huber scale of the constraint loss (1 cm): quadratic inside, linear (in metres) beyond."""
REGULARIZERS = ("floor", "skate", "jerk", "prior")
SCENE_COSTS = ("collision", "contact")


def target_squared(joints: torch.Tensor, targets: Targets) -> torch.Tensor:
    """(B, T, 22, 3) generated frames -> (B, K) squared distance of each target (its axes only; 0 on padding)."""
    rows = torch.arange(joints.shape[0], device=joints.device)[:, None]
    picked = joints[rows, targets.frames, targets.joints]  # (B, K, 3)
    diff = (picked - targets.points) * targets.masks
    return diff.square().sum(dim=-1) * targets.valid


def pseudo_huber(d2: torch.Tensor) -> torch.Tensor:
    """The pseudo-Huber distance of squared distances ``d2`` (m^2): ``sqrt(d2 + delta^2) - delta``.

    delta is :data:`HUBER_M`: 0 at 0, about the distance far from it, smooth near it.
    """
    return torch.sqrt(d2 + HUBER_M**2) - HUBER_M


def constraint_loss(joints: torch.Tensor, targets: Targets) -> torch.Tensor:
    """(B,) weighted mean pseudo-Huber distance of the targets (metres) plus any scene's :func:`scene_loss`.

    0 exactly when every target is met (and the scene is kept).
    """
    loss = (pseudo_huber(target_squared(joints, targets)) * targets.weights).sum(dim=1) / targets.weights.sum(dim=1)
    return loss if targets.scene is None else loss + scene_loss(joints, targets)


def scene_costs(joints: torch.Tensor, targets: Targets) -> dict[str, torch.Tensor]:
    """(B,) each scene cost of the (B, T, 22, 3) generated frames, metres (zeros when no problem has a scene).

    DART's ``cons_coll`` and ``cons_cont``.
    """
    if targets.scene is None:
        zero = joints.new_zeros(joints.shape[0])
        return {"collision": zero, "contact": zero}
    return {"collision": collision_cost(joints, targets.scene), "contact": contact_cost(joints, targets.scene)}


def scene_loss(joints: torch.Tensor, targets: Targets) -> torch.Tensor:
    """(B,) the scene costs weighted by each problem's ``scene_weights`` (0 for problems without a scene)."""
    costs = scene_costs(joints, targets)
    if targets.scene_weights is None:
        return costs["collision"] * 0.0
    w = targets.scene_weights
    return w[:, 0] * costs["collision"] + w[:, 1] * costs["contact"]


def goal_error_cm(joints: torch.Tensor, targets: Targets) -> torch.Tensor:
    """(B,) mean distance of the targets from their joints, cm (DART's goal error when the targets are a keyframe)."""
    d = target_squared(joints, targets).clamp(min=0).sqrt()
    valid = targets.valid.float()
    return (d * valid).sum(dim=1) / valid.sum(dim=1) * 100.0


def regularizers(joints: torch.Tensor, noise: torch.Tensor, fps: float,
                 names: tuple[str, ...] = REGULARIZERS) -> dict[str, torch.Tensor]:
    """(B,) the regularizers ``names`` of whole motions (B, T, 22, 3) and their noise (S, B, 1, D), in SI units.

    ``floor`` m (DART's floor distance), ``skate`` m/s (DART's skate), ``jerk`` m/s^3, ``prior`` (mean square of
    the noise above 1, per primitive, averaged). Only the terms asked for are computed (the optimizer's loop needs
    the weighted ones alone).
    """
    terms = {
        "floor": lambda: foot_floor_distance_cm(joints) / 100.0,
        "skate": lambda: foot_skate_cm_s(joints, fps) / 100.0,
        "jerk": lambda: jerk(joints, fps),
        "prior": lambda: -noise_prior(noise.flatten(2)).mean(dim=0),  # (S, B) -> (B,)
    }
    return {name: terms[name]() for name in names}
