"""Runs can be extended and resume exactly (issue 16, part 3): --total-steps on --resume, env state, old configs."""

import shutil
from pathlib import Path

import pytest
import torch
import yaml

from latentrl.app.cli import main
from latentrl.motion import save_motion_model
from latentrl.ppo.checkpoint import read_checkpoint
from tests.helpers import make_tiny_model
from tests.ppo.helpers import scalars

TINY = Path(__file__).resolve().parents[1] / "configs" / "tiny.yaml"
LOSSES = ("train/value_loss", "train/policy_gradient_loss", "train/approx_kl", "train/learning_rate")


@pytest.fixture(scope="module")
def motion_file(tmp_path_factory):
    return save_motion_model(make_tiny_model(), tmp_path_factory.mktemp("motion") / "tiny.pt")


def train(motion_file, run, *args) -> int:
    # episodes of 12 primitives span iterations of 8 steps: a resume must continue them mid-way
    return main(["train", str(TINY), "--set", f"env.motion={motion_file}", "--set", "env.max_episode_steps=12",
                 "--run-dir", str(run), "--no-progress", *map(str, args)])


def test_interrupted_and_resumed_run_matches_the_uninterrupted_one(motion_file, tmp_path):
    whole, cut = tmp_path / "whole", tmp_path / "cut"
    assert train(motion_file, whole, "--total-steps", 256) == 0
    shutil.copytree(whole, cut)
    (cut / "final.pt").unlink()  # killed during iteration 3: iter_2.pt is the newest checkpoint
    for it in (3, 4):
        (cut / "checkpoints" / f"iter_{it}.pt").unlink(missing_ok=True)  # the last one is final.pt
    assert main(["train", "--resume", str(cut), "--no-progress"]) == 0
    a, b = scalars(whole), scalars(cut)
    for tag in LOSSES:
        assert [s for s, _ in b[tag]] == [64, 128, 192, 256], tag
        assert b[tag] == a[tag], tag
    pa, pb = read_checkpoint(whole / "final.pt")["policy"], read_checkpoint(cut / "final.pt")["policy"]
    assert all(torch.equal(pa[k], pb[k]) for k in pa)


def test_total_steps_extends_a_finished_run_and_other_changes_are_refused(motion_file, tmp_path, capsys):
    run = tmp_path / "run"
    assert train(motion_file, run) == 0  # 128 steps: 2 iterations
    capsys.readouterr()
    assert main(["train", "--resume", str(run), "--total-steps", "64", "--no-progress"]) == 2
    assert "ppo.total_steps 64 is below the run's budget 128" in capsys.readouterr().err
    assert main(["train", "--resume", str(run), "--total-steps", "256", "--set", "ppo.learning_rate=1e-3",
                 "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "ppo.learning_rate: 0.0003 -> 0.001" in err and "ppo.total_steps" not in err
    assert main(["train", "--resume", str(run), "--total-steps", "256", "--no-progress"]) == 0
    assert "trained 4 iterations (256 env steps)" in capsys.readouterr().out
    assert yaml.safe_load((run / "config.yaml").read_text())["ppo"]["total_steps"] == 256
    lr = dict(scalars(run)["train/learning_rate"])
    # the linear anneal is recomputed over the new total: lr_k = (1 - k / K_new) lr_0 from iteration k = 2 on
    assert lr[128] == pytest.approx(3e-4 * (1 - 1 / 2))
    assert lr[192] == pytest.approx(3e-4 * (1 - 2 / 4)) and lr[256] == pytest.approx(3e-4 * (1 - 3 / 4))
    assert main(["train", "--resume", str(run), "--no-progress"]) == 0  # continues nothing: already at 256
    assert read_checkpoint(run / "final.pt")["env_steps"] == 256


def _old_layout(env: dict) -> dict:
    """The flat ``env:`` section runs wrote before env.reach/env.path/env.rewards (and env.seed_history)."""
    from latentrl.envs.config import ALIASES

    old = {k: v for k, v in env.items() if k not in ("reach", "path", "rewards", "seed_history", "joystick", "timed")}
    sections = {**env["reach"], **env["path"]}
    return {**old, **{k: v for k, v in sections.items() if k in ALIASES}}  # fields added since stay defaults


def test_runs_written_before_the_env_sections_still_resume(motion_file, tmp_path):
    run = tmp_path / "run"
    assert train(motion_file, run) == 0
    text = yaml.safe_load((run / "config.yaml").read_text())
    text["env"] = _old_layout(text["env"])
    (run / "config.yaml").write_text(yaml.safe_dump(text))
    for path in [run / "final.pt", *sorted((run / "checkpoints").glob("*.pt"))]:
        state = read_checkpoint(path)
        state["config"]["env"] = _old_layout(state["config"]["env"])
        torch.save(state, path)
    assert main(["train", "--resume", str(run), "--total-steps", "192", "--no-progress"]) == 0
    assert read_checkpoint(run / "final.pt")["env_steps"] == 192
