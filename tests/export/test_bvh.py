"""Our BVH files read by a third-party parser (the ``bvh`` package from PyPI), not only by our own."""

from pathlib import Path

import numpy as np
import pytest
import torch

from latentrl.motion.skeleton import JOINT_NAMES, PARENTS
from latentrl.render import ZUP_TO_YUP, save_bvh

Bvh = pytest.importorskip("bvh").Bvh


@pytest.fixture(scope="module")
def generated(tmp_path_factory) -> tuple[np.ndarray, Path]:
    """Three primitives (26 frames) of the default model walking, written as BVH."""
    from latentrl.motion import load_motion_model

    roll = load_motion_model("default").rollout("walk", 3, generator=torch.Generator().manual_seed(0))
    joints = roll.joints_world[0].numpy()
    return joints, save_bvh(tmp_path_factory.mktemp("bvh") / "walk.bvh", joints, fps=30)


def _axis(axis: str, degrees: float) -> np.ndarray:
    c, s = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))
    i, k = {"X": (1, 2), "Y": (2, 0), "Z": (0, 1)}[axis]
    m = np.eye(3)
    m[i, i], m[i, k], m[k, i], m[k, k] = c, -s, s, c
    return m


def _forward_kinematics(mocap, frame: int) -> dict[str, np.ndarray]:
    """Joint positions (file axes and units) from the third-party parser's offsets and channels only."""
    pos, rot = {}, {}
    for name in mocap.get_joints_names():  # hierarchy order: parents before children
        channels = mocap.joint_channels(name)
        values = dict(zip(channels, mocap.frame_joint_channels(frame, name, channels)))
        local = np.array(mocap.joint_offset(name), dtype=np.float64)
        r = np.eye(3)
        for channel in channels:
            if channel.endswith("position"):
                local["XYZ".index(channel[0])] = values[channel]
            else:
                r = r @ _axis(channel[0], values[channel])
        parent = mocap.joint_parent(name)
        if parent is None:
            pos[name], rot[name] = local, r
        else:
            pos[name] = pos[parent.name] + rot[parent.name] @ local
            rot[name] = rot[parent.name] @ r
    return pos


def test_third_party_parser_reads_names_hierarchy_frames_and_frame_time(generated):
    joints, path = generated
    mocap = Bvh(path.read_text())
    names = mocap.get_joints_names()
    assert len(names) == 22 and sorted(names) == sorted(JOINT_NAMES) and names[0] == "pelvis"
    for j, name in enumerate(JOINT_NAMES[1:], start=1):
        assert mocap.joint_parent(name).name == JOINT_NAMES[PARENTS[j]]
    assert mocap.joint_parent("pelvis") is None
    assert all(len(mocap.joint_channels(n)) == 6 for n in names)
    assert mocap.nframes == len(joints) == 26
    assert mocap.frame_time == pytest.approx(1 / 30, abs=1e-8)


def test_third_party_channel_values_match_the_motion(generated):
    joints, path = generated
    mocap = Bvh(path.read_text())
    expected_cm = joints @ ZUP_TO_YUP.T * 100.0  # Y-up centimetres
    for frame in (0, 13, 25):
        root = mocap.frame_joint_channels(frame, "pelvis", ["Xposition", "Yposition", "Zposition"])
        assert np.abs(np.array(root, dtype=np.float64) - expected_cm[frame, 0]).max() < 1e-4
        assert float(root[1]) == pytest.approx(joints[frame, 0, 2] * 100.0, abs=1e-4)  # pelvis height is +Y
        pos = _forward_kinematics(mocap, frame)
        ours = np.stack([pos[n] for n in JOINT_NAMES])
        assert np.abs(ours - expected_cm[frame]).max() < 1e-3  # centimetres: 10 micrometres
