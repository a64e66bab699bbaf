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
