import functools

import numpy as np
import pytest

from latentrl.datasets import deepmimic as dm
from latentrl.datasets.body import axis_angle_to_matrix_np, forward_kinematics_np, rest_joints, world_rotations
from latentrl.datasets.motion_text import validate_sequence
from latentrl.errors import DataError
from latentrl.motion.skeleton import FOOT_JOINTS, PARENTS

needs_pybullet = pytest.mark.skipif(
    not dm.deepmimic_available(),
    reason="pybullet is not installed (pip install 'latentrl[mocap]'); the DeepMimic clips ship with it",
)


@functools.cache
def clips(cycles=2):
    return dict(zip(dm.CLIPS, dm.load_deepmimic_clips(cycles=cycles)))


@functools.cache
def reference():
    return dm.mocap_reference_statistics()


# --- without pybullet -------------------------------------------------------------------------------------


def test_missing_pybullet_names_the_extra(monkeypatch):
    monkeypatch.setattr(dm, "_motions_dir", lambda: None)
    assert not dm.deepmimic_available()
    with pytest.raises(DataError, match=r"pip install 'latentrl\[mocap\]'"):
        dm.load_deepmimic_clips()
    with pytest.raises(DataError, match="mocap"):
        dm.mocap_reference_statistics()


def test_bone_direction_ik_recovers_known_rotations():
    """Observed joints from our own FK, with the true world rotations as twist reference: exact recovery."""
    rng = np.random.default_rng(0)
    rest = rest_joints(1.7)
    local = axis_angle_to_matrix_np(rng.normal(0.0, 0.4, (6, 22, 3)))
    for leaf in (10, 11, 13, 14, 15, 20, 21):  # joints the IK keeps at their rest angle
        local[:, leaf] = np.eye(3)
    joints = forward_kinematics_np(rest, local, rng.normal(0.0, 0.5, (6, 3)))
    solved = dm.bone_direction_ik(rest, joints, world_rotations(local))
    np.testing.assert_allclose(solved, local, atol=1e-9)
    # with a twist-free reference only bone directions are matched, and positions still are
    solved = dm.bone_direction_ik(rest * 1.1, joints, np.tile(np.eye(3), (6, 22, 1, 1)))
    fk = forward_kinematics_np(rest * 1.1, solved, np.zeros((6, 3)))
    for j in range(1, 22):
        if j in (10, 11, 13, 14, 15, 20, 21):
            continue
        child = dm._IK_CHILD[j]
        got, want = fk[:, child] - fk[:, j], joints[:, child] - joints[:, j]
        cos = np.sum(got * want, -1) / np.linalg.norm(got, axis=-1) / np.linalg.norm(want, axis=-1)
        assert cos.min() > 1 - 1e-9, (j, PARENTS[j])


def test_unknown_clip_is_named():
    with pytest.raises(DataError, match="unknown DeepMimic clip 'humanoid3d_wlak'.*did you mean 'humanoid3d_walk'"):
        dm.read_deepmimic_clip("humanoid3d_wlak")


# --- with pybullet ------------------------------------------------------------------------------------------


@needs_pybullet
def test_clips_exist_with_expected_layout():
    for name in dm.CLIPS:
        clip = dm.read_deepmimic_clip(name)
        assert clip["frames"].shape[1] == 44
    walk, jump = dm.read_deepmimic_clip("humanoid3d_walk"), dm.read_deepmimic_clip("humanoid3d_jump")
    assert len(walk["frames"]) == 39 and walk["loop"]
    assert walk["times"][-1] == pytest.approx(38 / 30, abs=1e-3)
    assert len(jump["frames"]) == 107 and not jump["loop"]
    assert jump["times"][-1] == pytest.approx(106 / 60, abs=1e-3)


@needs_pybullet
def test_deepmimic_forward_kinematics_is_sane():
    p = dm.deepmimic_joint_positions("humanoid3d_walk")
    idx = {n: i for i, n in enumerate(dm.DM_JOINTS)}
    assert len(p) == 39  # one closed cycle at 30 fps
    assert 0.84 < p[:, idx["root"], 2].min() and p[:, idx["root"], 2].max() < 0.9  # pelvis (hip line) height
    thigh = np.linalg.norm(p[:, idx["left_knee"]] - p[:, idx["left_hip"]], axis=-1)
    np.testing.assert_allclose(thigh, 0.25 * 1.686184, atol=1e-9)  # URDF units x 0.25 = metres
    ankles = p[:, [idx["left_ankle"], idx["right_ankle"]], 2].min(axis=1)
    assert 0.04 < np.median(ankles) < 0.07  # stance ankle ~5 cm above DeepMimic's floor (its foot box's sole)
    # z up and facing +y: the head is above the pelvis, the right hip at +x, and the walk advances along +y
    assert (p[:, idx["neck"], 2] > p[:, idx["root"], 2] + 0.3).all()
    assert (p[:, idx["right_hip"], 0] > p[:, idx["left_hip"], 0]).mean() > 0.9
    travel = p[-1, idx["root"]] - p[0, idx["root"]]
    assert travel[1] == pytest.approx(1.239, abs=0.01) and abs(travel[0]) < 0.02


@needs_pybullet
def test_retargeted_clips_are_valid_sequences_on_the_floor():
    for name, seq in clips().items():
        validate_sequence(seq, f"{name}.npz", check_fk=True)
        assert list(seq["seg_text"]) == [dm.CLIPS[name][0]]
        joints = seq["joints"]
        assert 0.85 < joints[:, 0, 2].mean() < 1.0, name
        lowest = joints[:, list(FOOT_JOINTS), 2].min(axis=1)
        assert 0.0 < np.percentile(lowest, 10) < 0.035, name  # stance toe bases ~2 cm up, as in our data
        assert lowest.min() > -0.03, name
    # tiling: a 5 s walk is 150 frames; the cycle seams (every 38 frames) are no rougher than the recording
    walk = dm.load_deepmimic_clips(["humanoid3d_walk"], seconds=5.0)[0]
    assert len(walk["transl"]) == 150
    accel = np.linalg.norm(np.diff(walk["joints"], 2, axis=0), axis=-1).max(axis=1)  # accel[i]: frame i + 1
    seams = np.array([38, 76, 114]) - 1
    assert accel[seams].max() <= np.delete(accel, seams).max()


@needs_pybullet
def test_speeds_cadence_and_turns_match_the_recordings():
    stats = reference()["clips"]
    assert stats["humanoid3d_walk"]["speed_m_s"] == pytest.approx(0.98, abs=0.03)
    assert stats["humanoid3d_run"]["speed_m_s"] == pytest.approx(3.6, abs=0.1)
    assert stats["humanoid3d_walk"]["cadence_steps_s"] == pytest.approx(2 / (38 / 30), abs=0.05)
    assert stats["humanoid3d_run"]["cadence_steps_s"] == pytest.approx(2 / (24 / 30), abs=0.1)
    assert abs(stats["humanoid3d_walk"]["turn_deg_s"]) < 2
    assert stats["walker/turn_left0"]["turn_deg_s"] == pytest.approx(30 / (37 / 30), abs=3)
    assert stats["walker/turn_right0"]["turn_deg_s"] < -60
    skills = reference()["skills"]
    assert set(skills) == {"walk", "run", "jump_forward", "turn_left", "turn_right"}
    assert skills["walk"]["skate_xy_cm_s"] < 3.0
    assert reference()["frames"] == sum(len(s["transl"]) for s in dm.load_deepmimic_clips(cycles=4))


@needs_pybullet
def test_height_scales_the_motion():
    small = dm.load_deepmimic_clips(["humanoid3d_walk"], height=1.5)[0]
    base = dm.load_deepmimic_clips(["humanoid3d_walk"])[0]
    ratio = 1.5 / dm.DM_BODY_HEIGHT_M
    travel = lambda s: s["joints"][-1, 0, 1] - s["joints"][0, 0, 1]  # noqa: E731
    assert travel(small) == pytest.approx(ratio * travel(base), rel=1e-3)
    np.testing.assert_allclose(small["poses"], base["poses"], atol=1e-5)
    with pytest.raises(DataError, match="height"):
        dm.load_deepmimic_clips(["humanoid3d_walk"], height=4.0)
    with pytest.raises(DataError, match="both seconds and cycles"):
        dm.load_deepmimic_clips(["humanoid3d_walk"], seconds=2.0, cycles=2)
