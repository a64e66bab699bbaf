"""Each kernel on hand-made motions whose answer is known in closed form."""

import math

import pytest
import torch

from latentrl.rewards import terms


def feet_track(left_xyz, right_xyz) -> torch.Tensor:
    """(1, T, 2, 3) foot positions from two (T, 3) tracks."""
    return torch.stack((torch.as_tensor(left_xyz), torch.as_tensor(right_xyz)), dim=1)[None].float()


def test_sliding_foot_on_floor_skates_its_full_displacement():
    t = torch.arange(9.0)
    left = torch.stack((0.01 * t, torch.zeros(9), torch.zeros(9)), -1)  # slides 1 cm per frame on the floor
    right = torch.zeros(9, 3)  # planted
    out = terms.foot_skate(feet_track(left, right))
    # left: 0.01 * (2 - 2^0) per transition, right: 0; mean over 8 transitions x 2 feet
    torch.testing.assert_close(out, torch.tensor([-0.005]))


def test_foot_above_contact_height_does_not_skate_and_the_ramp_is_exponential():
    t = torch.arange(9.0)
    lifted = torch.stack((0.01 * t, torch.zeros(9), torch.full((9,), 0.03)), -1)
    half = torch.stack((0.01 * t, torch.zeros(9), torch.full((9,), 0.015)), -1)
    still = torch.zeros(9, 3)
    assert terms.foot_skate(feet_track(lifted, still)).item() == 0.0
    torch.testing.assert_close(terms.foot_skate(feet_track(half, still)), torch.tensor([-0.01 * (2 - 2**0.5) / 2]))


def test_skate_uses_height_above_the_given_floor():
    t = torch.arange(9.0)
    on_raised_floor = torch.stack((0.01 * t, torch.zeros(9), torch.full((9,), 0.5)), -1)
    out = terms.foot_skate(feet_track(on_raised_floor, on_raised_floor), floor_height=0.5)
    torch.testing.assert_close(out, torch.tensor([-0.01]))


def test_floating_feet_are_penalised_beyond_three_centimetres():
    height = torch.tensor([[[0.13, 0.20]] * 8, [[0.02, 0.5]] * 8, [[-0.05, 0.3]] * 8])  # (3, 8, 2)
    out = terms.foot_floor(height)
    torch.testing.assert_close(out, torch.tensor([-0.10, 0.0, -0.02]))
    scaled = terms.foot_floor(height, scale=torch.tensor([0.1, 1.0, 1.0]))
    torch.testing.assert_close(scaled, torch.tensor([-0.01, 0.0, -0.02]))


def test_moving_toward_the_goal_is_rewarded_and_away_penalised():
    before = torch.zeros(3, 3)
    after = torch.tensor([[0.0, 0.5, 0.9], [0.0, -0.5, 0.9], [0.5, 0.0, 0.9]])  # toward, away, sideways
    goal = torch.tensor([[0.0, 3.0, 0.0]]).expand(3, 3)
    torch.testing.assert_close(
        terms.goal_progress(before, after, goal), torch.tensor([0.5, -0.5, 3.0 - math.hypot(0.5, 3)])
    )
    torch.testing.assert_close(terms.moving_orientation(before, after, goal), torch.tensor([1.0, 0.0, 0.5]))


def test_orientation_is_per_env_not_env_zero_broadcast():
    before = torch.zeros(2, 3)
    after = torch.tensor([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]])
    goal = torch.tensor([[0.0, 5.0, 0.0], [0.0, 5.0, 0.0]])
    assert terms.moving_orientation(before, after, goal).tolist() == [1.0, 0.0]


def test_standing_still_gives_neutral_orientation():
    p = torch.tensor([[1.0, 2.0, 0.9]])
    assert terms.moving_orientation(p, p, torch.tensor([[4.0, 6.0, 0.0]])).item() == pytest.approx(0.5)


def test_yaw_rate_is_cos_minus_one_of_the_turn_per_frame():
    turn = math.radians(10)
    joints = torch.zeros(1, 9, 22, 3)
    for t in range(9):
        axis = torch.tensor([math.cos(t * turn), math.sin(t * turn), 0.0]) * 0.09
        joints[0, t, 1] = -axis  # left hip
        joints[0, t, 2] = axis  # right hip (hips also tilt in z, which is ignored)
        joints[0, t, 2, 2] = 0.05
    torch.testing.assert_close(terms.yaw_rate(joints), torch.tensor([math.cos(turn) - 1]))
    still = joints[:, :1].expand(1, 9, 22, 3)
    assert terms.yaw_rate(still).item() == pytest.approx(0.0, abs=1e-7)


def test_jerk_of_a_cubic_trajectory_is_six_times_its_coefficient():
    t = torch.arange(10.0)
    joints = torch.zeros(1, 10, 22, 3)
    joints[0, :, 5, 0] = 0.001 * t**3  # one joint on a cubic along x
    joints[0, :, 3, :] = t[:, None] * 0.1  # another moves at constant speed: no jerk
    torch.testing.assert_close(terms.jerk(joints), torch.tensor([-0.006]))


def test_success_is_the_reached_mask():
    assert terms.success(torch.tensor([True, False])).tolist() == [1.0, 0.0]
