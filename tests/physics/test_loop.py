"""Stage 3: the closed loop feeds the last two simulated frames back as the motion model's history."""

import numpy as np
import pytest
import torch

pytest.importorskip("mujoco")

from latentrl.motion.skeleton import NUM_JOINTS  # noqa: E402
from latentrl.physics.humanoid import build_humanoid  # noqa: E402
from latentrl.physics.loop import closed_loop, simulated_features  # noqa: E402
from latentrl.physics.reference import features_rotations  # noqa: E402


@pytest.fixture(scope="module")
def default_model():
    from latentrl.motion.checkpoint import load_motion_model

    return load_motion_model("default")


def test_each_primitive_is_planned_from_the_simulated_frames(default_model):
    steps = 4
    result = closed_loop(default_model, build_humanoid(1.72), ["walk"] * steps,
                         generator=torch.Generator().manual_seed(0))
    frames = 2 + 8 * steps
    assert result.simulated.shape == result.planned.shape == (frames, NUM_JOINTS, 3)
    assert result.features.shape == (frames, 276)
    assert np.isfinite(result.simulated).all() and result.falls == []
    for k in range(1, steps):  # what the model was given = the two simulated frames before primitive k
        assert np.abs(result.histories[k] - result.simulated[8 * k : 8 * k + 2]).max() < 1e-4
    # and not what the model itself had planned there (physics moved the body)
    assert max(np.abs(result.histories[k] - result.planned[8 * k : 8 * k + 2]).max() for k in range(1, steps)) > 1e-3
    assert result.assist_force.shape == (frames,)


def test_simulated_features_round_trip_joints_and_rotations():
    rng = np.random.default_rng(0)
    joints = rng.normal(size=(3, NUM_JOINTS, 3))
    q, _ = np.linalg.qr(rng.normal(size=(3, NUM_JOINTS, 3, 3)))
    local = q * np.sign(np.linalg.det(q))[..., None, None]
    feats = simulated_features(joints, local, np.array([0.0, 0.0, 0.9]))
    assert np.allclose(feats[:, 144:210].reshape(3, NUM_JOINTS, 3), joints)
    assert np.allclose(features_rotations(feats), local, atol=1e-9)
    assert np.allclose(feats[:, 0:3], joints[:, 0] - [0.0, 0.0, 0.9])
    assert np.allclose(feats[-1, 210:276], (joints[-1] - joints[-2]).reshape(-1))  # last frame: constant velocity
