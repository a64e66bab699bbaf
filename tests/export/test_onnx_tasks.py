"""``latentrl export onnx`` of the shipped joystick and timed policies: onnxruntime and torch agree with the env.

Each graph's task inputs carry what the env observes (joystick: the commanded heading and speed;
timed: the waypoint and the time left), and the graph builds the observation with the env's own
functions, so over 4 steps the actions and states match the env's, at batch 2.
"""

import contextlib
import io
import json
from pathlib import Path

import onnx
import pytest
import torch

from latentrl.app.cli import main

pytest.importorskip("onnxruntime")

from latentrl.envs import JoystickEnv, TimedPathEnv  # noqa: E402
from latentrl.export.onnx import onnx_session, run_session  # noqa: E402
from latentrl.ppo import load_policy  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
TOL = 1e-4


def _export(name: str, out: Path) -> Path:
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(["export", "onnx", name, "--out", str(out), "--batch", "2", "--text", "walk"]) == 0
    assert "onnxruntime vs torch over one step" in printed.getvalue()
    return out


def _state_feeds(state):
    return [state.history, state.world.rotation, state.world.translation, state.airborne_flags().float()]


def _agree_over_four_steps(name: str, env, task_inputs, expected_names: list[str], tmp_path: Path) -> dict:
    """Drive ``env`` with the policy for 4 steps; the graph, fed the env's state (open loop) and its own state
    (closed loop) with ``task_inputs(env)``, gives the same actions, states and frames. Returns the metadata."""
    out = _export(name, tmp_path / f"{name}.onnx")
    policy = load_policy(ROOT / "policies" / f"{name}.pt").policy
    session = onnx_session(out)
    names = [i.name for i in session.get_inputs()]
    assert names == ["history", "world_rotation", "world_translation", "airborne", *expected_names]
    obs, _ = env.reset(seed=3)
    closed = _state_feeds(env._state)
    for _ in range(4):
        extra = task_inputs(env)
        action, frames, *state = run_session(session, [*_state_feeds(env._state), *extra], names)
        closed_action, _, *closed = run_session(session, [*closed, *extra], names)
        with torch.no_grad():
            expected = policy.act(obs, deterministic=True).action
        obs, *_ = env.step(expected)
        for ours, torch_value in zip(state, _state_feeds(env._state)):
            assert (ours - torch_value).abs().max() < 1e-5
        assert (action - expected).abs().max() < 1e-5
        assert (frames[:, -1] - env.history_world()[:, -1]).abs().max() < 1e-5
        assert (closed_action - expected).abs().max() < 1e-3
    for ours, torch_value in zip(closed, _state_feeds(env._state)):
        assert (ours - torch_value).abs().max() < TOL
    return {p.key: json.loads(p.value) for p in onnx.load(str(out)).metadata_props}


def test_shipped_joystick_policy_runs_in_onnxruntime_like_the_torch_env(tmp_path):
    env = JoystickEnv(2, motion="default", texts=["walk"], autoreset_mode="Disabled", foot_lock=True)
    meta = _agree_over_four_steps("joystick_walk_default", env,
                                  lambda e: [e.command_heading_deg, e.command_speed],
                                  ["command_heading_deg", "command_speed"], tmp_path)
    assert meta["latentrl.settings"]["task"] == "joystick"
    assert meta["latentrl.settings"]["inputs"] == ["command_heading_deg", "command_speed"]
    assert [i["name"] for i in meta["latentrl.contract"]["inputs"]][4:] == ["command_heading_deg", "command_speed"]


def test_shipped_timed_policy_runs_in_onnxruntime_like_the_torch_env(tmp_path):
    env = TimedPathEnv(2, motion="default", texts=["walk"], autoreset_mode="Disabled", foot_lock=True)
    meta = _agree_over_four_steps("timed_walk_default", env, lambda e: [e.goal_world.clone(), e._time_left()],
                                  ["goal", "time_left"], tmp_path)
    settings = meta["latentrl.settings"]
    assert settings["task"] == "timed" and settings["time_left_clip"] == 10.0 and settings["observe_next"] is False
