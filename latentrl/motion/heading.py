"""Body heading from the hip axis: the one kernel of the metrics, ``bench motion`` and the data statistics.

The heading of a frame is the yaw of the hip axis (right hip minus left hip) in the xy plane. It is
steadier than the pelvis velocity (defined when standing) and than the root orientation (which sways
with each step). Callers: :func:`latentrl.evaluation.metrics.heading_change_rad` (a rollout's total turn,
``bench motion``'s steer spread) and the generator's ``dataset_statistics`` (the data's steer spread).
"""

from __future__ import annotations

import math

import torch

from latentrl.motion.skeleton import LEFT_HIP, RIGHT_HIP


def hip_yaw_rad(joints: torch.Tensor) -> torch.Tensor:
    """(..., T, 22, 3) world joints -> (..., T) unwrapped hip-axis yaw, radians, + = counter-clockwise.

    Unwrapped: consecutive frames never differ by more than pi, so ``yaw[..., b] - yaw[..., a]`` is the
    signed turn between frames ``a`` and ``b`` however many times the body turned round.
    """
    axis = joints[..., RIGHT_HIP, :2] - joints[..., LEFT_HIP, :2]
    yaw = torch.atan2(axis[..., 1], axis[..., 0])
    step = torch.remainder(yaw[..., 1:] - yaw[..., :-1] + math.pi, 2 * math.pi) - math.pi
    return torch.cat((yaw[..., :1], yaw[..., :1] + step.cumsum(dim=-1)), dim=-1)
