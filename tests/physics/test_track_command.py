"""``latentrl physics track``: outputs other commands read, its report, and one-line refusals of bad input."""

import json
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("mujoco")

from latentrl.app.cli import main  # noqa: E402
from latentrl.motion.clip import MotionClip  # noqa: E402


def test_track_writes_a_motion_clip_and_a_report(sampled_walk, tmp_path, capsys):
    out = tmp_path / "tracked"
    assert main(["physics", "track", str(sampled_walk), "--out", str(out)]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert "falls 0" in line and "% of body weight" in line
    clip = MotionClip.load(out / "motion.npz")
    source = MotionClip.load(sampled_walk)
    assert clip.frames == source.frames and clip.features.shape == (clip.frames, 276)
    assert np.allclose(clip.features[:, 144:210].reshape(-1, 22, 3), clip.joints, atol=1e-5)
    report = json.loads((out / "report.json").read_text())
    assert report["falls"] == 0 and report["fall_frames"] == []
    assert set(report["assist"]) >= {"force_Ns_per_s", "force_percent_body_weight", "torque_Nms_per_s"}
    assert report["assist"]["force_Ns_per_s"] > 0
    for side in ("reference", "simulation", "simulation_soles"):
        assert set(report[side]) == {"penetration_mm", "floating_mm", "skating_mm"}
    assert report["simulation_soles"]["floating_mm"] < report["simulation"]["floating_mm"]  # soles are lower
    assert 0 < report["tracking"]["retarget_mpjpe_mm"] < 100
    assert report["tracking"]["mpjpe_mm"] < 300
    assert report["speed"]["real_time_factor"] > 0
    # the simulated motion is a motion like any other: BVH export reads it
    assert main(["motion", "export-bvh", str(out / "motion.npz"), "--out", str(tmp_path / "t.bvh")]) == 0


def bad_motion(tmp_path, name, **arrays):
    path = tmp_path / name
    np.savez(path, **arrays)
    return path


def test_a_motion_without_features_is_tracked_from_its_joints(sampled_walk, tmp_path):
    clip = dict(np.load(sampled_walk))
    path = bad_motion(tmp_path, "joints_only.npz", joints=clip["joints"], fps=clip["fps"])
    out = tmp_path / "tracked"
    assert main(["physics", "track", str(path), "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["rotations"] == "joints only" and report["falls"] == 0
    assert report["tracking"]["retarget_mpjpe_mm"] < 60
    assert MotionClip.load(out / "motion.npz").features.shape == (len(clip["joints"]), 276)


@pytest.mark.parametrize("case", ["missing", "not_npz", "bad_features", "nan_features", "nan_joints", "one_frame",
                                  "height"])
def test_bad_input_is_one_line_and_exit_2(case, sampled_walk, tmp_path, capsys):
    clip = dict(np.load(sampled_walk))
    args = []
    if case == "missing":
        path = tmp_path / "nowhere.npz"
    elif case == "not_npz":
        path = tmp_path / "text.npz"
        path.write_text("not a motion")
    elif case == "bad_features":
        feats = clip["features"][:, :9]
        path = bad_motion(tmp_path, "badfeat.npz", joints=clip["joints"], fps=clip["fps"], features=feats)
    elif case == "nan_features":
        feats = clip["features"].copy()
        feats[3, 7] = np.nan
        path = bad_motion(tmp_path, "nanfeat.npz", joints=clip["joints"], fps=clip["fps"], features=feats)
    elif case == "nan_joints":
        joints = clip["joints"].copy()
        joints[2, 4, 1] = np.nan
        path = bad_motion(tmp_path, "nanjoints.npz", joints=joints, fps=clip["fps"], features=clip["features"])
    elif case == "one_frame":
        path = bad_motion(tmp_path, "one.npz", joints=clip["joints"][:1], fps=clip["fps"])
    else:
        path, args = sampled_walk, ["--height", "7"]
    out = tmp_path / f"out_{case}"
    assert main(["physics", "track", str(path), "--out", str(out), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert ("height" in err[0]) if case == "height" else (str(path.name) in err[0])
    assert not out.exists()


def test_kinematic_imports_never_load_mujoco():
    code = ("import sys, latentrl, latentrl.envs, latentrl.evaluation, latentrl.app.cli\n"
            "from latentrl.app.cli import build_parser\n"
            "build_parser()\n"
            "assert 'mujoco' not in sys.modules, 'mujoco was imported'\n")
    subprocess.run([sys.executable, "-c", code], check=True)


def test_loop_writes_closed_and_open_loop_motions_and_a_report(tmp_path, capsys):
    out = tmp_path / "loop"
    assert main(["physics", "loop", "--text", "walk", "--seconds", "1", "--out", str(out)]) == 0
    assert "closed loop, 4 primitives" in capsys.readouterr().out
    report = json.loads((out / "report.json").read_text())
    for side in ("open_loop", "closed_loop"):
        assert report[side]["falls"] == 0
        assert report[side]["assist"]["force_percent_body_weight"] > 0
    assert set(report["closed_loop"]["simulated"]) == {"penetration_mm", "floating_mm", "skating_mm"}
    closed = MotionClip.load(out / "closed.npz")
    assert closed.frames == MotionClip.load(out / "open_kinematic.npz").frames == 2 + 8 * 4
    assert closed.features.shape == (closed.frames, 276) and closed.actions.shape[0] == 4


@pytest.mark.parametrize("args, word", [(["--text", ""], "--text"), (["--assist-hz", "-1"], "assist"),
                                        (["--height", "0.2"], "height"), (["--seconds", "0"], "seconds")])
def test_loop_refuses_bad_settings_in_one_line(args, word, tmp_path, capsys):
    out = tmp_path / "loop"
    assert main(["physics", "loop", "--out", str(out), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and word in err[0], err
    assert not out.exists()
