"""Checks of the scene skills on a decoded motion, each returning its measure as a tensor.

Crouch depth, sitting on a seat, feet on stair treads, a hand on its target, a wave.

Inputs are world joints ``(..., T, 22, 3)`` in metres, z up, floor at z = 0, as the metrics of
``evaluation/metrics.py`` take them; scene parameters are the fields the procedural generator stores
with its sequences (``docs/datasets.md``), so the same function judges the data and a model's rollout:

- crouch: how far the pelvis drops below its standing height (target >= ``CROUCH_MIN_DROP_M``).
- sit: the pelvis resting on the seat, ``SEATED_PELVIS_ABOVE_SEAT_M`` above its surface, within
  ``SEAT_HEIGHT_TOL_M`` in height and ``SEAT_XY_TOL_M`` across.
- stairs: each foot joint's height above the tread under it while the foot is planted: its depth below
  the tread (penetration, target <= 1 cm) and its height above it (float, target <= 3 cm; a flat foot's
  toe joint sits 2 cm up).
- reach (and pick up): the distance of the hand (wrist joint 20 left, 21 right) from its target at the
  motion's closest frame (target: within ``REACH_TOL_M``).
- wave: the hand above its shoulder, swinging side to side.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from latentrl.datasets.locomotion.feet import STAIR_TOE_BACK_M, STAIR_WIDTH_M, stairs_height
from latentrl.datasets.locomotion.skills import REACH_DIRECTIONS, SEATED_PELVIS_ABOVE_SEAT_M
from latentrl.motion.skeleton import FOOT_JOINTS, FPS, PELVIS

CROUCH_MIN_DROP_M = 0.25
"""A crouch lowers the pelvis at least this far below standing."""
SEAT_HEIGHT_TOL_M = 0.05
"""Largest pelvis height error on a seat (from the seat surface plus ``SEATED_PELVIS_ABOVE_SEAT_M``)."""
SEAT_XY_TOL_M = 0.10
"""Largest horizontal distance of the pelvis from the seat point."""
STAIR_PENETRATION_TOL_M = 0.01
"""Largest mean depth of a planted foot joint below its tread."""
STAIR_FLOAT_TOL_M = 0.03
"""Largest mean height of a planted foot joint above its tread."""
PLANTED_SPEED_M_S = 0.15
"""A foot joint slower than this is planted (for the stairs check)."""
REACH_TOL_M = 0.10
"""A reach succeeds when the hand comes this close to its target."""
WAVE_MIN_RAISED = 0.2
"""A wave keeps the hand above its shoulder at least this share of the frames (the data: 0.2 and more)."""
WAVE_SWING_HZ = (1.0, 3.5)
"""Side-to-side swings per raised second of a wave (the data's range)."""
HANDS = (20, 21)
"""Wrist joints of the left and right hand (SMPL-22 has no finger joints)."""

__all__ = [
    "CROUCH_MIN_DROP_M",
    "SEATED_PELVIS_ABOVE_SEAT_M",
    "SEAT_HEIGHT_TOL_M",
    "SEAT_XY_TOL_M",
    "STAIR_FLOAT_TOL_M",
    "STAIR_PENETRATION_TOL_M",
    "REACH_TOL_M",
    "WAVE_MIN_RAISED",
    "WAVE_SWING_HZ",
    "crouch_depth",
    "hand_distance",
    "reach_check",
    "reach_target",
    "seat_behind",
    "stairs_ahead",
    "wave_check",
    "pelvis_drop",
    "seat_errors",
    "sit_check",
    "stair_check",
    "tread_clearance",
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


def tread_clearance(joints: torch.Tensor, stairs: torch.Tensor) -> torch.Tensor:
    """(..., T, 2) height (m) of the foot joints (10, 11) above the ground of one flight under them.

    ``stairs`` is one row of the generator's ``stairs`` field (8 numbers: x, y, climbing direction, width,
    riser, tread, steps, base; the fields of ``latentrl.scenes.Stairs``); the ground is the base before the
    flight and the top step's height after it.
    """
    joints = _as_tensor(joints)
    feet = joints[..., list(FOOT_JOINTS), :]
    row = np.asarray(_as_tensor(stairs).detach().cpu(), dtype=np.float64)
    xy = feet[..., :2].detach().cpu().double().numpy()
    ground = torch.from_numpy(stairs_height(row, xy, landings=True)).to(feet.device, feet.dtype)
    return feet[..., 2] - ground


def stair_check(joints: torch.Tensor, stairs: torch.Tensor, fps: float = FPS) -> dict[str, torch.Tensor]:
    """Feet on the treads of a flight: penetration and float of the planted foot joints, as means (m).

    A foot joint is planted in a frame where it moves slower than ``PLANTED_SPEED_M_S`` (to the next
    frame). Returns ``(...,)`` tensors: ``penetration_m`` (mean depth below the tread), ``float_m`` (mean
    height above it), their largest values ``penetration_max_m``, ``float_max_m``, the number of planted
    foot-frames ``planted`` and ``ok`` (both means within the targets).
    """
    joints = _as_tensor(joints)
    clear = tread_clearance(joints, stairs)[..., :-1, :]
    feet = joints[..., list(FOOT_JOINTS), :]
    speed = torch.linalg.vector_norm(feet[..., 1:, :, :] - feet[..., :-1, :, :], dim=-1) * fps
    planted = speed < PLANTED_SPEED_M_S
    count = planted.sum(dim=(-1, -2))
    zero = torch.zeros((), dtype=clear.dtype, device=clear.device)
    depth = torch.where(planted, (-clear).clamp(min=0.0), zero)
    height = torch.where(planted, clear.clamp(min=0.0), zero)
    n = count.clamp(min=1).to(clear.dtype)
    out = {
        "penetration_m": depth.sum(dim=(-1, -2)) / n,
        "float_m": height.sum(dim=(-1, -2)) / n,
        "penetration_max_m": depth.amax(dim=(-1, -2)),
        "float_max_m": height.amax(dim=(-1, -2)),
        "planted": count,
    }
    out["ok"] = (out["penetration_m"] <= STAIR_PENETRATION_TOL_M) & (out["float_m"] <= STAIR_FLOAT_TOL_M)
    return out


def hand_distance(joints: torch.Tensor, target: torch.Tensor, hand: int) -> torch.Tensor:
    """(..., T) distance (m) of hand ``hand`` (0 left, 1 right: wrist joint 20 or 21) from ``target`` (..., 3)."""
    joints = _as_tensor(joints)
    target = _as_tensor(target, joints)
    return torch.linalg.vector_norm(joints[..., HANDS[hand], :] - target[..., None, :], dim=-1)


def reach_check(joints: torch.Tensor, target: torch.Tensor, hand: int) -> dict[str, torch.Tensor]:
    """How close a hand comes to its target (the measure of reach and pick up).

    Returns ``(...,)`` tensors: ``distance_m`` at the closest frame, that ``frame`` and ``reached`` (within
    ``REACH_TOL_M``).
    """
    dist = hand_distance(joints, target, hand)
    best, frame = dist.min(dim=-1)
    return {"distance_m": best, "frame": frame, "reached": best <= REACH_TOL_M}


def wave_check(joints: torch.Tensor, hand: int, fps: float = FPS) -> dict[str, torch.Tensor]:
    """A wave: how long the hand is up, and how often it swings side to side meanwhile.

    Returns ``(...,)`` tensors: ``raised`` (share of frames with the hand above its shoulder) and
    ``swings_hz`` (sign changes of the hand's sideways speed relative to the shoulder while raised, halved,
    per raised second).
    """
    joints = _as_tensor(joints)
    wrist, shoulder = joints[..., HANDS[hand], :], joints[..., 16 + hand, :]
    raised = wrist[..., 2] > shoulder[..., 2]
    across = joints[..., 2, :2] - joints[..., 1, :2]  # the hips' left-to-right axis
    across = across / torch.linalg.vector_norm(across, dim=-1, keepdim=True).clamp(min=1e-9)
    side = ((wrist[..., :2] - shoulder[..., :2]) * across).sum(dim=-1)
    vel = side[..., 1:] - side[..., :-1]
    flips = (vel[..., 1:] * vel[..., :-1] < 0) & raised[..., 2:] & raised[..., 1:-1]
    seconds = raised.sum(dim=-1).clamp(min=1).to(joints.dtype) / fps
    swings = flips.sum(dim=-1).to(joints.dtype) / 2 / seconds
    return {"raised": raised.to(joints.dtype).mean(dim=-1), "swings_hz": swings}


# --- scenes placed the way the data places them, for a rollout from a standing frame ---------------------


def _facing(joints0: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(..., 2) forward and right unit vectors of a standing frame (..., 22, 3), from the hip axis."""
    right = joints0[..., 2, :2] - joints0[..., 1, :2]
    right = right / torch.linalg.vector_norm(right, dim=-1, keepdim=True).clamp(min=1e-9)
    return torch.stack((-right[..., 1], right[..., 0]), dim=-1), right


def seat_behind(joints0: torch.Tensor, height: float = 0.45, back_thighs: float = 0.85) -> torch.Tensor:
    """(..., 4) the seat the data would put behind a standing frame (..., 22, 3): x, y, height, facing.

    ``sit_down`` moves the pelvis back from the planted feet by 0.75-0.95 of a thigh (``back_thighs``)
    onto a seat 0.2-0.6 m high (``height``); the thigh is the left hip-to-knee distance of the frame.
    """
    joints0 = _as_tensor(joints0)
    forward, _ = _facing(joints0)
    thigh = torch.linalg.vector_norm(joints0[..., 4, :] - joints0[..., 1, :], dim=-1, keepdim=True)
    xy = joints0[..., PELVIS, :2] - back_thighs * thigh * forward
    facing = torch.atan2(forward[..., 1], forward[..., 0])[..., None]
    return torch.cat((xy, torch.full_like(facing, height), facing), dim=-1)


def stairs_ahead(joints0: torch.Tensor, riser: float = 0.15, tread: float = 0.3, count: int = 6,
                 up: bool = True) -> torch.Tensor:
    """(..., 8) a flight in front of a standing frame (..., 22, 3), as the data builds one (``stairs`` row).

    Its first edge lies ``STAIR_TOE_BACK_M`` ahead of the leading toe joint, centred on the pelvis. Going
    up it climbs from the floor under the feet; going down the feet stand on its top step (the flight's
    base is ``count * riser`` below them) and it descends ahead.
    """
    joints0 = _as_tensor(joints0)
    forward, _ = _facing(joints0)
    toes = joints0[..., list(FOOT_JOINTS), :]
    lead = ((toes[..., :2] - joints0[..., None, PELVIS, :2]) * forward[..., None, :]).sum(dim=-1).amax(dim=-1)
    ground = (toes[..., 2].amin(dim=-1) - 0.02)[..., None]  # a flat foot's toe joint is 2 cm up
    edge = joints0[..., PELVIS, :2] + (lead + STAIR_TOE_BACK_M)[..., None] * forward
    angle = torch.atan2(forward[..., 1], forward[..., 0])[..., None]
    if up:
        start, direction, base = edge, angle, ground
    else:
        start, direction, base = edge + (count - 1) * tread * forward, angle + math.pi, ground - count * riser
    full = torch.ones_like(angle)
    return torch.cat((start, direction, STAIR_WIDTH_M * full, riser * full, tread * full, count * full, base), -1)


def reach_target(joints0: torch.Tensor, hand: int, direction: str, fraction: float = 0.8) -> torch.Tensor:
    """(..., 3) a target ``fraction`` of the arm's length from a standing frame's shoulder (..., 22, 3).

    ``direction`` is one of ``REACH_DIRECTIONS``: forward, up (60 degrees above forward), down (60 below;
    the data bends to reach it) or to the hand's side, as the generator draws them (middle of its ranges).
    """
    if direction not in REACH_DIRECTIONS:
        raise ValueError(f"direction '{direction}', expected one of {', '.join(REACH_DIRECTIONS)}")
    joints0 = _as_tensor(joints0)
    forward, right = _facing(joints0)
    shoulder, elbow, wrist = (joints0[..., j + hand, :] for j in (16, 18, 20))
    arm = (torch.linalg.vector_norm(elbow - shoulder, dim=-1) + torch.linalg.vector_norm(wrist - elbow, dim=-1))
    elevation = {"forward": 0.0, "up": 60.0, "down": -60.0, "side": 0.0}[direction]
    out = right * (1.0 if hand else -1.0)
    flat = out if direction == "side" else forward
    e = math.radians(elevation)
    offset = torch.cat((flat * math.cos(e), torch.full_like(flat[..., :1], math.sin(e))), dim=-1)
    return shoulder + (fraction * arm)[..., None] * offset
