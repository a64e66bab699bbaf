"""``latentrl export onnx``: the exported controller, run by onnxruntime, reproduces the torch env step by step."""

import contextlib
import io
import json
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from latentrl.app.cli import main

onnx = pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")

from latentrl.envs import FollowPathEnv, ReachLocationEnv, WaypointPath  # noqa: E402
from latentrl.export.onnx import (  # noqa: E402
    ControllerStep,
    controller_metadata,
    export_onnx,
    onnx_session,
    run_session,
)
from latentrl.ppo import load_policy  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
WALK_POLICY = ROOT / "policies" / "reach_walk_default.pt"
TOL = 1e-4


@pytest.fixture(scope="module")
def walk_onnx(tmp_path_factory):
    """The shipped walk policy exported through the CLI at batch 2 with 'walk' baked in."""
    out = tmp_path_factory.mktemp("onnx") / "walk.onnx"
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        assert main(["export", "onnx", str(WALK_POLICY), "--out", str(out), "--batch", "2", "--text", "walk"]) == 0
    line = printed.getvalue()
    assert line.startswith(f"wrote {out} (") and "onnxruntime vs torch over one step" in line
    return out


def _state_feeds(state):
    return [state.history, state.world.rotation, state.world.translation, state.airborne_flags().float()]


def test_shipped_walk_policy_runs_in_onnxruntime_like_the_torch_env(walk_onnx):
    """Each step from the env's state (open loop), and 4 steps feeding onnxruntime its own state (closed loop)."""
    policy = load_policy(WALK_POLICY).policy
    # the shipped walk policy was trained with the foot lock, and the export traces its training env's setting
    env = ReachLocationEnv(2, motion="default", texts=["walk"], autoreset_mode="Disabled", record_history=True,
                           foot_lock=True)
    obs, _ = env.reset(seed=3)
    session = onnx_session(walk_onnx)
    names = [i.name for i in session.get_inputs()]
    assert names == ["history", "world_rotation", "world_translation", "airborne", "goal"]
    closed = _state_feeds(env._state)
    landed = 0
    joints = []
    for _ in range(4):
        goal = env.goal_world.clone()
        action, frames, *state = run_session(session, [*_state_feeds(env._state), goal], names)
        closed_action, closed_frames, *closed = run_session(session, [*closed, goal], names)
        with torch.no_grad():
            expected = policy.act(obs, deterministic=True).action
        landed += int(env._state.airborne_flags().any())
        obs, *_ = env.step(expected)
        for ours, torch_value in zip(state, _state_feeds(env._state)):
            assert (ours - torch_value).abs().max() < 1e-5
        assert (action - expected).abs().max() < 1e-5
        # the last frame (with the lock, the next history's first frame sits one frame's lock shift away)
        assert (frames[:, -1] - env.history_world()[:, -1]).abs().max() < 1e-5
        # fed back, float32 rounding differences pass through the policy's normalizer: actions drift most
        assert (closed_action - expected).abs().max() < 1e-3
        joints.append(closed_frames)
    for ours, torch_value in zip(closed, _state_feeds(env._state)):
        assert (ours - torch_value).abs().max() < TOL
    # the flag is state: this seed has a step that starts in the air, which the graph must land as the env does
    assert landed > 0
    ours = torch.cat(joints, dim=1).numpy()
    for i in range(2):
        assert np.abs(ours[i] - env.export_history(i)["joints"][2:]).max() < TOL


def test_exported_file_passes_the_onnx_checker_and_carries_its_contract(walk_onnx):
    onnx.checker.check_model(str(walk_onnx), full_check=True)
    model = onnx.load(str(walk_onnx))
    assert model.opset_import[0].version == 17
    dims = {v.name: [d.dim_value for d in v.type.tensor_type.shape.dim] for v in (*model.graph.input,
                                                                                   *model.graph.output)}
    assert dims == {"history": [2, 2, 276], "world_rotation": [2, 3, 3], "world_translation": [2, 3], "airborne": [2],
                    "goal": [2, 3], "action": [2, 32], "joints_world": [2, 8, 22, 3], "next_history": [2, 2, 276],
                    "next_world_rotation": [2, 3, 3], "next_world_translation": [2, 3], "next_airborne": [2]}
    meta = {p.key: json.loads(p.value) for p in model.metadata_props}
    assert meta["latentrl.format"] == "latentrl.onnx-controller/2"
    assert meta["latentrl.settings"]["text"] == "walk" and meta["latentrl.settings"]["guidance_scale"] == 5.0
    assert meta["latentrl.settings"]["foot_lock"] is True  # the shipped walk policy's training env
    assert meta["latentrl.settings"]["next_at_last"] is None  # a reach policy sees no next waypoint
    assert [i["name"] for i in meta["latentrl.contract"]["inputs"]] == list(dims)[:5]
    assert len(meta["latentrl.joint_names"]) == 22 and "latentrl.texts" not in meta
    seeds = meta["latentrl.seeds"]["history"]
    history = np.asarray(seeds["data"], dtype=np.float32).reshape(seeds["shape"])
    from latentrl.motion import load_motion_model

    assert np.array_equal(history, load_motion_model("default").seed_history.numpy())


def test_text_input_and_observe_next_on_a_tiny_model(tmp_path):
    """A FollowPath policy that observes the next waypoint, with the text as a graph input."""
    from latentrl.ppo.config import PolicyConfig
    from latentrl.ppo.policy import ActorCritic
    from tests.helpers import make_tiny_model

    tiny_model = make_tiny_model()
    tiny_model.set_respacing("ddim5")  # half the unrolled sampler: a smaller graph, a faster test

    far = WaypointPath(((0.0, 30.0, 0.0), (20.0, 30.0, 0.0)), ("walk", "run"))
    other = WaypointPath(((-25.0, 10.0, 0.0), (-25.0, 40.0, 0.0)), ("run", "walk"))
    env = FollowPathEnv(2, motion=tiny_model, paths=[far, other], path_assignment="by_env", observe_next=True,
                        autoreset_mode="Disabled")
    torch.manual_seed(0)
    policy = ActorCritic(env.single_observation_space.shape[0], env.single_action_space.shape[0],
                         PolicyConfig(latent_dim=32, use_zero_init=False), env.metadata["observation_layout"]).eval()
    step = ControllerStep(policy, tiny_model, 2, observe_next=True)
    path = export_onnx(step, tmp_path / "tiny.onnx", opset=18, metadata=controller_metadata(step, {}, 18))
    session = onnx_session(path)
    names = [i.name for i in session.get_inputs()]
    assert names == ["history", "world_rotation", "world_translation", "airborne", "goal", "next_goal",
                     "text_embedding"]
    obs, _ = env.reset(seed=0)
    text = slice(*env.observation_layout["text"])
    next_goal = torch.tensor([far.waypoints[1], other.waypoints[1]])
    state = _state_feeds(env._state)
    for _ in range(2):
        assert (env.waypoint_index == 0).all()
        action, frames, *state = run_session(session, [*state, env.goal_world, next_goal, obs[:, text]], names)
        with torch.no_grad():
            expected = policy.act(obs, deterministic=True).action
        obs, *_ = env.step(expected)
        assert (action - expected).abs().max() < TOL
        assert (frames[:, -2:] - env.history_world()).abs().max() < TOL
    assert (state[0] - env._state.history).abs().max() < TOL


def test_missing_extra_is_one_line_naming_it(monkeypatch, capsys, tmp_path):
    monkeypatch.setitem(sys.modules, "onnxruntime", None)
    code = main(["export", "onnx", str(WALK_POLICY), "--out", str(tmp_path / "c.onnx")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1
    assert "latentrl[onnx]" in err and "onnxruntime" in err
    assert not (tmp_path / "c.onnx").exists()


@pytest.mark.parametrize("args, pattern", [(["--opset", "13"], "--opset must lie in"),
                                           (["--batch", "0"], "must be > 0")])
def test_bad_arguments_exit_2(args, pattern, capsys, tmp_path):
    code = main(["export", "onnx", str(WALK_POLICY), "--out", str(tmp_path / "c.onnx"), *args])
    assert code == 2 and pattern in capsys.readouterr().err
    assert not (tmp_path / "c.onnx").exists()
