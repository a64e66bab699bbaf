"""A motion as the humanoid's reference: root pose, hinge angles and their velocities per frame.

The motion's 276-D features carry SMPL joint rotations (each relative to its parent, from latentrl's rest
pose, which is the humanoid's zero pose). A motion model predicts those rotations and the joint positions
separately, and the two disagree (on the default model's walk, forward kinematics of its rotations puts the
feet 7-9 cm from its own foot joints). The joint positions are what the user sees and what every metric
reads, so :func:`reference_rotations` keeps each rotation's twist from the features and turns its bone
onto the joint positions (the smallest swing); the pelvis and spine3, which have several children, take
the best rigid fit of their children (Kabsch). Leaves (head, wrists, toes) keep the features' rotation.
A motion without features (an evaluation's episode files) gets its rotations from the joints alone: the
same swings, starting from the parent's orientation (bones keep no twist of their own).

Bone lengths differ too: the humanoid is rigid, a generated motion is not (the default model's run
stretches a shank between 0.31 and 0.69 m). Swinging bones alone would then carry every length difference
down to the feet, so the legs are solved last by two-bone IK (:func:`leg_ik`): each ankle goes where the
motion's is, each toe points at the motion's toe, with heights such that the motion's usual contact height
becomes the humanoid's sole on the floor (:func:`foot_targets`). Where a target is out of reach the pelvis
is lowered just enough for the soles to meet the floor when the motion's feet do (:func:`foot_height_shift`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from latentrl.errors import DataError
from latentrl.motion.skeleton import NUM_JOINTS, PARENTS, children
from latentrl.physics.humanoid import AXIS_ORDER, BODY_JOINTS, SOLE_JOINTS, Humanoid, sole_points

_AXIS = {"x": 0, "y": 1, "z": 2}


def axis_rotation(axis: str, angle: np.ndarray) -> np.ndarray:
    """(...,) radians -> (..., 3, 3) rotation about the body axis 'x', 'y' or 'z'."""
    c, s = np.cos(angle), np.sin(angle)
    i = _AXIS[axis]
    j, k = (i + 1) % 3, (i + 2) % 3
    out = np.zeros((*np.shape(angle), 3, 3))
    out[..., i, i] = 1.0
    out[..., j, j] = c
    out[..., k, k] = c
    out[..., k, j] = s
    out[..., j, k] = -s
    return out


def euler_angles(rotation: np.ndarray, order: str) -> np.ndarray:
    """(..., 3, 3) -> (..., 3) angles with ``R = R_a(q0) R_b(q1) R_c(q2)`` for ``order`` = 'abc' (distinct axes)."""
    i, j, k = (_AXIS[a] for a in order)
    s = 1.0 if (j - i) % 3 == 1 else -1.0  # cyclic (xyz, yzx, zxy) or not
    r = rotation
    middle = np.arcsin(np.clip(s * r[..., i, k], -1.0, 1.0))
    first = np.arctan2(-s * r[..., j, k], r[..., k, k])
    last = np.arctan2(-s * r[..., i, j], r[..., i, i])
    return np.stack((first, middle, last), axis=-1)


def euler_matrix(angles: np.ndarray, order: str) -> np.ndarray:
    """Inverse of :func:`euler_angles`: (..., 3) angles -> (..., 3, 3)."""
    a = np.asarray(angles)
    return axis_rotation(order[0], a[..., 0]) @ axis_rotation(order[1], a[..., 1]) @ axis_rotation(order[2], a[..., 2])


def hinge_angles(local: np.ndarray) -> np.ndarray:
    """(T, 22, 3, 3) local rotations -> (T, 63) hinge angles (joints 1..21, axes in :data:`AXIS_ORDER`), unwrapped."""
    angles = np.concatenate([euler_angles(local[:, j], AXIS_ORDER[j]) for j in BODY_JOINTS], axis=-1)
    return np.unwrap(angles, axis=0)


def _swing(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(T, 3), (T, 3) -> (T, 3, 3): the smallest rotation turning direction u onto direction v."""
    u = u / np.linalg.norm(u, axis=-1, keepdims=True).clip(1e-9)
    v = v / np.linalg.norm(v, axis=-1, keepdims=True).clip(1e-9)
    axis = np.cross(u, v)
    sin = np.linalg.norm(axis, axis=-1)
    cos = np.sum(u * v, axis=-1)
    angle = np.arctan2(sin, cos)
    n = axis / sin.clip(1e-12)[:, None]
    n[sin < 1e-12] = 0.0  # parallel: no turn (anti-parallel bones do not occur in a body)
    kx = np.zeros((len(u), 3, 3))
    kx[:, 0, 1], kx[:, 0, 2], kx[:, 1, 2] = -n[:, 2], n[:, 1], -n[:, 0]
    kx = kx - kx.transpose(0, 2, 1)
    eye = np.eye(3)[None]
    return eye + np.sin(angle)[:, None, None] * kx + (1 - np.cos(angle))[:, None, None] * (kx @ kx)


def _kabsch(rest_vectors: np.ndarray, world_vectors: np.ndarray) -> np.ndarray:
    """(C, 3) rest offsets, (T, C, 3) world offsets -> (T, 3, 3) rotations best mapping the first onto the second."""
    cov = np.einsum("ca,tcb->tba", rest_vectors, world_vectors)
    u, _, vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(u @ vt))
    fix = np.ones((len(cov), 3))
    fix[:, 2] = d
    return (u * fix[:, None, :]) @ vt


def global_rotations(local: np.ndarray) -> np.ndarray:
    """(T, 22, 3, 3) local rotations -> world rotations by chaining along :data:`PARENTS`."""
    out = np.empty_like(local)
    out[:, 0] = local[:, 0]
    for j in range(1, NUM_JOINTS):
        out[:, j] = out[:, PARENTS[j]] @ local[:, j]
    return out


def local_rotations(world: np.ndarray) -> np.ndarray:
    """Inverse of :func:`global_rotations`."""
    out = np.empty_like(world)
    out[:, 0] = world[:, 0]
    for j in range(1, NUM_JOINTS):
        out[:, j] = world[:, PARENTS[j]].transpose(0, 2, 1) @ world[:, j]
    return out


def features_rotations(features: np.ndarray) -> np.ndarray:
    """(T, 276) world features -> (T, 22, 3, 3) local rotations (6D rows, Gram-Schmidt)."""
    d6 = np.asarray(features, dtype=np.float64)[:, 3:135].reshape(len(features), NUM_JOINTS, 6)
    a, b = d6[..., :3], d6[..., 3:]
    r0 = a / np.linalg.norm(a, axis=-1, keepdims=True).clip(1e-9)
    b = b - np.sum(r0 * b, axis=-1, keepdims=True) * r0
    r1 = b / np.linalg.norm(b, axis=-1, keepdims=True).clip(1e-9)
    return np.stack((r0, r1, np.cross(r0, r1)), axis=-2)


def reference_rotations(local: np.ndarray | None, joints: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """Local rotations whose forward kinematics on ``rest`` follows ``joints`` (see the module docstring).

    Args:
        local: (T, 22, 3, 3) the features' local rotations, or None for a motion without features: then each
            bone swings from its parent's orientation (no twist of its own) and leaves follow their parent.
        joints: (T, 22, 3) the motion's joint positions.
        rest: (22, 3) the humanoid's rest joints.

    Returns:
        (T, 22, 3, 3) corrected local rotations.
    """
    world = np.tile(np.eye(3), (len(joints), NUM_JOINTS, 1, 1)) if local is None else global_rotations(local)
    feat = world.copy()
    for j in range(NUM_JOINTS):
        if local is None and j > 0:
            feat[:, j] = world[:, PARENTS[j]]
            world[:, j] = feat[:, j]
        kids = children(j)
        if len(kids) > 1:
            world[:, j] = _kabsch(rest[kids] - rest[j], joints[:, kids] - joints[:, j : j + 1])
        elif len(kids) == 1:
            c = kids[0]
            bone = np.einsum("tab,b->ta", feat[:, j], rest[c] - rest[j])
            world[:, j] = _swing(bone, joints[:, c] - joints[:, j]) @ feat[:, j]
    return local_rotations(world)


@dataclass
class Reference:
    """What the tracker follows, one row per motion frame.

    Attributes:
        fps: frames per second.
        joints: (T, 22, 3) the motion's joints (what tracking error is measured against).
        root_pos: (T, 3) pelvis position.
        root_rot: (T, 3, 3) pelvis orientation (rest body -> world).
        angles: (T, 63) hinge angles.
        root_vel: (T, 3) pelvis velocity, m/s. root_angvel: (T, 3) world angular velocity, rad/s.
        angle_vel: (T, 63) hinge angle velocities, rad/s.
    """

    fps: float
    joints: np.ndarray
    root_pos: np.ndarray
    root_rot: np.ndarray
    angles: np.ndarray
    root_vel: np.ndarray
    root_angvel: np.ndarray
    angle_vel: np.ndarray

    @property
    def frames(self) -> int:
        """Number of frames."""
        return len(self.joints)


FOOT_AND_ANKLE = (7, 8, 10, 11)


def forward_joints(rest: np.ndarray, local: np.ndarray, root_pos: np.ndarray) -> np.ndarray:
    """(22, 3) rest, (T, 22, 3, 3) local rotations, (T, 3) pelvis -> (T, 22, 3) joints of the rigid humanoid."""
    world = global_rotations(local)
    out = np.empty((len(local), NUM_JOINTS, 3))
    out[:, 0] = root_pos
    for j in range(1, NUM_JOINTS):
        p = PARENTS[j]
        out[:, j] = out[:, p] + np.einsum("tab,b->ta", world[:, p], rest[j] - rest[p])
    return out


def foot_height_shift(rest: np.ndarray, height: float, local: np.ndarray, joints: np.ndarray,
                      contact: np.ndarray | None = None) -> np.ndarray:
    """(T,) metres to add to the pelvis height so the humanoid's soles touch the floor when the motion's feet do.

    The motion's foot joints are on the floor at their ``contact`` heights (:func:`contact_heights`: about 0 for
    a floor-snapped rollout's toes, 2 cm for latentrl's training data); each frame the humanoid's lowest sole
    corner is put as far above the floor as the motion's foot joint nearest its contact height is above it.
    """
    fk = forward_joints(rest, local, joints[:, 0])
    world = global_rotations(local)[:, SOLE_JOINTS]
    corners = fk[:, SOLE_JOINTS, None, :] + np.einsum("tjab,jcb->tjca", world, sole_points(rest, height))
    sole = corners[..., 2].reshape(len(joints), -1).min(-1)
    above = joints[:, FOOT_AND_ANKLE, 2] - (contact_heights(joints) if contact is None else np.asarray(contact))
    return above.min(-1) - sole


def _rate(x: np.ndarray, fps: float) -> np.ndarray:
    return np.gradient(x, axis=0) * fps if len(x) > 1 else np.zeros_like(x)


def _angular_velocity(rot: np.ndarray, fps: float) -> np.ndarray:
    """(T, 3, 3) world rotations -> (T, 3) world angular velocity from R' R^T (central differences)."""
    if len(rot) < 2:
        return np.zeros((len(rot), 3))
    d = _rate(rot, fps) @ rot.transpose(0, 2, 1)
    return np.stack((d[:, 2, 1] - d[:, 1, 2], d[:, 0, 2] - d[:, 2, 0], d[:, 1, 0] - d[:, 0, 1]), axis=-1) / 2


LEGS = ((1, 4, 7, 10), (2, 5, 8, 11))
"""(hip, knee, ankle, toe base) of the left and the right leg."""


def contact_heights(joints: np.ndarray) -> np.ndarray:
    """(4,) each of a motion's ankles and toe bases' usual height on the floor: its 5th percentile over the clip."""
    return np.percentile(np.asarray(joints)[:, FOOT_AND_ANKLE, 2], 5, axis=0)


def foot_targets(joints: np.ndarray, rest: np.ndarray, contact: np.ndarray | None = None) -> np.ndarray:
    """(T, 4, 3) where the humanoid's ankles and toe bases (7, 8, 10, 11) should be.

    The motion's own ones, raised or lowered so that each joint's usual contact height in the motion
    (``contact``, default :func:`contact_heights` of ``joints``) becomes the humanoid's height of that joint
    standing flat.
    """
    feet = joints[:, FOOT_AND_ANKLE].copy()
    contact = contact_heights(joints) if contact is None else np.asarray(contact)
    feet[..., 2] += rest[list(FOOT_AND_ANKLE), 2] - contact
    return feet


def leg_ik(local: np.ndarray, root_pos: np.ndarray, rest: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Local rotations with each leg bent to put its ankle on its target (two-bone IK) and its toe toward its own.

    The knee stays in the plane the current pose bends it in; a target out of reach straightens the leg towards
    it. ``targets``: (T, 4, 3) from :func:`foot_targets` (order of ``FOOT_AND_ANKLE``).
    """
    world = global_rotations(local)
    pos = forward_joints(rest, local, root_pos)
    for side, (hip, knee, ankle, toe) in enumerate(LEGS):
        ankle_goal, toe_goal = targets[:, side], targets[:, 2 + side]
        l1 = float(np.linalg.norm(rest[knee] - rest[hip]))
        l2 = float(np.linalg.norm(rest[ankle] - rest[knee]))
        h = pos[:, hip]
        d = ankle_goal - h
        dist = np.linalg.norm(d, axis=-1, keepdims=True).clip(1e-9)
        axis = d / dist
        dist = dist.clip(abs(l1 - l2) + 1e-4, l1 + l2 - 1e-4)
        along = (l1**2 - l2**2 + dist**2) / (2 * dist)
        radial = np.sqrt(np.clip(l1**2 - along**2, 0.0, None))
        pole = pos[:, knee] - h
        pole = pole - np.sum(pole * axis, axis=-1, keepdims=True) * axis
        pole /= np.linalg.norm(pole, axis=-1, keepdims=True).clip(1e-9)
        k = h + along * axis + radial * pole
        a = h + dist * axis
        for joint, child, start, end in ((hip, knee, h, k), (knee, ankle, k, a), (ankle, toe, a, toe_goal)):
            bone = np.einsum("tab,b->ta", world[:, joint], rest[child] - rest[joint])
            world[:, joint] = _swing(bone, end - start) @ world[:, joint]
            if joint != ankle:  # children follow their parent until their own turn
                world[:, child] = _swing(bone, end - start) @ world[:, child]
        world[:, toe] = world[:, ankle] @ local[:, toe]
    return local_rotations(world)


def build_reference(joints: np.ndarray, features: np.ndarray | None, fps: float, humanoid: Humanoid,
                    contact: np.ndarray | None = None) -> Reference:
    """The :class:`Reference` of a motion, (T, 22, 3) joints and (T, 276) world features or None, on ``humanoid``.

    ``contact``: the motion's foot-joint contact heights (default: :func:`contact_heights` of ``joints``; a
    motion executed piece by piece passes those of the whole motion so far).
    """
    joints = np.asarray(joints, dtype=np.float64)
    if features is not None:
        features = np.asarray(features, dtype=np.float64)
        if features.ndim != 2 or features.shape != (len(joints), 276):
            raise DataError(f"field 'features' must be (T, 276) with T = {len(joints)} frames, got {features.shape}")
        if not np.isfinite(features).all():
            raise DataError("field 'features' holds NaN or inf")
    rest = humanoid.rest_joints
    local = reference_rotations(None if features is None else features_rotations(features), joints, rest)
    root_pos = joints[:, 0].copy()
    contact = contact_heights(joints) if contact is None else contact
    targets = foot_targets(joints, rest, contact)
    local = leg_ik(local, root_pos, rest, targets)
    root_pos[:, 2] += foot_height_shift(rest, humanoid.height, local, joints, contact)
    local = leg_ik(local, root_pos, rest, targets)
    angles = hinge_angles(local)
    root_rot = local[:, 0]
    return Reference(fps=float(fps), joints=joints, root_pos=root_pos, root_rot=root_rot, angles=angles,
                     root_vel=_rate(root_pos, fps), root_angvel=_angular_velocity(root_rot, fps),
                     angle_vel=_rate(angles, fps))


def fit_height(joints: np.ndarray) -> float:
    """Body height (m) whose rest skeleton best fits a motion's median bone lengths (least squares)."""
    from latentrl.datasets.body import rest_joints

    joints = np.asarray(joints, dtype=np.float64)
    unit = rest_joints(1.0)
    bones = range(1, NUM_JOINTS)
    unit_len = np.array([np.linalg.norm(unit[j] - unit[PARENTS[j]]) for j in bones])
    motion_len = np.array([np.median(np.linalg.norm(joints[:, j] - joints[:, PARENTS[j]], axis=-1)) for j in bones])
    return float((motion_len * unit_len).sum() / (unit_len**2).sum())


def kinematic_joints(rest: np.ndarray, ref: Reference) -> np.ndarray:
    """(T, 22, 3) joints of the humanoid placed exactly on the reference (no physics): the retargeting floor."""
    local = np.empty((ref.frames, NUM_JOINTS, 3, 3))
    local[:, 0] = ref.root_rot
    for i, j in enumerate(BODY_JOINTS):
        local[:, j] = euler_matrix(ref.angles[:, 3 * i : 3 * i + 3], AXIS_ORDER[j])
    return forward_joints(rest, local, ref.root_pos)
