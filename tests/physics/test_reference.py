"""A motion's rotations as hinge angles: the Euler layout round-trips and corrected rotations follow the joints."""

import numpy as np
import pytest

from latentrl.datasets.body import rest_joints
from latentrl.motion.skeleton import NUM_JOINTS
from latentrl.physics.reference import (
    euler_angles,
    euler_matrix,
    fit_height,
    forward_joints,
    reference_rotations,
)


def random_rotations(rng, shape, scale=0.6):
    angles = rng.uniform(-scale, scale, (*shape, 3))
    return euler_matrix(angles, "zxy")


@pytest.mark.parametrize("order", ["xyz", "xzy", "zxy", "yzx"])
def test_euler_round_trip(order):
    rng = np.random.default_rng(0)
    angles = rng.uniform(-1.2, 1.2, (50, 3))
    back = euler_angles(euler_matrix(angles, order), order)
    assert np.abs(back - angles).max() < 1e-9


def test_corrected_rotations_keep_a_rigid_motion_and_fix_a_wrong_one():
    rng = np.random.default_rng(1)
    rest = rest_joints(1.75)
    local = random_rotations(rng, (20, NUM_JOINTS))
    root = np.tile(rest[0], (20, 1))
    joints = forward_joints(rest, local, root)
    # a motion that is rigid on this skeleton: the correction changes nothing that matters
    fixed = reference_rotations(local, joints, rest)
    assert np.abs(forward_joints(rest, fixed, root) - joints).max() < 1e-6
    # rotations that disagree with the joints (as a motion model's may): the bones go back onto the joints
    noisy = local @ random_rotations(rng, (20, NUM_JOINTS), 0.3)
    off = np.linalg.norm(forward_joints(rest, noisy, root) - joints, axis=-1).mean()
    fixed = reference_rotations(noisy, joints, rest)
    assert off > 0.05
    assert np.abs(forward_joints(rest, fixed, root) - joints).max() < 1e-6


def test_fit_height_recovers_the_skeleton_height():
    rest = rest_joints(1.68)
    assert fit_height(np.tile(rest, (3, 1, 1))) == pytest.approx(1.68, abs=0.005)  # the 2 cm toe height is absolute


def test_leg_ik_puts_ankles_on_reachable_targets_and_keeps_the_upper_body():
    from latentrl.physics.reference import FOOT_AND_ANKLE, leg_ik

    rng = np.random.default_rng(2)
    rest = rest_joints(1.75)
    local = random_rotations(rng, (15, NUM_JOINTS), 0.3)
    root = np.tile(rest[0], (15, 1))
    joints = forward_joints(rest, local, root)
    same = forward_joints(rest, leg_ik(local, root, rest, joints[:, FOOT_AND_ANKLE]), root)
    assert np.abs(same - joints).max() < 1e-6
    targets = joints[:, FOOT_AND_ANKLE] + np.array([0.03, -0.04, 0.05])  # feet moved 7 cm, still within reach
    moved = forward_joints(rest, leg_ik(local, root, rest, targets), root)
    assert np.abs(moved[:, [7, 8]] - targets[:, :2]).max() < 1e-6
    upper = [0, 3, 6, 9, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21]
    assert np.abs(moved[:, upper] - joints[:, upper]).max() < 1e-9
