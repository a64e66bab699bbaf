import json

import numpy as np
import pytest
import torch

from latentrl.datasets.body import rest_joints
from latentrl.datasets.motion_text import (
    FIELDS,
    list_dataset,
    read_meta,
    read_sequence,
    validate_sequence,
    write_meta,
    write_sequence,
)
from latentrl.datasets.motion_text import (
    make_sequence as build_sequence,
)
from latentrl.errors import DataError
from latentrl.motion.rotations import axis_angle_to_matrix
from latentrl.motion.skeleton import forward_kinematics


def make_sequence(frames=12, seed=0):
    """A valid hand-made sequence: small random joint angles, a straight root path, two overlapping segments."""
    rng = np.random.default_rng(seed)
    rest = rest_joints(1.75).astype(np.float32)
    poses = (rng.normal(0, 0.2, (frames, 22, 3))).astype(np.float32)
    transl = np.stack([np.zeros(frames), np.linspace(0, 1, frames), np.zeros(frames)], -1).astype(np.float32)
    joints, _ = forward_kinematics(torch.from_numpy(rest).double(),
                                   axis_angle_to_matrix(torch.from_numpy(poses).double()),
                                   torch.from_numpy(transl).double())
    return {
        "fps": np.array(30, dtype=np.float32),
        "transl": transl,
        "pelvis_delta": rest[0].copy(),
        "rest_joints": rest,
        "poses": poses,
        "joints": joints.numpy().astype(np.float32),
        "seg_start": np.array([0, frames // 2 - 2], dtype=np.int32),
        "seg_end": np.array([frames // 2 + 2, frames], dtype=np.int32),
        "seg_text": np.array(["walk", "stand still"]),
    }


def test_make_sequence_stores_float32_and_fk_of_the_stored_values(tmp_path):
    ref = make_sequence()
    # float64 inputs, as the generators have them: everything is stored float32, joints from those values
    seq = build_sequence(ref["rest_joints"].astype(np.float64), ref["poses"].astype(np.float64),
                         ref["transl"].astype(np.float64), [(0, 4, "walk"), (4, 12, "stand still")])
    assert set(seq) == set(FIELDS)
    for field in ("transl", "pelvis_delta", "rest_joints", "poses", "joints"):
        assert seq[field].dtype == np.float32, field
    np.testing.assert_allclose(seq["joints"], ref["joints"], atol=1e-6)
    assert seq["seg_start"].tolist() == [0, 4] and seq["seg_end"].tolist() == [4, 12]
    assert seq["seg_text"].tolist() == ["walk", "stand still"]
    validate_sequence(seq, "built.npz")
    back = read_sequence(write_sequence(tmp_path / "built.npz", seq))
    np.testing.assert_array_equal(back["joints"], seq["joints"])


def error_of(seq, name="walk_0003.npz"):
    with pytest.raises(DataError) as info:
        validate_sequence(seq, name)
    return str(info.value)


def test_valid_sequence_passes_and_round_trips(tmp_path):
    seq = make_sequence()
    validate_sequence(seq, "ok.npz")
    path = write_sequence(tmp_path / "walk_0000.npz", seq)
    back = read_sequence(path)
    assert list(back) == list(FIELDS)
    for field in FIELDS:
        assert back[field].dtype == seq[field].dtype, field
        np.testing.assert_array_equal(back[field], seq[field])


def test_wrong_pose_shape_names_file_field_and_expectation():
    seq = make_sequence(frames=120)
    seq["poses"] = seq["poses"][:, :21]
    assert error_of(seq) == ("walk_0003.npz: field 'poses' has shape (120, 21, 3), expected (T, 22, 3) "
                             "with T = 120")


def test_missing_field_and_wrong_dtype_are_named():
    seq = make_sequence()
    del seq["seg_text"]
    assert "walk_0003.npz: missing field 'seg_text'" in error_of(seq)
    seq = make_sequence()
    seq["transl"] = seq["transl"].astype(np.float64)
    assert error_of(seq) == "walk_0003.npz: field 'transl' has dtype float64, expected float32"
    seq = make_sequence()
    seq["seg_start"] = seq["seg_start"].astype(np.int64)
    assert "field 'seg_start' has dtype int64, expected int32" in error_of(seq)


def test_write_casts_to_format_dtypes(tmp_path):
    seq = make_sequence()
    loose = {k: (v.astype(np.float64) if v.dtype == np.float32 else v.astype(np.int64) if v.dtype == np.int32
                 else v.tolist()) for k, v in seq.items()}
    back = read_sequence(write_sequence(tmp_path / "a.npz", loose))
    assert back["poses"].dtype == np.float32 and back["seg_end"].dtype == np.int32
    assert back["seg_text"].dtype.kind == "U"


def test_fps_nan_and_pelvis_delta_checks():
    seq = make_sequence()
    seq["fps"] = np.array(25, dtype=np.float32)
    assert error_of(seq) == "walk_0003.npz: field 'fps' is 25, expected 30"
    seq = make_sequence()
    seq["joints"][3, 4, 1] = np.nan
    assert error_of(seq) == "walk_0003.npz: field 'joints' contains NaN or infinite values"
    seq = make_sequence()
    seq["pelvis_delta"] = seq["pelvis_delta"] + 0.01
    assert "field 'pelvis_delta'" in error_of(seq) and "rest_joints[0]" in error_of(seq)


def test_joints_must_match_forward_kinematics():
    seq = make_sequence()
    seq["joints"][5, 18] += np.array([0.0, 0.0, 0.002], dtype=np.float32)  # 2 mm off at the left elbow
    msg = error_of(seq)
    assert "field 'joints' differs from forward kinematics" in msg
    assert "frame 5, joint 'left_elbow'" in msg
    validate_sequence(seq, "x.npz", check_fk=False)  # the cheap check skips it


def test_segments_must_cover_every_frame_and_stay_in_range():
    seq = make_sequence(frames=30)
    seq["seg_start"] = np.array([0, 20], dtype=np.int32)
    seq["seg_end"] = np.array([10, 30], dtype=np.int32)
    assert error_of(seq) == ("walk_0003.npz: fields 'seg_start'/'seg_end' leave frames 10-19 without a text "
                             "segment, expected every frame to be covered")
    seq["seg_end"] = np.array([21, 31], dtype=np.int32)
    assert "segment 1 has seg_start = 20, seg_end = 31" in error_of(seq)
    seq["seg_end"] = np.array([21, 30], dtype=np.int32)
    seq["seg_text"] = np.array(["walk", "  "])
    assert "field 'seg_text' entry 1 is empty" in error_of(seq)
    seq["seg_text"] = np.array(["walk"])
    assert "field 'seg_text' has shape (1,), expected (S,) with S = 2" in error_of(seq)


def test_pickled_arrays_are_refused(tmp_path):
    seq = make_sequence()
    seq["seg_text"] = np.array(["walk", "stand still"], dtype=object)
    path = tmp_path / "evil.npz"
    np.savez(path, **seq)
    with pytest.raises(DataError, match="evil.npz"):
        read_sequence(path)


def test_unreadable_and_missing_files(tmp_path):
    with pytest.raises(DataError, match="file not found"):
        read_sequence(tmp_path / "nope.npz")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(DataError, match="bad.npz: cannot read as .npz"):
        read_sequence(bad)


def test_list_dataset_and_meta(tmp_path):
    with pytest.raises(DataError, match="dataset folder not found"):
        list_dataset(tmp_path / "missing")
    with pytest.raises(DataError, match="no .npz sequences found"):
        list_dataset(tmp_path)
    for name in ("b.npz", "a.npz"):
        write_sequence(tmp_path / name, make_sequence())
    (tmp_path / "notes.txt").write_text("ignored")
    assert [p.name for p in list_dataset(tmp_path)] == ["a.npz", "b.npz"]
    assert read_meta(tmp_path) is None
    write_meta(tmp_path, {"name": "x", "frames_per_skill": {"walk": 3}})
    assert read_meta(tmp_path) == {"name": "x", "frames_per_skill": {"walk": 3}}
    (tmp_path / "meta.json").write_text("{oops")
    with pytest.raises(DataError, match="meta.json: invalid JSON"):
        read_meta(tmp_path)
    assert json.loads(json.dumps(FIELDS["poses"][1])) == ["T", 22, 3]
