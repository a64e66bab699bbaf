"""SMPL 22-joint skeleton facts shared by every layer.

Joint order, names and parents are SMPL's (and therefore DART's, which uses SMPL-X joints 0-21).
World convention everywhere in latentrl: metres, z up, floor at z = 0, 30 fps.
"""

from __future__ import annotations

import numpy as np

NUM_JOINTS = 22

JOINT_NAMES: tuple[str, ...] = (
    "pelvis",
    "left_hip",
    "right_hip",
    "spine1",
    "left_knee",
    "right_knee",
    "spine2",
    "left_ankle",
    "right_ankle",
    "spine3",
    "left_foot",
    "right_foot",
    "neck",
    "left_collar",
    "right_collar",
    "head",
    "left_shoulder",
    "right_shoulder",
    "left_elbow",
    "right_elbow",
    "left_wrist",
    "right_wrist",
)

#: Parent index of each joint; -1 for the root (pelvis).
PARENTS: tuple[int, ...] = (-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19)

PELVIS = 0
LEFT_HIP = 1
RIGHT_HIP = 2
HEAD = 15
#: DART's ``FOOT_JOINTS_IDX``: left_foot, right_foot (the toe-base joints used for contact).
FOOT_JOINTS: tuple[int, int] = (10, 11)
ANKLE_JOINTS: tuple[int, int] = (7, 8)

#: Left/right mirror pairs (for mirroring augmentation and symmetry checks).
MIRROR: tuple[int, ...] = (0, 2, 1, 3, 5, 4, 6, 8, 7, 9, 11, 10, 12, 14, 13, 15, 17, 16, 19, 18, 21, 20)

FPS = 30


def joint_index(name: str) -> int:
    """Index of a joint by SMPL name; raises ``KeyError`` listing the valid names."""
    try:
        return JOINT_NAMES.index(name)
    except ValueError:
        raise KeyError(f"unknown joint '{name}'; expected one of {', '.join(JOINT_NAMES)}") from None


def children(joint: int) -> list[int]:
    """Direct children of ``joint`` in the kinematic tree."""
    return [j for j, p in enumerate(PARENTS) if p == joint]


def forward_kinematics(rest_joints, rotations, transl):
    """Joint positions from local rotations (SMPL convention).

    Args:
        rest_joints: (..., 22, 3) joint positions of the rest pose with zero translation; the
            pelvis entry is the rest pelvis offset (DART's ``pelvis_delta``).
        rotations: (..., 22, 3, 3) rotation matrices; entry 0 is the global orientation (rest body
            to world), entry j > 0 is joint j's rotation relative to its parent's frame.
        transl: (..., 3) root translation in metres; the pelvis lands at ``transl + R0 @ 0 + rest[0]``
            (the global orientation rotates about the pelvis, as in SMPL).

    Returns:
        (joints, global_rotations): (..., 22, 3) world positions and (..., 22, 3, 3) world rotations.
    """
    import torch

    rest_joints = torch.as_tensor(rest_joints)
    rotations = torch.as_tensor(rotations)
    transl = torch.as_tensor(transl)
    batch = torch.broadcast_shapes(rest_joints.shape[:-2], rotations.shape[:-3], transl.shape[:-1])
    rest_joints = rest_joints.expand(*batch, NUM_JOINTS, 3)
    rotations = rotations.expand(*batch, NUM_JOINTS, 3, 3)
    transl = transl.expand(*batch, 3)
    glob = [rotations[..., 0, :, :]]
    pos = [transl + rest_joints[..., 0, :]]
    for j in range(1, NUM_JOINTS):
        p = PARENTS[j]
        offset = rest_joints[..., j, :] - rest_joints[..., p, :]
        pos.append(pos[p] + (glob[p] @ offset[..., None])[..., 0])
        glob.append(glob[p] @ rotations[..., j, :, :])
    return torch.stack(pos, dim=-2), torch.stack(glob, dim=-3)

# Approximate SMPL neutral T-pose offsets of each joint from its parent (metres, z up, facing +y,
# +x = body right). Only the directions are used: bone lengths come from the motion itself.
SMPL_REST_OFFSETS = np.array([
    [0.0, 0.0, 0.0],
    [-0.059, -0.018, -0.082], [0.061, -0.014, -0.091], [0.0, -0.030, 0.109],
    [-0.043, 0.009, -0.386], [0.043, 0.005, -0.384], [0.0, 0.0, 0.135],
    [0.015, -0.037, -0.427], [-0.015, -0.035, -0.424], [0.0, 0.025, 0.053],
    [-0.041, 0.122, -0.060], [0.035, 0.126, -0.062], [0.0, -0.034, 0.212],
    [-0.072, -0.019, 0.114], [0.083, -0.024, 0.112], [0.0, 0.050, 0.089],
    [-0.123, -0.019, 0.045], [0.113, -0.008, 0.047], [-0.255, -0.023, -0.016],
    [0.260, -0.014, -0.013], [-0.266, -0.007, 0.013], [0.269, -0.006, 0.007],
])


def rest_offsets(joints: np.ndarray) -> np.ndarray:
    """(22, 3) rest offsets of a motion (T, 22, 3), z-up metres: SMPL T-pose directions times its median bone lengths.

    The skeleton BVH export writes (with :data:`PARENTS`) and motion files carry (``rest_offsets``).
    """
    joints = np.asarray(joints)
    offsets = SMPL_REST_OFFSETS.copy()
    for j in range(1, NUM_JOINTS):
        length = float(np.median(np.linalg.norm(joints[:, j] - joints[:, PARENTS[j]], axis=-1)))
        if length > 1e-6:
            direction = offsets[j] / np.linalg.norm(offsets[j])
            offsets[j] = direction * length
    return offsets
