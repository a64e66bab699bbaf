"""DART's canonical frame, the feature transform, and world-transform bookkeeping.

Each primitive lives in the frame of its **first history frame**: origin at that frame's 3-D
pelvis, +x the right_hip - left_hip direction projected onto the floor plane, +z up, +y = z x x
(forward). A rollout keeps, per sequence, the transform from the current canonical frame to the
world: ``p_world = R_w @ p_canonical + t_w``.

Transforming features into a frame with axes ``R`` (columns, expressed in the old frame) and
origin ``t`` (DART's ``canonicalize`` with ``use_predicted_joints=1``), ``d`` = ``pelvis_delta``:

- ``transl' = R^T (transl + d - t) - d``   (the pelvis, not ``transl``, is what rotates)
- ``global_orient' = R^T G``;  body-joint 6D values are unchanged
- ``joints' = R^T (J - t)``;  ``transl_delta`` and ``joints_delta`` are rotated by ``R^T``
- ``global_orient_delta' = R^T Delta R``
"""

from __future__ import annotations

from typing import NamedTuple

import torch
import torch.nn.functional as F

from latentrl.motion.representation import Frames, join_frames, joints_of, split_frames
from latentrl.motion.rotations import matrix_to_rotation_6d, rotation_6d_to_matrix
from latentrl.motion.skeleton import LEFT_HIP, PELVIS, RIGHT_HIP


class WorldTransform(NamedTuple):
    """Canonical-to-world rigid transform per sequence: ``p_world = rotation @ p + translation``."""

    rotation: torch.Tensor  # (B, 3, 3)
    translation: torch.Tensor  # (B, 3) metres

    def apply(self, points: torch.Tensor) -> torch.Tensor:
        """(B, ..., 3) canonical points -> world points."""
        shape = points.shape
        flat = points.reshape(shape[0], -1, 3)
        out = flat @ self.rotation.transpose(-1, -2) + self.translation[:, None, :]
        return out.reshape(shape)

    def inverse_apply(self, points: torch.Tensor) -> torch.Tensor:
        """(B, ..., 3) world points -> canonical points."""
        shape = points.shape
        flat = points.reshape(shape[0], -1, 3)
        out = (flat - self.translation[:, None, :]) @ self.rotation
        return out.reshape(shape)

    def compose(self, rotation: torch.Tensor, translation: torch.Tensor) -> WorldTransform:
        """World transform of a new canonical frame given as (R, t) in the current canonical frame."""
        new_t = (self.rotation @ translation[..., None])[..., 0] + self.translation
        return WorldTransform(self.rotation @ rotation, new_t)

    def index(self, mask_or_idx) -> WorldTransform:
        """The transforms of the selected sequences (boolean mask or indices), e.g. the envs being reset."""
        return WorldTransform(self.rotation[mask_or_idx], self.translation[mask_or_idx])

    @staticmethod
    def identity(batch: int, device=None, dtype=torch.float32) -> WorldTransform:
        """``batch`` transforms that leave points where they are (canonical frame = world frame)."""
        eye = torch.eye(3, device=device, dtype=dtype).expand(batch, 3, 3).clone()
        return WorldTransform(eye, torch.zeros(batch, 3, device=device, dtype=dtype))


def canonical_frame(joints: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Canonical axes and origin from one frame of joints.

    Args:
        joints: (B, 22, 3) joint positions in the current frame.

    Returns:
        ``(R, t)``: (B, 3, 3) with columns x, y, z (the new axes in current coordinates) and
        (B, 3) the pelvis position.
    """
    x_axis = joints[:, RIGHT_HIP] - joints[:, LEFT_HIP]
    x_axis = torch.cat((x_axis[:, :2], torch.zeros_like(x_axis[:, 2:])), dim=-1)
    x_axis = F.normalize(x_axis, dim=-1)
    flat = torch.zeros_like(x_axis[:, 0])
    z_axis = torch.stack((flat, flat, torch.ones_like(flat)), dim=-1)  # (0, 0, 1), built on the device
    y_axis = F.normalize(torch.cross(z_axis, x_axis, dim=-1), dim=-1)
    return torch.stack((x_axis, y_axis, z_axis), dim=-1), joints[:, PELVIS]


def transform_features(
    features: torch.Tensor, rotation: torch.Tensor, origin: torch.Tensor, pelvis_delta: torch.Tensor
) -> torch.Tensor:
    """Express (B, T, 276) features in the frame with axes ``rotation`` (B,3,3) and origin (B,3).

    ``pelvis_delta`` (3,) or (B, 3): rest pelvis offset, ``pelvis = transl + pelvis_delta``.
    """
    f = split_frames(features)
    rt = rotation.transpose(-1, -2)  # (B, 3, 3)
    d = pelvis_delta.expand(features.shape[0], 3)[:, None, :]  # (B, 1, 3)
    t = origin[:, None, :]

    def rotate(v: torch.Tensor) -> torch.Tensor:  # (B, ..., 3) -> R^T v
        shape = v.shape
        return (v.reshape(shape[0], -1, 3) @ rotation).reshape(shape)

    glob = rotation_6d_to_matrix(f.poses_6d[:, :, 0])  # (B, T, 3, 3)
    delta = rotation_6d_to_matrix(f.global_orient_delta_6d)
    poses_6d = f.poses_6d.clone()
    poses_6d[:, :, 0] = matrix_to_rotation_6d(rt[:, None] @ glob)
    out = Frames(
        transl=rotate(f.transl + d - t) - d,
        poses_6d=poses_6d,
        transl_delta=rotate(f.transl_delta),
        global_orient_delta_6d=matrix_to_rotation_6d(rt[:, None] @ delta @ rotation[:, None]),
        joints=rotate(f.joints - t[:, :, None, :]),
        joints_delta=rotate(f.joints_delta),
    )
    return join_frames(out)


def canonicalize(features: torch.Tensor, pelvis_delta: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Move (B, T, 276) features into the canonical frame of their first frame.

    Returns ``(canonical_features, R, t)`` where ``(R, t)`` is the new frame expressed in the old one
    (feed them to :meth:`WorldTransform.compose` to keep world coordinates).
    """
    rotation, origin = canonical_frame(joints_of(features[:, 0]))
    return transform_features(features, rotation, origin, pelvis_delta), rotation, origin


def features_to_world(features: torch.Tensor, world: WorldTransform, pelvis_delta: torch.Tensor) -> torch.Tensor:
    """(B, T, 276) canonical features -> the same features in world coordinates."""
    rot_inv = world.rotation.transpose(-1, -2)
    origin_inv = -(rot_inv @ world.translation[..., None])[..., 0]
    return transform_features(features, rot_inv, origin_inv, pelvis_delta)


def world_to_canonical(features_world: torch.Tensor, pelvis_delta: torch.Tensor) -> tuple[torch.Tensor, WorldTransform]:
    """(B, T, 276) world features -> canonical features plus the world transform that undoes it."""
    canon, rotation, origin = canonicalize(features_world, pelvis_delta)
    return canon, WorldTransform(rotation, origin)
