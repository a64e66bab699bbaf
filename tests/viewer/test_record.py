"""``latentrl view/play --record FILE``: the frames a page showed, drawn as GIF or MP4 once the viewer stops."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from latentrl.app.cli import main
from tests.viewer.conftest import walk_controller, walking

ROOT = Path(__file__).resolve().parents[2]


def frame_count(path: Path) -> int:
    if path.suffix == ".gif":
        from PIL import Image

        with Image.open(path) as im:
            return im.n_frames
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(path))
    next(reader)
    return sum(1 for _ in reader)


def test_recorder_keeps_the_last_frames_and_writes_them(tmp_path, capsys):
    pytest.importorskip("imageio_ffmpeg")
    from latentrl.viewer.record import Recorder

    rec = Recorder(tmp_path / "r.mp4", "view", max_frames=20)
    joints = walking(25)
    for i, pose in enumerate(joints):
        rec.add(pose, "walk", np.array([0.0, 2.0 + (i > 10), 0.0]))
    assert len(rec.frames) == 20 and len(rec.goals) == 2
    assert np.array_equal(rec.frames[0][0], joints[5])  # the oldest five fell out
    assert rec.write() == tmp_path / "r.mp4" and frame_count(tmp_path / "r.mp4") == 20
    assert "latentrl view: wrote" in capsys.readouterr().out


def test_nothing_played_writes_nothing(tmp_path, capsys):
    from latentrl.viewer.record import Recorder

    assert Recorder(tmp_path / "r.gif", "play").write() is None
    assert "nothing was played" in capsys.readouterr().out and not list(tmp_path.iterdir())


def test_player_records_what_it_plays(server, eval_folder, tmp_path):
    from latentrl.viewer.playback import Player
    from latentrl.viewer.record import Recorder
    from latentrl.viewer.sources import open_source

    rec = Recorder(tmp_path / "v.gif", "view")
    player = Player(server, open_source(eval_folder), rec)
    for _ in range(9):
        with player.lock:
            player._advance(1 / 30)  # one tick of the playback thread at speed 1: one frame
    assert len(rec.frames) == 9
    assert np.array_equal(rec.frames[-1][0], player.clip.joints[9])
    assert frame_count(rec.write()) == 3  # a GIF keeps every 3rd frame


def test_play_records_every_frame_shown(server, tmp_path):
    pytest.importorskip("imageio_ffmpeg")
    from latentrl.viewer.record import Recorder

    live = walk_controller(server)
    live.recorder = Recorder(tmp_path / "p.mp4", "play")
    live.set_goal((0.5, 3.0))
    for _ in range(2):
        live._generate()
        while live.frames:
            live._show_next()
    assert len(live.recorder.frames) == 16 and len(live.recorder.goals) == 1
    assert frame_count(live.recorder.write()) == 16


@pytest.mark.parametrize("argv, pattern", [
    (["view", "{motion}", "--record", "{tmp}/x.avi"], "--record must name a .gif or .mp4 file"),
    (["view", "{motion}", "--record", "{tmp}/afile/x.gif"], "--record folder"),
    (["play", "reach_walk_default", "--record", "x.webm"], "--record must name a .gif or .mp4 file"),
])
def test_bad_record_paths_get_one_line_before_any_server(capsys, motion_file, tmp_path, argv, pattern):
    (tmp_path / "afile").write_text("")
    code = main([a.format(motion=motion_file, tmp=tmp_path) for a in argv])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and pattern in err, err


def test_view_record_end_to_end(motion_file, tmp_path):
    pytest.importorskip("viser")
    out = tmp_path / "view.gif"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    argv = [sys.executable, "-m", "latentrl.app.cli", "view", str(motion_file), "--port", "0", "--record", str(out)]
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=env)
    try:
        line = proc.stdout.readline()
        assert line.startswith("latentrl view: open http://127.0.0.1:"), line
        time.sleep(1.0)  # the page plays (no browser needed) and every frame played is kept
        proc.send_signal(signal.SIGINT)
        log, _ = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0, log
    assert f"latentrl view: wrote {out}" in log and frame_count(out) >= 3, log
