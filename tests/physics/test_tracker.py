"""Stage 1: the untrained PD tracker with its reported root assist."""

import numpy as np
import pytest
import torch

pytest.importorskip("mujoco")

from latentrl.motion.representation import compute_features  # noqa: E402
from latentrl.motion.skeleton import NUM_JOINTS  # noqa: E402
from latentrl.physics.humanoid import build_humanoid  # noqa: E402
from latentrl.physics.reference import build_reference  # noqa: E402
from latentrl.physics.tracker import track  # noqa: E402


def standing_features(rest: np.ndarray, frames: int) -> tuple[np.ndarray, np.ndarray]:
    joints = np.tile(rest, (frames + 1, 1, 1))
    rotations = np.tile(np.eye(3), (frames + 1, NUM_JOINTS, 1, 1))
    transl = joints[:, 0] - rest[0]
    feats = compute_features(torch.as_tensor(transl), torch.as_tensor(rotations), torch.as_tensor(joints))
    return joints[:-1], feats.numpy()


def test_standing_reference_needs_almost_no_assist():
    humanoid = build_humanoid(1.75)
    joints, feats = standing_features(humanoid.rest_joints, 90)
    result = track(humanoid, build_reference(joints, feats, 30.0, humanoid))
    summary = result.assist_summary()
    assert result.falls == []
    assert np.linalg.norm(result.joints - joints, axis=-1).mean() < 0.01
    assert 0.0 <= summary["force_percent_body_weight"] < 2.0
    assert result.rotations.shape == (90, NUM_JOINTS, 3, 3)


def test_assist_off_reports_zero_and_a_lifted_body_falls():
    humanoid = build_humanoid(1.75)
    joints, feats = standing_features(humanoid.rest_joints, 90)
    lift = np.clip((np.arange(90) - 10) / 30, 0, 1) * 0.8  # the reference rises 0.8 m in 1 s and floats there
    joints[..., 2] += lift[:, None]
    feats[:, 146:210:3] += lift[:, None]
    ref = build_reference(joints, feats, 30.0, humanoid)
    off = track(humanoid, ref, assist_hz=None)
    assert off.assist_summary()["force_Ns_per_s"] == 0.0
    assert len(off.falls) >= 1
    held = track(humanoid, ref, assist_hz=2.0)
    assert held.falls == []
    assert held.assist_summary()["force_percent_body_weight"] > 80.0  # the assist carries the body: reported


def test_tracks_a_sampled_walk_without_falls(sampled_walk):
    from latentrl.motion.clip import MotionClip

    clip = MotionClip.load(sampled_walk)
    humanoid = build_humanoid(1.72)
    ref = build_reference(clip.joints, clip.features, clip.fps, humanoid)
    result = track(humanoid, ref)
    assert result.falls == []
    assert np.isfinite(result.joints).all()
    assert np.linalg.norm(result.joints - clip.joints, axis=-1).mean() < 0.3
    assert result.assist_summary()["force_Ns_per_s"] > 0.0
