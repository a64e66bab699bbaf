"""Anthropometric SMPL-22 rest skeleton and the rigid-body kit that poses it from foot targets.

World frame everywhere: metres, z up, floor at z = 0. The rest body stands upright facing +y with its
right along +x and the arms hanging down (not a T-pose). Joint angles follow SMPL: entry 0 of a pose is the
global orientation (rest body -> world), entry j > 0 the rotation of joint j relative to its parent's frame.

Segment lengths are fractions of body height H from Drillis & Contini (1966) as reproduced in Winter,
*Biomechanics and Motor Control of Human Movement*, Fig. 4.1 (offline_assets.md section 4). Two deliberate
choices:

- the legs are built from joint centres: hip centres at 0.50H (the 0.53H trochanter landmark sits about
  0.03H higher), so the pelvis joint lands at the quoted 0.53H standing height; thigh and shank keep Winter's
  0.245 : 0.246 ratio over the 0.461H between hip centre and ankle centre (ankle height 0.039H);
- the toe-base ('foot', SMPL joints 10/11) joint sits ``TOE_HEIGHT_M`` = 2 cm above the floor with the foot
  flat. DART's contact test treats a foot joint below 3 cm as (partly) in contact; 2 cm keeps stance feet
  detected while each lift-off or touch-down crosses only 1 cm of the weighted band, which keeps the
  contact-weighted skate of a clean gait small (see docs/datasets.md).

The rest legs are exactly vertical, so every leg segment's rest frame is the identity; ``leg_rotations`` relies
on that.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from latentrl.motion.skeleton import NUM_JOINTS, PARENTS

#: Height (m) of the toe-base joint above the floor when the foot is flat on it.
TOE_HEIGHT_M = 0.02

# Rest joint positions as fractions of body height H: (x, y, z) with x = body right, y = forward, z = up.
# Left-side joints carry x < 0. Only the toe height is absolute (TOE_HEIGHT_M), see the module docstring.
_HIP_HALF_WIDTH = 0.05  # hip joint centres about 0.10H apart
_ANKLE_HEIGHT = 0.039
_HIP_HEIGHT = 0.50
_KNEE_HEIGHT = _ANKLE_HEIGHT + (_HIP_HEIGHT - _ANKLE_HEIGHT) * 0.246 / 0.491
_TOE_FORWARD = 0.075  # ankle centre to toe base, about half the 0.152H foot length
_HEEL_BACK = 0.03  # heel contact point behind the ankle centre
_PELVIS_HEIGHT = 0.53
_NECK_HEIGHT = 0.835
_SPINE_FRACTIONS = (0.22, 0.48, 0.62)  # spine1..3 along pelvis -> neck (SMPL-like spacing)

_REST_FRACTIONS: dict[str, tuple[float, float, float]] = {
    "pelvis": (0.0, 0.0, _PELVIS_HEIGHT),
    "hip": (_HIP_HALF_WIDTH, 0.0, _HIP_HEIGHT),
    "knee": (_HIP_HALF_WIDTH, 0.0, _KNEE_HEIGHT),
    "ankle": (_HIP_HALF_WIDTH, 0.0, _ANKLE_HEIGHT),
    "collar": (0.04, -0.005, 0.79),
    "shoulder": (0.10, -0.005, 0.80),  # biacromial width 0.259H; joint centres sit inside the acromions
    "elbow": (0.11, -0.005, 0.80 - 0.186),  # upper arm 0.186H, hanging with ~3 deg of abduction
    "wrist": (0.115, 0.0, 0.80 - 0.186 - 0.146),  # forearm 0.146H
    "head": (0.0, 0.01, 0.905),  # chin at 0.870H
}


@dataclass(frozen=True)
class Body:
    """One body: its rest skeleton and the leg and foot dimensions the gait code reads.

    Attributes:
        height: body height H in metres.
        rest_joints: (22, 3) rest joint positions with zero translation, metres, z up, facing +y; entry 0 is the
            rest pelvis offset (``pelvis_delta``).
    """

    height: float
    rest_joints: np.ndarray

    @property
    def thigh(self) -> float:
        """Hip-to-knee length (m)."""
        return float(np.linalg.norm(self.rest_joints[4] - self.rest_joints[1]))

    @property
    def shank(self) -> float:
        """Knee-to-ankle length (m)."""
        return float(np.linalg.norm(self.rest_joints[7] - self.rest_joints[4]))

    @property
    def hip_offsets(self) -> np.ndarray:
        """(2, 3) left and right hip centres relative to the pelvis joint in the rest (pelvis) frame, metres."""
        return self.rest_joints[[1, 2]] - self.rest_joints[0]

    @property
    def ankle_to_toe(self) -> np.ndarray:
        """(3,) toe-base joint minus ankle joint with the foot flat, foot frame (= rest frame), metres."""
        return self.rest_joints[10] - self.rest_joints[7]

    @property
    def heel_to_toe(self) -> np.ndarray:
        """(3,) toe-base joint minus the heel's floor contact point with the foot flat, metres."""
        return np.array([0.0, (_TOE_FORWARD + _HEEL_BACK) * self.height, TOE_HEIGHT_M])

    @property
    def pelvis_height(self) -> float:
        """Standing pelvis height above the floor (m)."""
        return float(self.rest_joints[0, 2])


def make_body(height: float) -> Body:
    """Rest skeleton for a body of ``height`` metres (see the module docstring for the proportions)."""
    return Body(height=float(height), rest_joints=rest_joints(height))


def rest_joints(height: float) -> np.ndarray:
    """(22, 3) float64 rest joint positions for body height ``height`` (m): z up, facing +y, right = +x."""
    h = float(height)
    fr = _REST_FRACTIONS
    joints = np.zeros((NUM_JOINTS, 3))

    def put(index: int, frac: tuple[float, float, float], side: float = 1.0) -> None:
        joints[index] = (side * frac[0] * h, frac[1] * h, frac[2] * h)

    put(0, fr["pelvis"])
    for side, offset in ((-1.0, 0), (1.0, 1)):  # left joints at -x, right joints at +x
        put(1 + offset, fr["hip"], side)
        put(4 + offset, fr["knee"], side)
        put(7 + offset, fr["ankle"], side)
        joints[10 + offset] = (side * _HIP_HALF_WIDTH * h, _TOE_FORWARD * h, TOE_HEIGHT_M)
        put(13 + offset, fr["collar"], side)
        put(16 + offset, fr["shoulder"], side)
        put(18 + offset, fr["elbow"], side)
        put(20 + offset, fr["wrist"], side)
    spine_length = (_NECK_HEIGHT - _PELVIS_HEIGHT) * h
    for index, frac in zip((3, 6, 9), _SPINE_FRACTIONS):
        joints[index] = (0.0, 0.0, _PELVIS_HEIGHT * h + frac * spine_length)
    joints[12] = (0.0, 0.0, _NECK_HEIGHT * h)
    put(15, fr["head"])
    return joints


# --- rotations (numpy, float64; matrices act on column vectors) ---------------------------------------------


def rot_x(angle: np.ndarray) -> np.ndarray:
    """(...,) radians -> (..., 3, 3) rotation about +x (body right); positive tips +y towards +z."""
    c, s = np.cos(angle), np.sin(angle)
    o, z = np.ones_like(c), np.zeros_like(c)
    return np.stack((o, z, z, z, c, -s, z, s, c), axis=-1).reshape(*np.shape(angle), 3, 3)


def rot_y(angle: np.ndarray) -> np.ndarray:
    """(...,) radians -> (..., 3, 3) rotation about +y (forward); positive tips +z towards +x."""
    c, s = np.cos(angle), np.sin(angle)
    o, z = np.ones_like(c), np.zeros_like(c)
    return np.stack((c, z, s, z, o, z, -s, z, c), axis=-1).reshape(*np.shape(angle), 3, 3)


def rot_z(angle: np.ndarray) -> np.ndarray:
    """(...,) radians -> (..., 3, 3) rotation about +z; positive is counter-clockwise seen from above."""
    c, s = np.cos(angle), np.sin(angle)
    o, z = np.ones_like(c), np.zeros_like(c)
    return np.stack((c, -s, z, s, c, z, z, z, o), axis=-1).reshape(*np.shape(angle), 3, 3)


def yaw_roll_pitch(yaw: np.ndarray, roll: np.ndarray, pitch: np.ndarray) -> np.ndarray:
    """(...,) angles in radians -> (..., 3, 3) ``Rz(yaw) @ Ry(roll) @ Rx(pitch)``.

    With the body's axes: positive yaw turns left, positive roll leans right, positive pitch leans back (or
    lifts the toes / swings a limb forward, for a segment hanging down).
    """
    return rot_z(yaw) @ rot_y(roll) @ rot_x(pitch)


def _normalize(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _segment_frame(direction: np.ndarray, hinge: np.ndarray) -> np.ndarray:
    """(T, 3, 3) world frame of a leg segment pointing along ``direction`` with knee hinge ``hinge`` (+x).

    Columns: x = hinge, y = z cross x, z = -direction; a vertical segment with hinge +x gives the identity,
    which is its rest frame.
    """
    z = -direction
    y = np.cross(z, hinge)
    return np.stack((hinge, y, z), axis=-1)


def two_bone_ik(
    hip: np.ndarray, ankle: np.ndarray, pole: np.ndarray, thigh: float, shank: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Analytic leg IK: thigh and shank directions that put the ankle at ``ankle``.

    The knee bends in the plane spanned by the hip->ankle line and ``pole`` (towards the pole). Targets
    beyond reach are approached along the hip->ankle line with the leg straight (callers lower the pelvis so
    that stance targets are always reachable).

    Args:
        hip: (T, 3) hip joint positions, world, metres.
        ankle: (T, 3) ankle targets, world, metres.
        pole: (T, 3) direction the knee should point to (usually the foot's forward direction).
        thigh, shank: segment lengths in metres.

    Returns:
        (thigh_dir, shank_dir, hinge): (T, 3) unit vectors; ``hinge`` is the knee axis (body right for a
        forward-pointing knee), about which the knee flexes by a negative angle.
    """
    to_ankle = ankle - hip
    dist = np.linalg.norm(to_ankle, axis=-1, keepdims=True)
    along = to_ankle / np.maximum(dist, 1e-9)
    dist = np.clip(dist, abs(thigh - shank) + 1e-6, (thigh + shank) * (1.0 - 1e-9))
    cos_hip = np.clip((thigh**2 + dist**2 - shank**2) / (2.0 * thigh * dist), -1.0, 1.0)
    sin_hip = np.sqrt(1.0 - cos_hip**2)
    side = pole - np.sum(pole * along, axis=-1, keepdims=True) * along
    degenerate = np.linalg.norm(side, axis=-1, keepdims=True) < 1e-6
    side = np.where(degenerate, np.array([0.0, 1.0, 0.0]), side)  # only for a leg aimed along its pole
    side = _normalize(side)
    thigh_dir = cos_hip * along + sin_hip * side
    knee = hip + thigh * thigh_dir
    shank_dir = _normalize(hip + dist * along - knee)
    hinge = _normalize(np.cross(along, side))
    return thigh_dir, shank_dir, hinge


def leg_rotations(
    parent_rot: np.ndarray, thigh_dir: np.ndarray, shank_dir: np.ndarray, hinge: np.ndarray, foot_rot: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Local hip, knee and ankle rotations (SMPL convention) from world segment directions.

    Args:
        parent_rot: (T, 3, 3) world rotation of the pelvis.
        thigh_dir, shank_dir, hinge: (T, 3) from ``two_bone_ik``.
        foot_rot: (T, 3, 3) world rotation of the foot (rest foot -> world).

    Returns:
        (hip_local, knee_local, ankle_local): (T, 3, 3) each; the knee is a pure rotation about its hinge.
    """
    hip_world = _segment_frame(thigh_dir, hinge)
    knee_world = _segment_frame(shank_dir, hinge)
    hip_local = np.swapaxes(parent_rot, -1, -2) @ hip_world
    knee_local = np.swapaxes(hip_world, -1, -2) @ knee_world
    ankle_local = np.swapaxes(knee_world, -1, -2) @ foot_rot
    return hip_local, knee_local, ankle_local


def world_rotations(local_rot: np.ndarray) -> np.ndarray:
    """(T, 22, 3, 3) local rotations -> (T, 22, 3, 3) world rotations along the SMPL kinematic tree."""
    world = np.empty_like(local_rot)
    world[:, 0] = local_rot[:, 0]
    for j in range(1, NUM_JOINTS):
        world[:, j] = world[:, PARENTS[j]] @ local_rot[:, j]
    return world


# --- numpy twins of latentrl.motion.rotations / skeleton for the generator's hot path ----------------------
# The generator works in numpy on a few hundred frames at a time, where torch's per-op overhead (and thread
# start-up on a busy 2-core machine) costs more than the arithmetic. Results agree with the torch versions to
# float64 precision; tests check this.


def axis_angle_to_matrix_np(axis_angle: np.ndarray) -> np.ndarray:
    """(..., 3) axis-angle (radians) -> (..., 3, 3) by Rodrigues' formula; first order below 1e-8 rad."""
    angle = np.linalg.norm(axis_angle, axis=-1)[..., None, None]
    x, y, z = np.moveaxis(axis_angle, -1, 0)
    zero = np.zeros_like(x)
    skew = np.stack((zero, -z, y, z, zero, -x, -y, x, zero), axis=-1).reshape(*x.shape, 3, 3)
    safe = np.where(angle < 1e-8, 1.0, angle)
    k = skew / safe
    rot = np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)
    return np.where(angle < 1e-8, np.eye(3) + skew, rot)


def matrix_to_axis_angle_np(matrix: np.ndarray) -> np.ndarray:
    """(..., 3, 3) rotations -> (..., 3) axis-angle with angle in [0, pi] (via Shepperd's quaternion)."""
    m = matrix
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    d21, d02, d10 = m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]
    s10, s02, s21 = m[..., 1, 0] + m[..., 0, 1], m[..., 0, 2] + m[..., 2, 0], m[..., 2, 1] + m[..., 1, 2]
    diag = np.stack((1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22, 1 - m00 - m11 + m22), -1)
    root = np.sqrt(np.maximum(diag, 1e-12))
    cands = np.stack((  # (w, x, y, z) * 4 * component, one row per choice of the largest component
        np.stack((root[..., 0] ** 2, d21, d02, d10), -1),
        np.stack((d21, root[..., 1] ** 2, s10, s02), -1),
        np.stack((d02, s10, root[..., 2] ** 2, s21), -1),
        np.stack((d10, s02, s21, root[..., 3] ** 2), -1),
    ), -2) / (2.0 * root[..., None])
    best = np.argmax(diag, axis=-1)[..., None, None]
    quat = np.take_along_axis(cands, np.broadcast_to(best, (*best.shape[:-2], 1, 4)), -2)[..., 0, :]
    quat = quat / np.linalg.norm(quat, axis=-1, keepdims=True)
    quat = np.where(quat[..., :1] < 0, -quat, quat)
    sin_half = np.linalg.norm(quat[..., 1:], axis=-1, keepdims=True)
    angle = 2.0 * np.arctan2(sin_half, quat[..., :1])
    scale = np.where(sin_half < 1e-8, 2.0, angle / np.maximum(sin_half, 1e-12))
    return quat[..., 1:] * scale


def forward_kinematics_np(rest: np.ndarray, local_rot: np.ndarray, transl: np.ndarray) -> np.ndarray:
    """(T, 22, 3) world joints from (22, 3) rest joints, (T, 22, 3, 3) local rotations, (T, 3) translation."""
    world = world_rotations(local_rot)
    pos = np.empty((len(local_rot), NUM_JOINTS, 3))
    pos[:, 0] = transl + rest[0]
    for j in range(1, NUM_JOINTS):
        p = PARENTS[j]
        pos[:, j] = pos[:, p] + world[:, p] @ (rest[j] - rest[p])
    return pos
