import math

import torch

from latentrl.motion.rotations import (
    axis_angle_to_matrix,
    matrix_to_axis_angle,
    matrix_to_quaternion,
    matrix_to_rotation_6d,
    quaternion_to_matrix,
    rotation_6d_to_matrix,
    rotation_about_z,
)


def random_rotations(n=500, seed=0):
    g = torch.Generator().manual_seed(seed)
    return axis_angle_to_matrix(torch.randn(n, 3, generator=g) * 1.5)


def test_6d_is_first_two_rows():
    r = random_rotations(4)
    d6 = matrix_to_rotation_6d(r)
    torch.testing.assert_close(d6[:, :3], r[:, 0])
    torch.testing.assert_close(d6[:, 3:], r[:, 1])


def test_6d_round_trip_and_gram_schmidt():
    r = random_rotations()
    torch.testing.assert_close(rotation_6d_to_matrix(matrix_to_rotation_6d(r)), r, atol=1e-5, rtol=0)
    noisy = matrix_to_rotation_6d(r) * 1.7 + 0.01
    m = rotation_6d_to_matrix(noisy)
    torch.testing.assert_close(m @ m.transpose(-1, -2), torch.eye(3).expand(len(m), 3, 3), atol=1e-5, rtol=0)
    assert torch.allclose(torch.det(m), torch.ones(len(m)), atol=1e-5)


def test_axis_angle_round_trips_including_near_pi_and_zero():
    g = torch.Generator().manual_seed(1)
    axes = torch.nn.functional.normalize(torch.randn(200, 3, generator=g), dim=-1)
    angles = torch.cat([torch.full((50,), math.pi - 1e-4), torch.full((50,), 1e-9), torch.rand(100, generator=g) * 3])
    aa = axes * angles[:, None]
    r = axis_angle_to_matrix(aa)
    torch.testing.assert_close(axis_angle_to_matrix(matrix_to_axis_angle(r)), r, atol=1e-5, rtol=0)
    torch.testing.assert_close(quaternion_to_matrix(matrix_to_quaternion(r)), r, atol=1e-5, rtol=0)


def test_rotation_about_z_turns_y_to_minus_x():
    r = rotation_about_z(torch.tensor(math.pi / 2))
    torch.testing.assert_close(r @ torch.tensor([0.0, 1.0, 0.0]), torch.tensor([-1.0, 0.0, 0.0]), atol=1e-6, rtol=0)
