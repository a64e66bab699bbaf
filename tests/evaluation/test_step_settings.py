"""One ``StepSettings``: every field set away from its default reaches the env, ``latentrl eval``, ``latentrl play``
and ``latentrl export onnx`` from the training config a checkpoint stores; old checkpoints get the defaults."""

from __future__ import annotations

import dataclasses
import json

import pytest
import torch

from latentrl.app.cli import main
from latentrl.envs.config import EnvConfig, build
from latentrl.envs.settings import StepSettings
from latentrl.errors import ConfigError
from tests.evaluation.conftest import NEAR, write_paths
from tests.helpers import make_tiny_model

CHANGED = StepSettings(guidance_scale=3.0, action_bound=2.5, foot_lock=True, foot_lock_min_weight=0.2, amp="bf16")


def test_every_field_is_changed_here():
    default = StepSettings()
    assert all(getattr(CHANGED, f.name) != getattr(default, f.name) for f in dataclasses.fields(StepSettings))


@pytest.fixture
def trained(eval_files, tmp_path):
    """The test policy with a stored env config that sets every step setting to CHANGED."""
    state = torch.load(eval_files["policy"], weights_only=True)
    state["config"] = {"env": {"motion": str(eval_files["motion"]), **dataclasses.asdict(CHANGED)}}
    policy = tmp_path / "changed.pt"
    torch.save(state, policy)
    return policy


def test_the_env_takes_the_configs_settings():
    env = build(EnvConfig(num_envs=1, **dataclasses.asdict(CHANGED)), "cpu", motion=make_tiny_model())
    assert env.step_settings == CHANGED
    assert (env.guidance_scale, env.action_bound, env.foot_lock, env.foot_lock_min_weight, env.amp) == (
        3.0, 2.5, True, 0.2, "bf16")
    assert env.single_action_space.high.max() == 2.5


def test_eval_records_every_setting(trained, tmp_path):
    out = tmp_path / "o"
    assert main(["eval", str(trained), "--paths", str(write_paths(tmp_path, [NEAR])), "--episodes", "1",
                 "--max-steps", "1", "--device", "cpu", "--out", str(out), "--no-render", "--no-motions"]) == 0
    settings = json.loads((out / "report.json").read_text())["settings"]
    assert {k: settings[k] for k in dataclasses.asdict(CHANGED)} == dataclasses.asdict(CHANGED)


def test_play_builds_its_env_with_every_setting(trained, eval_files):
    from latentrl.motion.checkpoint import load_motion_model
    from latentrl.viewer.live import play_env

    checkpoint = torch.load(trained, weights_only=True)
    env = play_env(checkpoint, load_motion_model(str(eval_files["motion"])), None, "cpu")
    assert env.step_settings == CHANGED


def test_the_onnx_controller_carries_every_setting(trained, eval_files):
    from latentrl.export.onnx import controller_metadata, load_controller

    step, info = load_controller(trained, motion=str(eval_files["motion"]))
    assert step.settings == CHANGED
    meta = json.loads(controller_metadata(step, info)["latentrl.settings"])
    assert (meta["guidance_scale"], meta["action_bound"], meta["foot_lock"], meta["foot_lock_min_weight"],
            meta["training_amp"]) == (3.0, 2.5, True, 0.2, "bf16")


def test_an_old_checkpoint_without_the_newer_fields_gets_their_defaults():
    old = {"env": {"guidance_scale": 4.0, "foot_lock": True}}  # written before foot_lock_min_weight and amp existed
    assert StepSettings.of(old["env"]) == StepSettings(guidance_scale=4.0, foot_lock=True)
    from latentrl.evaluation.trained import stored_step_settings

    assert stored_step_settings(old) == StepSettings(guidance_scale=4.0, foot_lock=True)
    assert stored_step_settings(None) == StepSettings()


@pytest.mark.parametrize("field, value", [("guidance_scale", float("nan")), ("action_bound", 0.0),
                                          ("foot_lock_min_weight", 0.0), ("amp", "fp8")])
def test_one_validation_names_the_field(field, value):
    with pytest.raises(ConfigError, match=field):
        StepSettings(**{field: value}).validate()
    with pytest.raises(ConfigError, match=field):
        EnvConfig(**{field: value}).validate()
    with pytest.raises(ConfigError, match=field):
        build(EnvConfig(num_envs=1), "cpu", motion=make_tiny_model(), **{field: value})
