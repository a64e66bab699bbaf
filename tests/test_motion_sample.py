"""``latentrl motion sample``: what it writes (motion, GIF or MP4) and where it says it wrote it."""

from pathlib import Path

import numpy as np
import pytest

from latentrl.app.cli import main
from latentrl.motion import save_motion_model
from latentrl.render import load_motion_npz
from tests.helpers import make_tiny_model


@pytest.fixture(scope="module")
def model_file(tmp_path_factory) -> Path:
    return save_motion_model(make_tiny_model(), tmp_path_factory.mktemp("model") / "motion.pt")


def test_render_mp4_decodes_with_the_motions_frame_count(model_file, tmp_path, capsys):
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")
    out, video = tmp_path / "m.npz", tmp_path / "m.mp4"
    assert main(["motion", "sample", "--motion", str(model_file), "--seconds", "1", "--out", str(out),
                 "--render", str(video)]) == 0
    frames = len(load_motion_npz(out)["joints"])
    reader = imageio_ffmpeg.read_frames(str(video))
    next(reader)
    assert sum(1 for _ in reader) == frames == 2 + 8 * 4  # 1 s = 4 primitives of 8 frames after 2 seed frames
    assert f"wrote {video}" in capsys.readouterr().out


def sample(model_file, tmp_path, *flags) -> dict:
    out = tmp_path / f"m{len(list(tmp_path.iterdir()))}.npz"
    assert main(["motion", "sample", "--motion", str(model_file), "--out", str(out), *flags]) == 0
    return load_motion_npz(out)


def test_durations_set_the_frame_count(model_file, tmp_path, capsys):
    motion = sample(model_file, tmp_path, "--text", "walk:3", "--text", "run:1.5")
    # 3 s = 11.25 primitives -> 11, 1.5 s = 5.6 -> 6; 2 seed frames + 8 per primitive
    assert len(motion["joints"]) == 2 + 8 * (11 + 6) == 138
    texts = list(motion["texts"])
    assert texts[2:] == ["walk"] * 88 + ["run"] * 48
    out = capsys.readouterr().out
    assert f"wrote {tmp_path.resolve()}" in out and "walk 2.93 s, run 1.60 s" in out and "latentrl view" in out


def test_dart_primitive_counts_and_shared_seconds(model_file, tmp_path):
    dart = sample(model_file, tmp_path, "--text", "walk*5,run*3")
    assert len(dart["joints"]) == 2 + 8 * 8 and list(dart["texts"][2:]) == ["walk"] * 40 + ["run"] * 24
    mixed = sample(model_file, tmp_path, "--text", "walk:1", "--text", "run", "--seconds", "3")
    # 3 s = ceil(11.25) = 12 primitives; walk:1 takes round(3.75) = 4, run the 8 left
    assert list(mixed["texts"][2:]) == ["walk"] * 32 + ["run"] * 64
    plain = sample(model_file, tmp_path, "--text", "walk", "--text", "run", "--seconds", "4")
    assert list(plain["texts"][2:]) == ["walk"] * 64 + ["run"] * 56  # 15 primitives: the first text gets 8


@pytest.mark.parametrize("flags, message", [
    (["--text", "walk:x"], r"--text 'walk:x': expected PROMPT or PROMPT:SECONDS"),
    (["--text", "walk*2,run"], r"--text 'walk\*2,run': expected DART's PROMPT\*N.*got 'run'"),
    (["--text", "walk:2", "--seconds", "5"], r"--seconds 5: every --text already has a duration"),
    (["--text", "walk:3", "--text", "run", "--seconds", "2.9"], r"--seconds 2.9: leaves 0 primitives"),
])
def test_bad_timelines_get_one_line(model_file, tmp_path, capsys, flags, message):
    import re

    code = main(["motion", "sample", "--motion", str(model_file), "--out", str(tmp_path / "m.npz"), *flags])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and re.search(message, err), err
    assert not list(tmp_path.iterdir())


def test_foot_lock_cuts_the_slide_and_no_floor_snap_leaves_the_floor(tmp_path):
    import torch

    from latentrl.motion.contacts import foot_positions, weighted_foot_slide

    def slide(motion) -> float:
        return float(weighted_foot_slide(foot_positions(torch.tensor(motion["joints"]))).sum())

    flags = ("--text", "walk:2", "--seed", "3")
    model_file = "default"  # the shipped model walks with planted feet (a random tiny model floats)
    free, locked = sample(model_file, tmp_path, *flags), sample(model_file, tmp_path, *flags, "--foot-lock")
    assert bool(locked["foot_lock"]) and not bool(free["foot_lock"])
    assert slide(locked) < 0.5 * slide(free)
    unsnapped = sample(model_file, tmp_path, *flags, "--no-floor-snap")
    lowest = free["joints"][2:, :, 2].reshape(-1, 8 * 22).min(axis=1)
    assert np.allclose(lowest, 0.0, atol=1e-5)  # the snap puts every primitive's lowest joint on the floor
    assert not np.allclose(unsnapped["joints"][2:, :, 2].reshape(-1, 8 * 22).min(axis=1), 0.0, atol=1e-3)
