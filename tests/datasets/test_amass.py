"""AMASS converter on small synthetic AMASS-like files (never real AMASS data)."""

import json

import numpy as np
import pytest

from latentrl.datasets import amass
from latentrl.datasets.body import axis_angle_to_matrix_np, forward_kinematics_np, matrix_to_axis_angle_np, rest_joints
from latentrl.datasets.motion_text import list_dataset, read_meta, read_sequence
from latentrl.errors import DataError

REST = rest_joints(1.72)
C = amass.SMPL_FROM_LATENTRL


def truth(t):
    """Known smooth motion at times ``t`` (s): latentrl local rotations (T, 22, 3, 3) and pelvis (T, 3)."""
    rng = np.random.default_rng(7)
    amp, freq, phase = rng.uniform(0.1, 0.5, (22, 3)), rng.uniform(0.5, 1.5, (22, 3)), rng.uniform(0, 6, (22, 3))
    aa = amp * np.sin(2 * np.pi * freq * t[:, None, None] + phase)
    aa[:, 0] = np.stack([0.1 * np.sin(t), 0.05 * np.cos(2 * t), 0.8 * t], -1)  # tilt and a steady left turn
    pelvis = np.stack([0.3 * np.sin(t), 1.1 * t, REST[0, 2] + 0.03 * np.sin(6 * t)], -1)
    return axis_angle_to_matrix_np(aa), pelvis


def write_amass(path, fps, seconds=3.0, width=156, rest=REST, **extra):
    """An AMASS-style file: SMPL-convention axis-angle poses and SMPL's trans (pelvis = trans + J0)."""
    t = np.arange(int(round(seconds * fps)) + 1) / fps
    local, pelvis = truth(t)
    poses = np.zeros((len(t), width))
    poses[:, :66] = matrix_to_axis_angle_np(amass.latentrl_rotations_to_smpl(local)).reshape(len(t), 66)
    fields = {"poses": poses, "trans": pelvis - C @ rest[0], "mocap_framerate": np.array(fps),
              "betas": np.zeros(16), "gender": np.array("neutral")}
    fields.update(extra)
    np.savez(path, **{k: v for k, v in fields.items() if v is not None})
    return path


def expected_joints(num):
    t = np.arange(num) / 30.0
    local, pelvis = truth(t)
    return forward_kinematics_np(REST, local, pelvis - REST[0])


LABELS = [{"start": 0.0, "end": 1.5, "text": "walk"}, {"start": 1.5, "end": 3.0, "text": "turn left"}]
WHOLE = [{"text": "walk"}]  # a segment without times covers the whole sequence


@pytest.mark.parametrize("fps", [60.0, 50.0, 120.0])
def test_round_trip_joints_within_1cm(tmp_path, fps):
    src = write_amass(tmp_path / "walk_turn_poses.npz", fps)
    out = amass.convert_amass([src], [LABELS], tmp_path / "out", body_model=REST)
    assert [p.name for p in out] == ["walk_turn_poses.npz"]
    seq = read_sequence(out[0], check_fk=True)
    assert len(seq["transl"]) == 91  # 3 s at 30 fps, both ends included
    err = np.linalg.norm(seq["joints"] - expected_joints(91), axis=-1)
    assert err.max() < (1e-4 if fps in (60.0, 120.0) else 0.01), err.max()  # 60/120 fps: the samples coincide
    np.testing.assert_allclose(seq["rest_joints"], REST, atol=1e-6)
    np.testing.assert_allclose(seq["transl"] + seq["pelvis_delta"], seq["joints"][:, 0], atol=1e-5)
    assert list(seq["seg_text"]) == ["walk", "turn left"]
    assert list(seq["seg_start"]) == [0, 45] and list(seq["seg_end"]) == [45, 91]
    meta = read_meta(tmp_path / "out")
    assert meta["num_sequences"] == 1 and meta["frames"] == 91 and meta["frames_per_text"]["walk"] == 45


def test_smpl_frame_rest_joints_and_smpl_widths(tmp_path):
    """The same body given as SMPL-frame joints (y up, left = +x), from SMPL-X / SMPL widths, gives the same."""
    rest_smpl = REST @ C.T
    for width in (165, 72, 66):
        src = write_amass(tmp_path / f"w{width}.npz", 60.0, seconds=1.0, width=width, gender=np.array(b"female"))
        [seq] = amass.amass_to_sequences(src, WHOLE, amass.RestJointsBody(rest_smpl, frame="smpl"))
        assert np.abs(seq["joints"] - expected_joints(31)).max() < 1e-4
    np.save(tmp_path / "rest.npy", rest_smpl)
    body = amass.resolve_body_model(tmp_path / "rest.npy")
    assert body.frame == "smpl"
    np.testing.assert_allclose(body.rest_joints_smpl(), rest_smpl)


def test_rotation_frame_conversion_round_trips():
    rot = axis_angle_to_matrix_np(np.random.default_rng(1).normal(0, 1, (4, 22, 3)))
    np.testing.assert_allclose(amass.smpl_rotations_to_latentrl(amass.latentrl_rotations_to_smpl(rot)), rot,
                               atol=1e-12)
    # SMPL's rest frame faces +z with y up: a zero SMPL pose is an upright body facing world +y after AMASS's
    # usual root rotation of +90 degrees about x
    root = axis_angle_to_matrix_np(np.array([np.pi / 2, 0.0, 0.0]))
    zero = np.tile(np.eye(3), (1, 22, 1, 1))
    zero[0, 0] = root
    ours = amass.smpl_rotations_to_latentrl(zero)
    np.testing.assert_allclose(ours[0, 0], np.diag([-1.0, -1.0, 1.0]), atol=1e-12)  # upright, turned to -y
    np.testing.assert_allclose(ours[0, 1:], np.tile(np.eye(3), (21, 1, 1)), atol=1e-12)


def test_label_formats(tmp_path):
    src = write_amass(tmp_path / "seq.npz", 60.0, seconds=2.0)
    babel_segments = [{"start_t": 0.0, "end_t": 1.0, "proc_label": "stand", "raw_label": "standing"},
                      {"start_t": 1.0, "end_t": 2.0, "proc_label": "walk"},
                      {"start_t": 0.8, "end_t": 1.2, "proc_label": "transition"}]
    entry = {"feat_p": "CMU/CMU/01/seq.npz", "dur": 2.0, "frame_ann": {"labels": babel_segments}, "seq_ann": None}
    for spec in (babel_segments, {"labels": babel_segments}, entry):
        [seq] = amass.amass_to_sequences(src, spec, REST)
        assert list(seq["seg_text"]) == ["stand", "walk", "transition"]
        assert list(seq["seg_start"]) == [0, 30, 24] and list(seq["seg_end"]) == [30, 61, 36]
    seq_only = {"frame_ann": None, "seq_ann": {"labels": [{"proc_label": "walk"}, {"proc_label": "wave"}]}}
    [seq] = amass.amass_to_sequences(src, seq_only, REST)
    assert list(seq["seg_text"]) == ["walk", "wave"] and list(seq["seg_end"]) == [61, 61]
    # a whole BABEL file, keyed by sequence id, matched by feat_p; and a JSON file path
    babel_file = tmp_path / "train.json"
    babel_file.write_text(json.dumps({"1234": entry, "99": {**entry, "feat_p": "CMU/CMU/02/other.npz"}}))
    out = amass.convert_amass([src], babel_file, tmp_path / "out", REST)
    assert list(read_sequence(out[0])["seg_text"]) == ["stand", "walk", "transition"]
    (tmp_path / "plain.json").write_text(json.dumps([{"start": 0, "end": 2.0, "text": "walk"}]))
    out = amass.convert_amass(src, tmp_path / "plain.json", tmp_path / "out2", REST)
    assert list(read_sequence(out[0])["seg_text"]) == ["walk"]
    # a mapping keyed by file stem
    out = amass.convert_amass([src], {"seq": WHOLE}, tmp_path / "out3", REST)
    assert read_meta(tmp_path / "out3")["sources"][0]["outputs"][0]["frames"] == 61


def test_unlabelled_gaps_are_cropped_or_refused(tmp_path):
    src = write_amass(tmp_path / "gappy.npz", 60.0, seconds=3.0)
    labels = [{"start": 0.0, "end": 1.0, "text": "walk"}, {"start": 2.0, "end": 2.5, "text": "run"}]
    out = amass.convert_amass([src], [labels], tmp_path / "out", REST)
    assert [p.name for p in out] == ["gappy_p0.npz", "gappy_p1.npz"]
    first, second = (read_sequence(p) for p in out)
    assert len(first["transl"]) == 30 and len(second["transl"]) == 15
    np.testing.assert_allclose(second["joints"], expected_joints(91)[60:75], atol=1e-4)
    with pytest.raises(DataError, match=r"gappy.npz labels: frames 30-59 \(30 fps\) have no label"):
        amass.amass_to_sequences(src, labels, REST, uncovered="error")


def test_floor_feet_puts_stance_feet_on_the_floor(tmp_path):
    src = write_amass(tmp_path / "s.npz", 60.0, seconds=1.0)
    rest_taller = rest_joints(1.9)  # not the subject's body: heights are off until floor="feet"
    [seq] = amass.amass_to_sequences(src, WHOLE, rest_taller, floor="feet")
    sole = amass.sole_heights(seq["joints"].astype(float), seq["rest_joints"].astype(float))
    assert sole.min() > -0.05 and np.median(sole.min(axis=1)) < 0.05


def error(fn, *args, **kwargs):
    with pytest.raises(DataError) as info:
        fn(*args, **kwargs)
    return str(info.value)


def test_errors_name_file_and_field(tmp_path):
    missing = tmp_path / "shape.npz"
    np.savez(missing, betas=np.zeros(16), gender=np.array("male"))
    assert error(amass.load_amass, missing).startswith("shape.npz: missing field 'poses' (a shape.npz holds no motion)")
    bad = write_amass(tmp_path / "bad.npz", 60.0, seconds=1.0, width=156)
    data = dict(np.load(bad))
    np.savez(bad, **{**data, "poses": data["poses"][:, :100]})
    assert error(amass.load_amass, bad).startswith("bad.npz: field 'poses' has shape (61, 100), expected (T, W)")
    np.savez(bad, **{**data, "trans": data["trans"][:10]})
    assert error(amass.load_amass, bad) == "bad.npz: field 'trans' has shape (10, 3), expected (61, 3) like 'poses'"
    np.savez(bad, **{k: v for k, v in data.items() if k != "mocap_framerate"})
    assert "bad.npz: missing field 'mocap_framerate' (or 'mocap_frame_rate')" in error(amass.load_amass, bad)
    np.savez(bad, **{**{k: v for k, v in data.items() if k != "mocap_framerate"}, "mocap_frame_rate": np.array(0.0)})
    assert "field 'mocap_frame_rate' is 0, expected a positive frame rate" in error(amass.load_amass, bad)
    (tmp_path / "junk.npz").write_text("not a zip")
    assert "junk.npz: cannot read as .npz" in error(amass.load_amass, tmp_path / "junk.npz")

    src = write_amass(tmp_path / "ok.npz", 60.0, seconds=2.0)
    outside = [{"start": 0.0, "end": 1.0, "text": "walk"}, {"start": 1.5, "end": 9.0, "text": "run"}]
    assert error(amass.amass_to_sequences, src, outside, REST) == (
        "ok.npz labels: label 1 ('run') runs from 1.5 s to 9 s, outside the sequence (0 to 2.017 s), "
        "expected times inside it")
    assert "label 0 ('walk') runs from 1 s to 0.5 s, expected start < end" in error(
        amass.amass_to_sequences, src, [{"start": 1.0, "end": 0.5, "text": "walk"}], REST)
    assert "ok.npz labels[0]: missing text" in error(amass.amass_to_sequences, src, [{"start": 0, "end": 1}], REST)
    # a label ending a little past the end (BABEL rounding) is clipped, not refused
    [seq] = amass.amass_to_sequences(src, [{"start": 0.0, "end": 2.05, "text": "walk"}], REST)
    assert list(seq["seg_end"]) == [61]

    assert error(amass.resolve_body_model, "nonsense").startswith("unknown body model 'nonsense', expected")
    assert "unknown body model" in error(amass.convert_amass, [src], [LABELS], tmp_path / "o", body_model=42)
    assert "SMPL model folder not found" in error(amass.resolve_body_model, f"smplx:{tmp_path / 'no_models'}")
    assert "expected the left hip towards -x" in error(amass.RestJointsBody, REST * np.array([-1.0, 1.0, 1.0]))
    assert "expected +z (latentrl frame) or +y (SMPL frame)" in error(amass.RestJointsBody, REST[:, [0, 2, 1]] * -1)
    assert "rest joints have shape (21, 3)" in error(amass.RestJointsBody, REST[:21])
    np.savez(tmp_path / "nojoints.npz", foo=np.zeros(3))
    assert "nojoints.npz: missing field 'rest_joints'" in error(amass.resolve_body_model, tmp_path / "nojoints.npz")
    # an output folder with sequences already in it is refused
    amass.convert_amass([src], [WHOLE], tmp_path / "taken", REST)
    assert "already holds 1 .npz files" in error(amass.convert_amass, [src], [WHOLE], tmp_path / "taken", REST)
    assert len(amass.convert_amass([src], [WHOLE], tmp_path / "taken", REST, overwrite=True)) == 1


def test_smplx_body_without_package_names_the_extra(tmp_path, monkeypatch):
    import builtins

    real_import = builtins.__import__

    def no_smplx(name, *args, **kwargs):
        if name == "smplx":
            raise ImportError("no smplx")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_smplx)
    body = amass.resolve_body_model(f"smplx:{tmp_path}")
    assert isinstance(body, amass.SmplxBody)
    assert "pip install 'latentrl[amass]'" in error(body.rest_joints_smpl, np.zeros(10), "male")


def test_command_line(tmp_path, capsys):
    with pytest.raises(SystemExit) as info:
        amass.main(["--help"])
    assert info.value.code == 0
    assert "--smplx-model" in capsys.readouterr().out
    src = write_amass(tmp_path / "cli_walk.npz", 60.0, seconds=1.0)
    np.savez(tmp_path / "body.npz", rest_joints=REST)
    (tmp_path / "labels").mkdir()
    (tmp_path / "labels" / "cli_walk.json").write_text(json.dumps(WHOLE))
    code = amass.main([str(src), "--labels", str(tmp_path / "labels"), "--out", str(tmp_path / "out"),
                       "--rest-joints", str(tmp_path / "body.npz")])
    assert code == 0 and len(list_dataset(tmp_path / "out")) == 1
    code = amass.main([str(src), "--labels", str(tmp_path / "labels"), "--out", str(tmp_path / "out"),
                       "--rest-joints", str(tmp_path / "body.npz")])
    assert code == 2 and "already holds 1 .npz files" in capsys.readouterr().err


def test_smplx_body_with_a_fake_model(tmp_path):
    """SmplxBody through the real smplx package, on a made-up SMPL model whose joints are our rest joints."""
    pytest.importorskip("smplx", reason="smplx is not installed (pip install 'latentrl[amass]')")
    import pickle

    verts, rest_smpl = 6890, REST @ C.T
    joints = np.concatenate([rest_smpl, rest_smpl[20:22] + [0.0, -0.08, 0.0]])  # SMPL has 24 joints (hands)
    template = np.zeros((verts, 3))
    template[:24] = joints
    regressor = np.zeros((24, verts))
    regressor[np.arange(24), np.arange(24)] = 1.0
    weights = np.zeros((verts, 24))
    weights[np.arange(verts), np.minimum(np.arange(verts), 23)] = 1.0
    shapedirs = np.zeros((verts, 3, 10))
    shapedirs[:24, 1, 0] = 0.1 * joints[:, 1]  # beta 0 stretches the body 10% along SMPL's up axis
    parents = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21]
    model = {"v_template": template, "shapedirs": shapedirs, "posedirs": np.zeros((verts, 3, 207)),
             "J_regressor": regressor, "kintree_table": np.stack([parents, np.arange(24)]), "weights": weights,
             "f": np.array([[0, 1, 2]])}
    (tmp_path / "models" / "smpl").mkdir(parents=True)
    with open(tmp_path / "models" / "smpl" / "SMPL_NEUTRAL.pkl", "wb") as handle:
        pickle.dump(model, handle)
    body = amass.resolve_body_model(f"smpl:{tmp_path / 'models'}")
    np.testing.assert_allclose(body.rest_joints_smpl(np.zeros(16), None), rest_smpl, atol=1e-6)  # 16 -> 10 betas
    stretched = body.rest_joints_smpl(np.eye(10)[0], "neutral")
    np.testing.assert_allclose(stretched[:, 1], 1.1 * rest_smpl[:, 1], atol=1e-6)
    src = write_amass(tmp_path / "s.npz", 60.0, seconds=1.0)
    [seq] = amass.amass_to_sequences(src, WHOLE, body)
    assert np.abs(seq["joints"] - expected_joints(31)).max() < 1e-4


def test_cli_and_module_main_share_one_request(tmp_path):
    from latentrl.app.cli import main as cli_main

    src = write_amass(tmp_path / "walk_turn_poses.npz", 60.0)
    (tmp_path / "labels.json").write_text(json.dumps(LABELS))
    np.save(tmp_path / "rest.npy", REST)
    common = [str(src), "--labels", str(tmp_path / "labels.json"), "--rest-joints", str(tmp_path / "rest.npy"),
              "--rest-frame", "latentrl"]
    assert cli_main(["data", "convert-amass", *common, "--out", str(tmp_path / "cli")]) == 0
    assert amass.main([*common, "--out", str(tmp_path / "module")]) == 0
    a, b = (read_sequence(tmp_path / d / "walk_turn_poses.npz") for d in ("cli", "module"))
    np.testing.assert_array_equal(a["joints"], b["joints"])
    assert cli_main(["data", "convert-amass", *common[:3], "--out", str(tmp_path / "x")]) == 2  # no body given
