"""latentrl.render: the shared motion .npz and the BVH export (round trip, axes, rotations, parser)."""

import numpy as np
import pytest

from latentrl.errors import DataError
from latentrl.motion.skeleton import JOINT_NAMES, PARENTS
from latentrl.render import (
    _SMPL_REST_OFFSETS,
    ZUP_TO_YUP,
    load_bvh,
    load_motion_npz,
    save_bvh,
    save_motion_npz,
)
from tests.helpers import walking_clip


def noisy_walk(frames: int = 40, seed: int = 0) -> np.ndarray:
    """A walking clip whose joints are jittered by ~1 cm, so bone lengths are not rigid (like generated motion)."""
    joints = walking_clip(frames, yaw=0.7)["joints"].numpy().astype(np.float64)
    return joints + 0.01 * np.random.default_rng(seed).standard_normal(joints.shape)


def t_pose(frames: int = 4, yaw: float = 0.5) -> np.ndarray:
    """The BVH rest pose itself, turned by ``yaw`` about z and walking along x."""
    rest = np.zeros((22, 3))
    rest[0] = [0.0, 0.0, 0.95]
    for j in range(1, 22):
        rest[j] = rest[PARENTS[j]] + _SMPL_REST_OFFSETS[j]
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return np.stack([rest @ rot.T + [0.1 * t, 0.2, 0.0] for t in range(frames)])


def motion_values(path) -> np.ndarray:
    """(T, 22, 6) channel values of our files (6 channels per joint, hierarchy order)."""
    lines = path.read_text().split("MOTION")[1].strip().splitlines()[2:]
    return np.array([line.split() for line in lines], dtype=np.float64).reshape(len(lines), 22, 6)


def test_bvh_round_trip_reproduces_joint_positions(tmp_path):
    joints = noisy_walk()
    out = save_bvh(tmp_path / "walk.bvh", joints, fps=30)
    back = load_bvh(out)
    assert back["joints"].shape == joints.shape and list(back["names"]) == list(JOINT_NAMES)
    assert np.abs(back["joints"] - joints).max() < 1e-3  # metres: under 1 mm (in practice ~1e-7)
    assert float(back["fps"]) == pytest.approx(30.0)
    assert list(back["parents"]) == list(PARENTS)


def test_bvh_is_y_up_centimetres_with_smpl_hierarchy(tmp_path):
    joints = noisy_walk(5)
    text = save_bvh(tmp_path / "walk.bvh", joints).read_text()
    assert text.startswith("HIERARCHY\nROOT pelvis\n")  # nothing before HIERARCHY: Blender requires it
    assert text.count("JOINT ") == 21 and text.count("End Site") == 5
    root = motion_values(tmp_path / "walk.bvh")[:, 0, :3]
    assert np.allclose(root, joints[:, 0] @ ZUP_TO_YUP.T * 100.0, atol=1e-4)  # pelvis height is +Y, in cm
    assert np.allclose(root[:, 1], joints[:, 0, 2] * 100.0, atol=1e-4)


def test_rest_pose_motion_has_zero_joint_rotations_and_root_yaw(tmp_path):
    path = save_bvh(tmp_path / "t.bvh", t_pose(yaw=0.5))
    values = motion_values(path)
    assert np.abs(values[:, 1:, 3:]).max() < 1e-4  # every joint at rest: no local rotation
    assert np.allclose(values[:, 0, 3:], [0.0, 0.0, np.degrees(0.5)], atol=1e-4)  # Z, X, Y: yaw about +Y
    assert np.abs(load_bvh(path)["joints"] - t_pose(yaw=0.5)).max() < 1e-6


def test_parser_reads_a_rotation_only_bvh(tmp_path):
    # A standard file: child joints carry rotations only, so OFFSETs place them.
    text = """HIERARCHY
ROOT hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT arm
  {
    OFFSET 10 0 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 5 0 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.5
0 100 0 0 0 0 0 0 0
0 100 0 90 0 0 0 0 0
"""
    path = tmp_path / "two.bvh"
    path.write_text(text)
    out = load_bvh(path)
    assert list(out["names"]) == ["hips", "arm"] and float(out["fps"]) == 2.0
    # file (Y-up, cm) -> ours (z up, m): frame 0 arm at x = 0.1 m, 1 m up; frame 1 the root turned 90 deg
    # about Y-up's z (= our -y), so the arm points up: 1.1 m.
    assert np.allclose(out["joints"][0], [[0.0, 0.0, 1.0], [0.1, 0.0, 1.0]], atol=1e-6)
    assert np.allclose(out["joints"][1], [[0.0, 0.0, 1.0], [0.0, 0.0, 1.1]], atol=1e-6)


def test_bvh_errors(tmp_path):
    with pytest.raises(DataError, match=r"joints. must be \(T, 22, 3\) with T > 0"):
        save_bvh(tmp_path / "x.bvh", np.zeros((3, 21, 3)))
    with pytest.raises(DataError, match="NaN"):
        save_bvh(tmp_path / "x.bvh", np.full((3, 22, 3), np.nan))
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 3 Xposition Yposition Zposition\n}\nMOTION\n"
                   "Frames: 2\nFrame Time: 0.1\n0 0 0\n")
    with pytest.raises(DataError, match="expected 2 frames x 3 channels"):
        load_bvh(bad)
    plain = tmp_path / "plain.txt"
    plain.write_text("nothing")
    with pytest.raises(DataError, match="not a BVH"):
        load_bvh(plain)


def test_motion_npz_round_trip(tmp_path):
    joints = noisy_walk(6).astype(np.float32)
    path = save_motion_npz(tmp_path / "m.npz", joints, texts=["walk"] * 6, actions=np.ones((1, 16)), success=True)
    back = load_motion_npz(path)
    assert np.array_equal(back["joints"], joints) and list(back["texts"]) == ["walk"] * 6
    assert back["actions"].shape == (1, 16) and bool(back["success"])


def test_gif_plays_in_real_time_with_goals_outside_the_box_left_out(tmp_path):
    from PIL import Image

    from latentrl.render import render_gif

    joints = np.zeros((30, 22, 3), np.float32)
    joints[..., 2] = 1.0
    path = render_gif(tmp_path / "m.gif", joints, texts=["walk"] * 30, title="suite path 0 (walk)",
                      goals=np.array([[0.0, 1.0, 0.0], [0.0, 50.0, 0.0]]))
    with Image.open(path) as im:
        assert im.n_frames == 10 and im.info["duration"] == 100  # 30 frames at 30 fps, every 3rd: 1 s exactly
