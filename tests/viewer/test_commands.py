"""``latentrl view`` / ``latentrl play`` without a browser: bad input, the missing extra, Ctrl-C, live control."""

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from latentrl.app.cli import main
from tests.viewer.conftest import walk_controller

ROOT = Path(__file__).resolve().parents[2]
POLICY = ROOT / "policies" / "reach_walk_default.pt"


def one_line_error(capsys, argv, pattern):
    code = main(argv)
    err = capsys.readouterr().err.strip()
    assert code == 2, err
    assert len(err.splitlines()) == 1, err
    assert pattern in err, err


@pytest.mark.parametrize("argv, pattern", [
    (["view", "nowhere.npz"], "no such file or folder"),
    (["view", str(POLICY)], "latentrl play"),
    (["view", str(ROOT / "README.md")], "expected a motion .npz"),
    (["play", "nowhere.pt"], "no such policy checkpoint"),
    (["view", "x.npz", "--port", "70000"], "expected a port in 0..65535"),
    (["play", str(POLICY), "--port", "http"], "expected a port in 0..65535"),
])
def test_bad_input(capsys, argv, pattern):
    one_line_error(capsys, argv, pattern)


def test_port_in_use(capsys, motion_file):
    pytest.importorskip("viser")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        one_line_error(capsys, ["view", str(motion_file), "--port", str(port)], f"--port {port}: already in use")
        one_line_error(capsys, ["play", str(POLICY), "--port", str(port)], f"--port {port}: already in use")


@pytest.mark.parametrize("name, task", [("timed_walk_default", "timed")])
def test_play_refuses_a_task_it_cannot_steer_by_name(capsys, name, task):
    """A shipped timed policy: one line naming its task, not a dimension blaming the motion model."""
    one_line_error(capsys, ["play", name], f"this policy's task is '{task}'")


def test_play_takes_shipped_names_and_refuses_a_next_waypoint_policy(capsys):
    pytest.importorskip("viser")
    with socket.socket() as busy:  # the name resolves: play gets as far as the busy port
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        one_line_error(capsys, ["play", "reach_walk_default", "--port", str(port)], f"--port {port}: already in use")
    one_line_error(capsys, ["play", "path_mixed_default", "--port", "0", "--device", "cpu"],
                   "also observes the next waypoint")


def test_unresolvable_host(capsys, motion_file):
    pytest.importorskip("viser")
    one_line_error(capsys, ["view", str(motion_file), "--host", "no.such.host.invalid"], "cannot be resolved")


def test_missing_extra_names_it(capsys, motion_file, monkeypatch):
    monkeypatch.setitem(sys.modules, "viser", None)  # import viser -> ImportError
    one_line_error(capsys, ["view", str(motion_file)], "pip install 'latentrl[viewer]'")
    one_line_error(capsys, ["play", str(POLICY)], "optional extra 'viewer'")


def test_nothing_else_imports_the_viewer():
    for path in (ROOT / "latentrl").rglob("*.py"):
        if "viewer" in path.parts or path.name == "cli.py":
            continue
        assert "latentrl.viewer" not in path.read_text(), path


def test_ctrl_c_stops_cleanly(motion_file):
    pytest.importorskip("viser")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-m", "latentrl.app.cli", "view", str(motion_file), "--port", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    try:
        line = proc.stdout.readline()
        assert line.startswith("latentrl view: open http://127.0.0.1:") and "Ctrl-C" in line, line
        proc.send_signal(signal.SIGINT)
        out, _ = proc.communicate(timeout=20)
    finally:
        proc.kill()
    assert proc.returncode == 0, out
    assert out.strip().splitlines()[-1] == "latentrl view: stopped", out


def test_player_without_browser(server, eval_folder):
    from latentrl.viewer.playback import Player
    from latentrl.viewer.sources import open_source

    player = Player(server, open_source(eval_folder))
    assert player.clip.frames == 50 and player.slider.max == 49
    player.toggle()
    assert not player.playing and player.play.label == "Play"
    player.select(player.source.entries[1].label)
    assert "timeout" in player.metrics.content
    player.start()
    time.sleep(0.2)
    player.stop.set()
    player.thread.join(2)


def test_live_control_walks_to_the_goal(server):
    """The shipped walk policy, driven by the controller's own loop, walks towards a goal set as a click would."""
    from latentrl.viewer.live import floor_point

    live = walk_controller(server)
    env = live.env
    start = live.pelvis().copy()
    goal = floor_point((0.0, -4.0, 3.0), (0.3, 0.8, -0.5))  # a click ray in front of the start pose, to the right
    assert goal is not None and floor_point((0, 0, 1), (0, 0, 1)) is None
    live.set_goal(goal[:2])
    before = np.hypot(*(goal[:2] - start[:2]))
    for _ in range(12):  # one primitive per call: 96 frames, 3.2 s of motion
        live._generate()
        while live.frames:
            live._show_next()
    after = np.hypot(*(goal[:2] - live.pelvis()[:2]))
    assert after < before - 0.8, (before, after)
    assert "pelvis:" in live.status_text() and "generation:" in live.status_text()
    live.text.value = "run"  # as the dropdown does
    assert env.text == "run"
    live.reset()
    assert np.allclose(live.pelvis()[:2], start[:2]) and live.goal is None and env.text == "run"
