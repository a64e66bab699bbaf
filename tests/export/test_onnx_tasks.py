"""``latentrl export onnx`` of the shipped joystick, timed, obstacle, maze and ReachJoint policies: onnxruntime and
torch agree with the env.

Each graph's task inputs carry what the env observes (joystick: the commanded heading and speed; timed: the waypoint
and the time left; obstacles: the goal and the scene rays the engine casts; maze: the waypoint, the next one and the
rays; ReachJoint: the joint, its target, whether it is planar and the time left), and the graph builds the
observation with the env's own functions, so over 4 steps the actions and states match the env's, at batch 2.
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
        closed = closed[:4]  # the state; a scene policy's graph also says where to cast the next rays
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


def test_shipped_reach_joint_policy_runs_in_onnxruntime_like_the_torch_env(tmp_path):
    """Goals of several joints (planar and 3-D) fall due within the 4 steps: the graph's one-hot and gather of the
    goal joint observe as the env does."""
    from latentrl.envs.reach_joint import JOINTS, JointGoal, JointGoalEntry, ReachJointEnv
    from latentrl.motion.skeleton import FPS

    entries = [JointGoalEntry("walk", (JointGoal("pelvis", (0.1, 0.4), 0.2), JointGoal("left_foot", (-0.1, 0.6), 0.5),
                                       JointGoal("right_hand", (0.3, 1.0, 1.0), 1.0))),
               JointGoalEntry("walk", (JointGoal("head", (0.0, 0.5, 1.6), 0.3), JointGoal("pelvis", (0.2, 1.2), 1.2)))]
    env = ReachJointEnv(2, motion="default", goals=entries, autoreset_mode="Disabled", foot_lock=True,
                        joints=("pelvis",), planar=("pelvis",))

    def task_inputs(e):
        g = e.current_goal()
        slot = e._joint[e._rows, e._gi].float()
        return [g["target"].clone(), slot, g["planar"].float(), (g["frame"] - e._now_frame()).float() / FPS]

    meta = _agree_over_four_steps("reach_joint_default", env, task_inputs,
                                  ["joint_target", "goal_joint", "goal_planar", "time_left"], tmp_path)
    settings = meta["latentrl.settings"]
    assert settings["task"] == "reach_joint" and settings["joints"] == list(JOINTS)
    assert settings["time_left_clip"] == 10.0 and settings["observe_next"] is False


def test_shipped_obstacle_policy_takes_the_engines_rays_and_says_where_to_cast_the_next(tmp_path):
    from latentrl.envs import ReachLocationEnv
    from latentrl.envs.scene import ray_fan
    from latentrl.scenes import Box, Cylinder, Scene

    room = Scene((Box((0.4, 1.6), (0.6, 0.5, 1.0)), Cylinder((-0.8, 2.5), 0.3, 1.2), Box((1.5, 0.0), (0.3, 2.0, 1.0))))
    env = ReachLocationEnv(2, motion="default", texts=["walk"], autoreset_mode="Disabled", foot_lock=True,
                           scene=room)
    cast = []

    def inputs(e):
        rays = e.scene.rays(e.history_world())
        cast.append(rays)
        return [e.goal_world.clone(), rays]

    meta = _agree_over_four_steps("reach_obstacles_default", env, inputs, ["goal", "scene_rays"], tmp_path)
    assert all(float(r.min()) < 4.0 for r in cast)  # the rays saw the room
    assert meta["latentrl.settings"]["scene_rays"]["count"] == 16
    seeds = meta["latentrl.seeds"]
    assert len(seeds["ray_directions"]["shape"]) == 3 and seeds["ray_directions"]["shape"][1:] == [16, 2]
    # the graph's next_ray_* are the env's fan after the step, so an engine casts exactly the env's rays
    session = onnx_session(tmp_path / "reach_obstacles_default.onnx")
    names = [i.name for i in session.get_inputs()]
    outs = [o.name for o in session.get_outputs()]
    assert outs[-2:] == ["next_ray_origin", "next_ray_directions"]
    env.reset(seed=5)
    feeds = [*_state_feeds(env._state), *inputs(env)]
    with torch.no_grad():
        action = load_policy(ROOT / "policies" / "reach_obstacles_default.pt").policy.act(
            env.observation(), deterministic=True).action
    *_, origin, dirs = run_session(session, feeds, names)
    env.step(action)
    want_origin, want_dirs = ray_fan(env.history_world())
    assert (origin - want_origin).abs().max() < 1e-4 and (dirs - want_dirs).abs().max() < 1e-4


def test_shipped_maze_policy_takes_the_next_waypoint_and_the_rays_of_its_maze(tmp_path):
    from latentrl.envs import FollowPathEnv
    from latentrl.envs.path import load_paths
    from latentrl.resources import packaged

    maze = load_paths(packaged("tasks") / "paths" / "maze.json")[0]  # maze_a's route, in maze_a
    env = FollowPathEnv(2, motion="default", texts=["walk"], paths=[maze], path_assignment="by_env",
                        observe_next=True, next_at_last="extend", autoreset_mode="Disabled", foot_lock=True,
                        scene=maze.scene)
    meta = _agree_over_four_steps("path_maze_default", env,
                                  lambda e: [e.goal_world.clone(), e._waypoint(1).clone(),
                                             e.scene.rays(e.history_world())],
                                  ["goal", "next_goal", "scene_rays"], tmp_path)
    settings = meta["latentrl.settings"]
    assert settings["task"] == "path" and settings["observe_next"] is True and settings["next_at_last"] == "extend"
    assert settings["scene_rays"]["count"] == 16
