"""What ``latentrl view PATH`` opens (no browser, no Viser): motions, evaluations, runs, folders, bad paths."""

import os
import time

import numpy as np
import pytest

from latentrl.errors import DataError
from latentrl.viewer.scene import bone_segments, contact_weights, floor_extent, frame_camera, joint_colours
from latentrl.viewer.sources import load_clip, metrics_table, open_source, per_frame_goals
from tests.viewer.conftest import walking, write_eval


def test_motion_file(motion_file):
    source = open_source(motion_file)
    assert source.kind == "motion" and len(source.entries) == 1
    assert "50 frames" in source.summary and "walk" in source.summary
    metrics = source.entries[0].metrics
    assert metrics["floor_cm"] == pytest.approx(0.0, abs=0.6) and metrics["skate_cm_s"] >= 0
    clip = source.entries[0].load()
    assert clip.joints.shape == (50, 22, 3) and clip.goals is None and clip.texts[0] == "walk"


def test_evaluation_folder(eval_folder):
    source = open_source(eval_folder)
    assert source.kind == "evaluation" and len(source.entries) == 2
    assert source.entries[0].label == "demo path 0 ep 000 (reached)"
    assert source.entries[1].label == "demo path 0 ep 001 (timeout)"
    assert "success 0.50 ± 0.10" in source.summary
    assert open_source(eval_folder / "report.json").kind == "evaluation"
    clip = source.entries[1].load()
    assert clip.waypoints.shape == (2, 3)
    # goals per frame: seed frames and the first 3 primitives show waypoint 0, the rest waypoint 1
    assert (clip.goals[:26] == [0, 1, 0]).all() and (clip.goals[26:] == [1, 2, 0]).all()
    table = metrics_table(source.entries[1].metrics)
    assert "| success | no |" in table and "| end | timeout |" in table and "| reach time (s) | 1.70 |" in table


def test_run_shows_its_latest_evaluation(tmp_path):
    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    (run / "final.pt").write_bytes(b"")
    with pytest.raises(DataError, match="no evaluation yet.*latentrl eval .*final.pt"):
        open_source(run)
    old = write_eval(run / "eval", episodes=1)
    write_eval(run / "eval-final", episodes=2)
    past = time.time() - 100
    os.utime(old / "report.json", (past, past))
    source = open_source(run)
    assert source.kind == "run" and len(source.entries) == 2 and "eval-final" in source.title


def test_folder_of_motions(tmp_path, motion_file):
    source = open_source(motion_file.parent)
    assert source.kind == "folder" and [e.label for e in source.entries] == ["walk.npz"]


@pytest.mark.parametrize("make, message", [
    (lambda d: d / "missing.npz", "no such file or folder"),
    (lambda d: (d / "notes.txt").write_text("x") and d / "notes.txt", "expected a motion .npz"),
    (lambda d: (d / "p.pt").write_bytes(b"x") and d / "p.pt", "a checkpoint.*latentrl play"),
    (lambda d: (d / "bad.npz").write_text("no zip") and d / "bad.npz", "not a readable motion"),
    (lambda d: (d / "empty").mkdir() or d / "empty", "holds no report.json"),
])
def test_bad_paths_are_one_line(tmp_path, make, message):
    with pytest.raises(DataError, match=message) as err:
        open_source(make(tmp_path))
    assert "\n" not in str(err.value)


def test_evaluation_without_motions(eval_folder):
    import json

    report = json.loads((eval_folder / "report.json").read_text())
    for ep in report["suites"]["demo"]["paths"][0]["episodes"]:
        ep["motion"] = None
    (eval_folder / "report.json").write_text(json.dumps(report))
    with pytest.raises(DataError, match="no motion files.*--no-motions"):
        open_source(eval_folder)


def test_geometry():
    joints = walking(10)
    assert bone_segments(joints[0]).shape == (21, 2, 3)
    lifted = joints[0].copy()
    lifted[11, 2] = 0.05  # right foot 5 cm up
    w = contact_weights(lifted)
    assert w[0] == pytest.approx(1.0, abs=0.05) and w[1] == 0.0
    colours = joint_colours(lifted)
    assert colours[10, 1] > 150 and colours[11, 1] == 150  # green on the floor, grey in the air
    position, look_at = frame_camera(joints)
    assert position[1] < look_at[1] and position[2] > look_at[2]  # behind the start, above
    centre, size = floor_extent(joints)
    assert size >= 6 and np.isfinite(centre).all()


def test_per_frame_goals_without_primitive():
    goals = per_frame_goals(np.array([[1, 0, 0], [2, 0, 0]]), 2 + 16)
    assert goals[:10, 0].tolist() == [1] * 10 and goals[10:, 0].tolist() == [2] * 8


def test_load_clip_rejects_nonfinite(tmp_path):
    joints = walking(5)
    joints[2, 3, 0] = np.nan
    path = tmp_path / "nan.npz"  # written by hand: save_motion_npz itself refuses NaN joints
    np.savez(path, joints=joints, fps=np.float32(30))
    with pytest.raises(DataError, match="non-finite|NaN or inf"):
        load_clip(path)


def _optimize_output(folder):
    """A real ``latentrl optimize`` output folder (tiny model, 2 steps): one keyframe problem, one joint problem."""
    from latentrl.optim import OptimizeSettings, optimize, parse_suite
    from latentrl.optim.report import write_outputs
    from tests.helpers import make_tiny_model

    model = make_tiny_model()
    key = walking(16)[15].tolist()
    problems = parse_suite({"format": "latentrl.constraints/1", "problems": [
        {"name": "key", "primitives": 2, "constraints": [{"type": "keyframe", "frame": 15, "joints": key}]},
        {"name": "wrist", "primitives": 2, "constraints": [{"type": "joint", "frame": 5, "joint": "right_wrist",
                                                            "position": [0.3, 0.5, 1.0]}]}]})
    settings = OptimizeSettings(steps=2)
    write_outputs(optimize(model, problems, settings), folder, settings, {"suite": "hand-made"}, plot=False)
    return folder


def test_optimize_folder_shows_targets_and_ghost_keyframes(tmp_path):
    folder = _optimize_output(tmp_path / "opt")
    source = open_source(folder)
    assert source.kind == "optimize" and len(source.entries) == 2
    assert source.entries[0].label.startswith("key (") and "hand-made" in source.summary
    assert open_source(folder / "report.json").kind == "optimize"
    key = source.entries[0].load()
    assert key.targets.shape == (22, 3) and set(key.target_frames) == {2 + 15}
    assert list(key.keyframes()) == [17] and key.keyframes()[17].shape == (22, 3)
    wrist = source.entries[1].load()
    assert wrist.targets.shape == (1, 3) and wrist.keyframes() == {}
    assert "| goal error (cm) |" in metrics_table(source.entries[0].metrics)


def test_optimize_report_naming_a_file_outside_its_folder_is_refused(tmp_path):
    import json

    folder = _optimize_output(tmp_path / "opt")
    report = json.loads((folder / "report.json").read_text())
    report["problems"][0]["motion"] = "../../etc/passwd"
    (folder / "report.json").write_text(json.dumps(report))
    with pytest.raises(DataError, match="points outside"):
        open_source(folder)
    report["problems"][0]["motion"] = "motions/key.npz"
    report["problems"][0]["targets"] = [{"motion_frame": -1, "position": [0, 0, 0]}]
    (folder / "report.json").write_text(json.dumps(report))
    with pytest.raises(DataError, match="motion_frame"):
        open_source(folder)


def test_scene_draws_targets_in_a_real_viser_server(tmp_path):
    viser = pytest.importorskip("viser")
    from latentrl.viewer.scene import TARGET_DIM, TARGET_ON, SkeletonScene

    clip = open_source(_optimize_output(tmp_path / "opt")).entries[0].load()
    server = viser.ViserServer(host="127.0.0.1", port=0)
    try:
        scene = SkeletonScene(server)
        scene.set_targets(clip.targets, clip.keyframes())
        assert len(scene.target_nodes) == 2 and list(scene.ghosts) == [17]
        scene.show_targets_at(17, clip.target_frames)
        assert (np.asarray(scene.targets.colors) == TARGET_ON).all()
        assert (np.asarray(scene.ghosts[17].colors) == TARGET_ON).all()
        scene.show_targets_at(3, clip.target_frames)
        assert (np.asarray(scene.targets.colors) == TARGET_DIM).all()
        assert (np.asarray(scene.ghosts[17].colors) == TARGET_DIM).all()
        scene.set_targets(None)
        assert scene.target_nodes == []
    finally:
        server.stop()
