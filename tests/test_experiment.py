"""`latentrl train` wiring: config sections -> env -> trainer -> run directory (tiny real models)."""

from pathlib import Path

import pytest
import torch

from latentrl.app.cli import main
from latentrl.app.train import TrainConfig
from latentrl.config import load_config
from latentrl.errors import ConfigError
from latentrl.motion import save_motion_model
from tests.helpers import make_tiny_model

ROOT = Path(__file__).resolve().parents[1]
TINY = ROOT / "configs" / "tiny.yaml"


@pytest.fixture(scope="module")
def motion_file(tmp_path_factory):
    return save_motion_model(make_tiny_model(), tmp_path_factory.mktemp("motion") / "tiny.pt")


def run_cli(*args) -> int:
    return main([str(a) for a in args])


@pytest.mark.parametrize("trainer", ["native", "sb3"])
def test_train_cli_writes_run_directory(motion_file, tmp_path, trainer):
    run = tmp_path / trainer
    code = run_cli("train", TINY, "--set", f"env.motion={motion_file}", "--run-dir", run, "--trainer", trainer,
                   "--no-progress")
    assert code == 0
    assert (run / "config.yaml").is_file() and (run / "final.pt").is_file() and (run / "train.log").is_file()
    assert list((run / "checkpoints").glob("iter_*.pt"))
    saved = load_config(TrainConfig, run / "config.yaml")
    assert saved.env.motion == str(motion_file) and saved.ppo.total_steps == 128


def test_resume_continues_step_count(motion_file, tmp_path):
    run = tmp_path / "run"
    args = ("train", TINY, "--set", f"env.motion={motion_file}", "--total-steps", 256, "--run-dir", run,
            "--no-progress")
    assert run_cli(*args) == 0
    # simulate a run killed after its second iteration: drop what came later
    (run / "final.pt").unlink()
    for it in (3, 4):
        (run / "checkpoints" / f"iter_{it}.pt").unlink(missing_ok=True)
    assert run_cli("train", "--resume", run, "--no-progress") == 0
    log = (run / "train.log").read_text()
    assert "start at iteration 2, 128 env steps" in log
    assert (run / "final.pt").is_file()


def test_train_cli_errors_are_one_line(motion_file, tmp_path, capsys):
    assert run_cli("train", tmp_path / "missing.yaml") == 2
    assert "config file not found" in capsys.readouterr().err
    assert run_cli("train", TINY, "--set", "env.num_envz=3") == 2
    err = capsys.readouterr().err
    assert "env.num_envz" in err and "num_envs" in err and err.count("\n") == 1
    assert run_cli("train", TINY, "--set", f"env.motion={motion_file}", "--device", "cuda:7",
                   "--run-dir", tmp_path / "r") == 2 or torch.cuda.is_available()


def test_shipped_configs_load():
    for path in sorted((ROOT / "configs").glob("*.yaml")):
        cfg = load_config(TrainConfig, path)
        cfg.ppo.plan(cfg.env.num_envs)


def test_bad_values_name_the_field():
    with pytest.raises(ConfigError, match="env.task"):
        load_config(TrainConfig, TINY, ["env.task=dance"])
    with pytest.raises(ConfigError, match="ppo.learning_rate"):
        load_config(TrainConfig, TINY, ["ppo.learning_rate=-0.1"])
