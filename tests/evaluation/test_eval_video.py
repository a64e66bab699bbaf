"""``eval/episode``: every ``eval.video_every`` evaluations a tiny training run writes one rendered episode to
TensorBoard (an animated GIF image summary), read back with TensorBoard's ``EventAccumulator``."""

from __future__ import annotations

import io
import json
import re
from pathlib import Path

import numpy as np
import pytest

from latentrl.app.cli import main
from latentrl.errors import ConfigError
from latentrl.evaluation.config import EvalConfig
from latentrl.evaluation.video import EpisodeRecorder, takes_sink
from latentrl.monitor import EVAL_EPISODE

TINY = Path(__file__).resolve().parents[2] / "latentrl" / "configs" / "tiny.yaml"
AWAY = {"goal_location": [[0.0, 30.0, 0.0]], "goal_text": ["walk"]}
"""One waypoint 30 m away: never reached in 3 steps, so every episode runs its whole budget."""


def images(run_dir: Path) -> dict[str, list]:
    """Tag -> image events of the run's events files (what TensorBoard's Images tab shows)."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(run_dir), size_guidance={"images": 0})
    acc.Reload()
    return {tag: acc.Images(tag) for tag in acc.Tags()["images"]}


def train(eval_files, tmp_path: Path, *sets: str) -> Path:
    paths = tmp_path / "away.json"
    paths.write_text(json.dumps([AWAY]))
    run = tmp_path / "run"
    settings = [f"env.motion={eval_files['motion']}", "ppo.eval_every=1", f"eval.paths=[{paths}]", "eval.episodes=1",
                "eval.max_steps=3", "eval.video_size=64", *sets]
    assert main(["train", str(TINY), "--run-dir", str(run), "--no-progress",
                 *[x for s in settings for x in ("--set", s)]]) == 0
    return run


def test_a_tiny_run_writes_an_episode_video_every_n_evaluations(eval_files, tmp_path):
    from PIL import Image

    run = train(eval_files, tmp_path, "eval.video_every=2")  # 2 iterations, 2 evaluations: a video at the first
    events = images(run)[EVAL_EPISODE]
    assert [e.step for e in events] == [64]  # env steps of the first iteration (8 envs x 8 steps)
    assert (events[0].width, events[0].height) == (64, 64)
    with Image.open(io.BytesIO(events[0].encoded_image_string)) as gif:
        # 3 primitives: 2 seed frames + 24 = 26 frames at 30 fps, every 3rd kept: 9 frames at 10 fps
        assert gif.format == "GIF" and gif.size == (64, 64) and gif.n_frames == 9
        assert gif.info["duration"] == 100


def test_video_every_zero_writes_none(eval_files, tmp_path):
    run = train(eval_files, tmp_path, "eval.video_every=0")
    assert EVAL_EPISODE not in images(run)


def test_the_recorder_counts_evaluations_and_keeps_the_first_episode():
    rec = EpisodeRecorder(every=3)
    assert [rec.start() for _ in range(7)] == [True, False, False, True, False, False, True]
    assert not EpisodeRecorder(every=0).start()
    rec.sink(None, {"joints": np.zeros((4, 22, 3))})
    first = rec.clip
    rec.sink(None, {"joints": np.ones((4, 22, 3))})
    assert rec.clip is first  # later episodes are not kept
    assert takes_sink(lambda act, settings, sink=None: None) and not takes_sink(lambda act, settings: None)


@pytest.mark.parametrize(("field", "value", "message"), [
    ("video_every", -1, "video_every: must be >= 0 (0: no video), got -1"),
    ("video_size", 100, "video_size: must be a multiple of 16 from 64 to 640, got 100"),
    ("video_size", 1024, "video_size: must be a multiple of 16 from 64 to 640, got 1024"),
])
def test_bad_video_settings_are_refused_naming_the_field(field, value, message):
    with pytest.raises(ConfigError, match=re.escape(message)):
        EvalConfig(**{field: value}).validate()


def test_train_refuses_a_bad_video_size_in_one_line(tmp_path, capsys):
    code = main(["train", str(TINY), "--run-dir", str(tmp_path / "run"), "--no-progress", "--set",
                 "eval.video_size=100"])
    err = capsys.readouterr().err.strip()
    assert code == 2 and err.endswith("tiny.yaml: eval.video_size: must be a multiple of 16 from 64 to 640, got 100")
    assert len(err.splitlines()) == 1 and not (tmp_path / "run").exists()
