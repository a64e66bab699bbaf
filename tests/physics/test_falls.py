"""A body that falls in ``physics track`` / ``physics loop`` is never a silent success: the report counts the falls
and their frames, one stderr line says so, and the exit status is 4 (the outputs are written and load)."""

import json

import numpy as np
import pytest

pytest.importorskip("mujoco")

from latentrl.app.cli import main  # noqa: E402
from latentrl.app.physics import FELL_EXIT  # noqa: E402
from latentrl.motion.clip import MotionClip  # noqa: E402


def _joints_only(tmp_path, name, joints, fps):
    path = tmp_path / name
    np.savez(path, joints=joints, fps=fps)
    return path


@pytest.mark.parametrize("kind", ["teleport", "fly"])
def test_a_motion_the_body_cannot_follow_is_reported_as_falls_with_exit_4(kind, sampled_walk, tmp_path, capsys):
    clip = dict(np.load(sampled_walk))
    joints = clip["joints"].copy()
    args = []
    if kind == "teleport":  # half-way through, the whole body jumps 3 m forward
        joints[33:, :, 0] += 3.0
    else:  # the body rises 1 m in 0.7 s and floats; with the root assist off nothing holds it up there
        joints[..., 2] += (np.clip((np.arange(len(joints)) - 10) / 20, 0, 1) * 1.0)[:, None]
        args = ["--assist-hz", "0"]
    path = _joints_only(tmp_path, f"{kind}.npz", joints, clip["fps"])
    out = tmp_path / "out"
    assert main(["physics", "track", str(path), "--out", str(out), *args]) == FELL_EXIT
    captured = capsys.readouterr()
    report = json.loads((out / "report.json").read_text())
    assert report["falls"] >= 1 and len(report["fall_frames"]) == report["falls"]
    if kind == "teleport":
        assert 33 in report["fall_frames"]
    assert f"falls {report['falls']}," in captured.out.strip().splitlines()[-1]
    err = captured.err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in captured.err, err
    assert err[0].startswith(f"latentrl: physics track: the humanoid fell {report['falls']} time"), err
    assert str(report["fall_frames"][0]) in err[0] and err[0].endswith(f"exit {FELL_EXIT}"), err
    assert MotionClip.load(out / "motion.npz").frames == len(joints)


def test_a_closed_loop_that_falls_is_reported_with_exit_4(tmp_path, capsys):
    out = tmp_path / "loop"
    assert main(["physics", "loop", "--text", "walk", "--seconds", "2", "--assist-hz", "0",
                 "--out", str(out)]) == FELL_EXIT
    report = json.loads((out / "report.json").read_text())
    falls = {side: report[side]["falls"] for side in ("open_loop", "closed_loop")}
    assert falls["closed_loop"] >= 1, falls
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("latentrl: physics loop: the humanoid fell "), err
    assert f"{falls['closed_loop']} time" in err[0] and "in the closed loop" in err[0], err
    assert MotionClip.load(out / "closed.npz").frames == 2 + 8 * 8
