"""Goals seen from the body: DART's goal observation and the body's forward axis.

World frame: metres, z up. The body's forward axis is DART's (``get_new_coordinate``): the
hip axis ``right_hip - left_hip`` flattened onto the floor gives +x, and forward is
``z x x``, i.e. +y of the canonical frame built from that frame.
"""

from __future__ import annotations

import math

import torch

from latentrl.constants import OBS_GOAL_ANGLE_CLIP_DEG, OBS_GOAL_DIST_CLIP_M
from latentrl.motion.canonical import canonical_frame


def body_forward(joints: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(N, 22, 3) world joints of one frame -> ((N, 3) unit forward axis with z = 0, (N, 3) pelvis)."""
    axes, pelvis = canonical_frame(joints)
    return axes[:, :, 1], pelvis


def rotate_xy(vectors: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    """(N, >=2) vectors turned counter-clockwise about +z by (N,) ``angle`` radians -> (N, 2) xy."""
    c, s = torch.cos(angle), torch.sin(angle)
    x, y = vectors[:, 0], vectors[:, 1]
    return torch.stack((c * x - s * y, s * x + c * y), dim=-1)


def goal_features(
    last_frame_joints: torch.Tensor,
    canonical_rotation: torch.Tensor,
    goal_world: torch.Tensor,
    angle_clip_deg: float = OBS_GOAL_ANGLE_CLIP_DEG,
    dist_clip: float = OBS_GOAL_DIST_CLIP_M,
) -> torch.Tensor:
    """DART's goal observation: clipped unit direction (canonical frame) and clipped distance.

    The direction is the xy vector from the pelvis of the **last** history frame to the goal,
    turned toward that frame's forward axis so that it lies within ``angle_clip_deg`` of it
    (the turn's sign is that of ``(forward x goal).z``; a goal exactly behind gives sign 0,
    i.e. straight forward), then expressed in the canonical frame of **history frame 0**.

    Args:
        last_frame_joints: (N, 22, 3) world joints of the last history frame.
        canonical_rotation: (N, 3, 3) canonical-to-world rotation of the history.
        goal_world: (N, 3) goal, world (z ignored).
        angle_clip_deg: half-width of the direction cone, degrees (DART 60).
        dist_clip: distance clip, metres (DART 5).

    Returns:
        (N, 4): ``goal_dir`` (3, unit, horizontal in the world) and ``goal_dist`` (1, metres).
    """
    forward, pelvis = body_forward(last_frame_joints)
    to_goal = goal_world[:, :2] - pelvis[:, :2]
    dist = torch.linalg.vector_norm(to_goal, dim=-1, keepdim=True)
    direction = to_goal / dist.clamp(min=1e-12)
    cos = (direction * forward[:, :2]).sum(-1).clamp(math.cos(math.radians(angle_clip_deg)), 1.0)
    sign = torch.sign(forward[:, 0] * direction[:, 1] - forward[:, 1] * direction[:, 0])
    clipped = torch.cat((rotate_xy(forward, torch.acos(cos) * sign), torch.zeros_like(dist)), dim=-1)
    local = (clipped[:, None, :] @ canonical_rotation)[:, 0]  # R^T v
    return torch.cat((local, dist.clamp(max=dist_clip)), dim=-1)
