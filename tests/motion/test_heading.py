"""The hip-axis heading kernel: known answers on hand-made turning bodies."""

import math

import numpy as np
import torch

from latentrl.evaluation import metrics as M
from latentrl.motion.heading import hip_yaw_rad


def _turning_body(total_rad: float, frames: int = 91) -> torch.Tensor:
    """(frames, 22, 3) joints whose hips turn at a constant rate by ``total_rad`` (start: hip axis along +x)."""
    yaw = torch.linspace(0.0, total_rad, frames, dtype=torch.float64)
    joints = torch.zeros(frames, 22, 3, dtype=torch.float64)
    axis = torch.stack((torch.cos(yaw), torch.sin(yaw)), dim=-1) * 0.1
    joints[:, 1, :2], joints[:, 2, :2] = -axis, axis
    return joints


def test_three_full_turns_unwrap_to_six_pi_both_ways():
    for total in (6 * math.pi, -6 * math.pi, 0.5):
        yaw = hip_yaw_rad(_turning_body(total))
        assert yaw.shape == (91,)
        assert abs(float(yaw[-1] - yaw[0]) - total) < 1e-9
        assert abs(float(M.heading_change_rad(_turning_body(total))) - total) < 1e-9
        assert float(yaw.diff().abs().max()) <= math.pi


def test_batched_and_numpy_callers_agree():
    body = torch.stack((_turning_body(1.0), _turning_body(-2.0)))
    yaw = hip_yaw_rad(body)
    assert yaw.shape == (2, 91)
    assert torch.allclose(yaw[1], hip_yaw_rad(_turning_body(-2.0)))
    # the generator's statistics pass float64 numpy joints through torch.from_numpy
    assert np.allclose(hip_yaw_rad(torch.from_numpy(body[0].numpy())).numpy(), yaw[0].numpy())
