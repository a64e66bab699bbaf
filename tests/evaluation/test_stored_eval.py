"""A policy stores the evaluation settings its card's figures need (``eval.foot_lock_min_weight``): ``latentrl
eval POLICY`` takes them without flags, a flag overrides them, and the shipped run policy stores its 0.05."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from latentrl.app.cli import main
from latentrl.evaluation.trained import stored_eval_choices
from tests.evaluation.conftest import NEAR, write_paths

TINY = Path(__file__).resolve().parents[2] / "configs" / "tiny.yaml"


def train(eval_files, run: Path, *sets: str) -> Path:
    settings = [f"env.motion={eval_files['motion']}", "env.foot_lock=true", "ppo.eval_every=0", *sets]
    assert main(["train", str(TINY), "--run-dir", str(run), "--no-progress",
                 *[x for s in settings for x in ("--set", s)]]) == 0
    return run / "final.pt"


@pytest.fixture(scope="module")
def stored(eval_files, tmp_path_factory) -> Path:
    """A tiny trained policy (foot lock trained at the default 0.5) that stores 0.05 for evaluation."""
    return train(eval_files, tmp_path_factory.mktemp("stored") / "run", "eval.foot_lock_min_weight=0.05")


def weight_used(policy: Path, out: Path, *flags: str) -> float:
    paths = write_paths(out.parent, [NEAR], f"{out.name}.json")
    assert main(["eval", str(policy), "--paths", str(paths), "--episodes", "1", "--max-steps", "2", "--device", "cpu",
                 "--out", str(out), "--no-motions", "--no-progress", *flags]) == 0
    return json.loads((out / "report.json").read_text())["settings"]["foot_lock_min_weight"]


def test_eval_takes_the_stored_setting_without_a_flag(stored, tmp_path, capsys):
    assert stored_eval_choices(stored) == {"foot_lock_min_weight": 0.05}
    assert weight_used(stored, tmp_path / "plain") == pytest.approx(0.05)
    assert "contact weight 0.05 (the policy's stored evaluation setting" in capsys.readouterr().out


def test_a_flag_overrides_the_stored_setting(stored, tmp_path):
    assert weight_used(stored, tmp_path / "flag", "--foot-lock-min-weight", "0.3") == pytest.approx(0.3)


def test_a_policy_that_stores_none_keeps_its_training_value(eval_files, tmp_path):
    plain = train(eval_files, tmp_path / "run")
    assert stored_eval_choices(plain) == {}
    assert weight_used(plain, tmp_path / "none") == pytest.approx(0.5)


def test_a_bad_stored_value_is_refused_at_training(eval_files, tmp_path, capsys):
    assert main(["train", str(TINY), "--run-dir", str(tmp_path / "r"), "--no-progress", "--set",
                 f"env.motion={eval_files['motion']}", "--set", "eval.foot_lock_min_weight=3"]) == 2
    assert "foot_lock_min_weight" in capsys.readouterr().err


def test_the_shipped_run_policy_stores_its_cards_setting():
    from latentrl.resources import policy_file

    assert stored_eval_choices(policy_file("reach_run_default")) == {"foot_lock_min_weight": 0.05}
    assert stored_eval_choices(policy_file("reach_walk_default")) == {}
