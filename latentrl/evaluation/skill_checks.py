"""Checks of the scene skills on a decoded motion, each returning its measure as a tensor.

Crouch depth and sitting on a seat; stairs and reaches join as the generator makes them.

Inputs are world joints ``(..., T, 22, 3)`` in metres, z up, floor at z = 0, as the metrics of
``evaluation/metrics.py`` take them; scene parameters are the fields the procedural generator stores
with its sequences (``docs/datasets.md``), so the same function judges the data and a model's rollout:

- crouch: how far the pelvis drops below its standing height (target >= ``CROUCH_MIN_DROP_M``).
- sit: the pelvis resting on the seat, ``SEATED_PELVIS_ABOVE_SEAT_M`` above its surface, within
  ``SEAT_HEIGHT_TOL_M`` in height and ``SEAT_XY_TOL_M`` across.
"""

from __future__ import annotations

import torch

from latentrl.datasets.locomotion.skills import SEATED_PELVIS_ABOVE_SEAT_M
from latentrl.motion.skeleton import PELVIS

CROUCH_MIN_DROP_M = 0.25
"""A crouch lowers the pelvis at least this far below standing."""
SEAT_HEIGHT_TOL_M = 0.05
"""Largest pelvis height error on a seat (from the seat surface plus ``SEATED_PELVIS_ABOVE_SEAT_M``)."""
SEAT_XY_TOL_M = 0.10
"""Largest horizontal distance of the pelvis from the seat point."""

__all__ = [
    "CROUCH_MIN_DROP_M",
    "SEATED_PELVIS_ABOVE_SEAT_M",
    "SEAT_HEIGHT_TOL_M",
    "SEAT_XY_TOL_M",
    "crouch_depth",
    "pelvis_drop",
    "seat_errors",
    "sit_check",
]


def _as_tensor(x, like: torch.Tensor | None = None) -> torch.Tensor:
    t = torch.as_tensor(x)
    if like is not None:
        t = t.to(like.device, like.dtype)
    return t


def pelvis_drop(joints: torch.Tensor, standing_z: torch.Tensor | float | None = None) -> torch.Tensor:
    """(..., T) how far the pelvis is below ``standing_z`` ((...,) or a number, m); default: its first frame.

    The first frame of a rollout from a standing seed is the standing height; data sequences pass the
    rest pelvis height (``rest_joints[0, 2]``).
    """
    joints = _as_tensor(joints)
    z = joints[..., PELVIS, 2]
    ref = z[..., :1] if standing_z is None else _as_tensor(standing_z, z)[..., None]
    return ref - z


def crouch_depth(joints: torch.Tensor, standing_z: torch.Tensor | float | None = None,
                 hold_frames: int = 15) -> torch.Tensor:
    """(...,) the crouch's depth (m): the smallest pelvis drop over the last ``hold_frames`` frames.

    The issue's measure (``crouch: pelvis drop >= 25 cm``) on a rollout that was asked to crouch: the
    drop it holds at the end, not a dip on the way.
    """
    return pelvis_drop(joints, standing_z)[..., -hold_frames:].amin(dim=-1)


def seat_errors(joints: torch.Tensor, seat: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(..., T) pelvis height error (m, signed: + above) and (..., T) horizontal distance (m) from a seat.

    ``seat`` is ``(..., 4)``: x, y, seat height, facing yaw (the generator's ``seats`` row); the pelvis
    of a seated body is ``SEATED_PELVIS_ABOVE_SEAT_M`` above the seat surface, over the seat point.
    """
    joints = _as_tensor(joints)
    seat = _as_tensor(seat, joints)
    pelvis = joints[..., PELVIS, :]
    height = pelvis[..., 2] - (seat[..., 2:3] + SEATED_PELVIS_ABOVE_SEAT_M)
    xy = torch.linalg.vector_norm(pelvis[..., :2] - seat[..., None, :2], dim=-1)
    return height, xy


def sit_check(joints: torch.Tensor, seat: torch.Tensor, hold_frames: int = 15) -> dict[str, torch.Tensor]:
    """Whether a motion ends seated on ``seat``: the pelvis within the tolerances on each of its last frames.

    Returns ``(...,)`` tensors: ``seated`` (bool), ``height_err_m`` (largest |height error| over the
    held frames) and ``xy_err_m`` (largest horizontal distance over them).
    """
    height, xy = seat_errors(joints, seat)
    h = height[..., -hold_frames:].abs().amax(dim=-1)
    d = xy[..., -hold_frames:].amax(dim=-1)
    return {"seated": (h <= SEAT_HEIGHT_TOL_M) & (d <= SEAT_XY_TOL_M), "height_err_m": h, "xy_err_m": d}
