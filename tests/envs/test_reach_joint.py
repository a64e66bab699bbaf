"""ReachJoint: the observation layout, the error and success at the goal time, random goals in range, the
rewards, joint-goal files and their errors, the config section, and the Gymnasium id."""

import json
import math

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env

import latentrl  # noqa: F401  (registers the ids)
from latentrl.envs.reach_joint import (
    JOINTS,
    JointGoal,
    JointGoalEntry,
    ReachJointConfig,
    ReachJointEnv,
    goal_frame,
    load_joint_goals,
)
from latentrl.errors import ConfigError, DataError
from latentrl.motion.skeleton import FPS
from tests.envs.conftest import actions

ENTRY = JointGoalEntry("walk", (JointGoal("pelvis", (0.3, 0.5, 0.8), 0.2),
                                JointGoal("left_foot", (0.1, 0.9), 0.4),
                                JointGoal("right_hand", (0.2, 1.0, 1.0), 1.0)))


def make(tiny_model, n=2, **kwargs) -> ReachJointEnv:
    return ReachJointEnv(n, motion=tiny_model, **kwargs)


def test_observation_layout_carries_the_goal_in_the_body_frame_the_joint_and_the_time_left(tiny_model):
    env = make(tiny_model, goals=[ENTRY], max_episode_steps=8)
    fields = env.observation_fields
    assert list(fields)[:5] == ["goal_vec", "goal_dist", "joint", "planar", "time_left"]
    assert [b - a for a, b in list(fields.values())[:5]] == [3, 1, len(JOINTS), 1, 1]
    obs, _ = env.reset(seed=0)
    last = env.history_world()[:, -1, JOINTS["pelvis"]]
    offset = torch.tensor(ENTRY.goals[0].target) - last
    body = (offset[:, None, :] @ env._state.world.rotation)[:, 0]  # R^T v: the body frame of history frame 0
    assert obs[:, slice(*fields["goal_vec"])] == pytest.approx(body, abs=1e-5)
    assert obs[:, slice(*fields["goal_dist"])].flatten() == pytest.approx(offset.norm(dim=-1), abs=1e-5)
    assert obs[:, slice(*fields["joint"])].tolist() == [[1.0, 0, 0, 0, 0, 0]] * 2
    assert obs[:, slice(*fields["planar"])].flatten().tolist() == [0.0, 0.0]
    assert obs[:, slice(*fields["time_left"])].flatten() == pytest.approx([6 / FPS] * 2)
    # after the first step the current goal is the left foot's: 2-D, z of the offset is 0
    obs, *_ = env.step(actions(2, 0))
    assert obs[:, slice(*fields["joint"])].argmax(dim=1).tolist() == [list(JOINTS).index("left_foot")] * 2
    assert obs[:, slice(*fields["planar"])].flatten().tolist() == [1.0, 1.0]
    vec = obs[:, slice(*fields["goal_vec"])]
    assert vec[:, 2].abs().max() < 1e-6
    assert obs[:, slice(*fields["time_left"])].flatten() == pytest.approx([(12 - 8) / FPS] * 2)


def test_error_and_success_are_measured_at_the_goal_frame(tiny_model):
    env = make(tiny_model, goals=[ENTRY], max_episode_steps=8, record_history=True, autoreset_mode="Disabled")
    env.reset(seed=0)
    due, errors, ends = [], [], []
    for k in range(4):
        _, reward, terminated, _, infos = env.step(actions(2, k))
        due.append(infos["goal_due"].tolist())
        errors.append(infos["joint_error_m"])
        ends.append((terminated.tolist(), infos["is_success"].tolist()))
    # frames 6 and 12 fall in steps 0 and 1, frame 30 in step 3 (frames 25-32), which ends the entry
    assert due == [[True] * 2, [True] * 2, [False] * 2, [True] * 2]
    assert ends[3][0] == [True, True] and ends[2][0] == [False, False]
    record, frames = env.goal_record()
    assert frames[0].tolist() == [6, 12, 30]
    joints = torch.as_tensor(env.export_clip(0, episode=0).joints)  # frame m of the episode is clip frame 1 + m
    expect = [(joints[7, JOINTS["pelvis"]] - torch.tensor([0.3, 0.5, 0.8])).norm(),
              (joints[13, JOINTS["left_foot"], :2] - torch.tensor([0.1, 0.9])).norm(),
              (joints[31, JOINTS["right_hand"]] - torch.tensor([0.2, 1.0, 1.0])).norm()]
    assert record[0].tolist() == pytest.approx([float(e) for e in expect], abs=1e-5)
    assert errors[0][0] == pytest.approx(float(expect[0]), abs=1e-5)
    assert math.isnan(float(errors[2][0]))
    # success: every goal of the entry within the radius at its frame
    assert ends[3][1] == [bool((record[i] < 0.1).all()) for i in range(2)]
    wide = make(tiny_model, goals=[ENTRY], max_episode_steps=8, radius=100.0, autoreset_mode="Disabled")
    wide.reset(seed=0)
    for k in range(4):
        _, _, terminated, _, infos = wide.step(actions(2, k))
    assert terminated.all() and infos["is_success"].all()


def test_goals_in_one_step_are_each_scored_and_asap_goals_get_a_time(tiny_model):
    entry = JointGoalEntry("walk", (JointGoal("pelvis", (0.0, 0.1), 1 / FPS), JointGoal("pelvis", (0.0, 0.2), 3 / FPS),
                                    JointGoal("left_foot", (0.0, 1.2), None)))
    env = make(tiny_model, goals=[entry], max_episode_steps=12, max_speed=1.0, autoreset_mode="Disabled")
    env.reset(seed=0)
    _, _, terminated, _, _ = env.step(actions(2, 0))
    record, frames = env.goal_record()
    assert torch.isfinite(record[:, :2]).all() and torch.isnan(record[:, 2]).all() and not terminated.any()
    # the asap footstep leaves the previous target (0, 0.2) at its frame 3: 1.0 m at 1.0 m/s is 30 frames later
    assert frames[:, 2].tolist() == [33, 33]
    # a first goal asap is timed from where its joint is at the start
    first = JointGoalEntry("walk", (JointGoal("left_foot", (0.0, 1.2), None),))
    env = make(tiny_model, goals=[first], max_episode_steps=12, max_speed=1.0, autoreset_mode="Disabled")
    env.reset(seed=0)
    foot = env.history_world()[:, -1, JOINTS["left_foot"], :2]
    need = ((foot - torch.tensor([0.0, 1.2])).norm(dim=-1) / 1.0 * FPS).ceil().long()
    assert env.goal_record()[1][:, 0].tolist() == need.clamp(min=1).tolist()


def test_random_goals_lie_in_their_time_distance_and_angle_ranges(tiny_model):
    env = make(tiny_model, 64, joints=("pelvis", "left_foot", "right_hand"), near_share=0.5, far_time=(1.0, 2.0),
               distance=(0.2, 3.0), max_speed=1.2, angle_deg=45.0, height_offset=(-0.1, 0.1))
    env.reset(seed=0)
    goal = env.current_goal()
    lead = goal["frame"]
    near = lead <= 8
    assert near.any() and (~near).any()
    assert ((lead >= 1) & (near | ((lead >= 30) & (lead <= 60)))).all()
    history = env.history_world()[:, -1]
    start = history[torch.arange(64), goal["joint"]]
    dist = (goal["target"][:, :2] - start[:, :2]).norm(dim=-1)
    cap = (1.2 * lead.float() / FPS).clamp(max=3.0)
    assert (dist <= cap + 1e-4).all() and (dist[~near] >= 0.2 - 1e-4).all()  # near goals: a path's step
    feet = goal["planar"]
    assert set(goal["joint"][feet].tolist()) <= {JOINTS["left_foot"], JOINTS["right_foot"]}
    assert (goal["target"][feet, 2] == 0).all()
    dz = goal["target"][~feet, 2] - start[~feet, 2]
    assert (dz.abs() <= 0.1 + 1e-5).all()
    assert set(goal["joint"].tolist()) == {JOINTS[j] for j in ("pelvis", "left_foot", "right_hand")}
    # within 45 degrees of the body's forward axis (+y of the canonical frame of the last frame)
    from latentrl.envs.goal import body_forward

    forward, _ = body_forward(history)
    to = torch.nn.functional.normalize(goal["target"][:, :2] - start[:, :2], dim=-1)
    cos = (to * forward[:, :2]).sum(-1)
    assert (cos[~near] >= math.cos(math.radians(45)) - 1e-4).all()


def test_a_new_goal_follows_each_due_one_and_the_rewards_read_the_joint_error(tiny_model):
    env = make(tiny_model, 4, near_share=1.0, max_episode_steps=16)
    env.reset(seed=1)
    before = env.current_goal()
    _, reward, _, _, infos = env.step(actions(4, 0))
    assert infos["goal_due"].all()  # near goals fall within the first step
    after = env.current_goal()
    assert (after["frame"] > 8).all() and not torch.equal(after["target"], before["target"])
    err = infos["joint_error_m"]
    assert infos["reward/joint_arrival"] == pytest.approx(torch.exp(-err / 0.1), abs=1e-6)
    assert torch.isfinite(infos["reward/joint_dist"]).all()


def test_near_goals_run_along_a_path_that_keeps_up_its_velocity(tiny_model):
    env = make(tiny_model, 8, near_share=1.0, near_run=[4, 4], max_episode_steps=32)
    env.reset(seed=2)
    assert env._run_left.tolist() == [3] * 8  # the first of a run of 4 was drawn at the reset
    checked = 0
    for k in range(6):
        before = env.current_goal()
        left, velocity = env._run_left.clone(), env._run_vel.clone()
        _, _, _, _, infos = env.step(actions(8, k))
        assert infos["goal_due"].all()  # one near goal per step
        after = env.current_goal()
        gap, now = after["frame"] - before["frame"], 8 * (k + 1)
        assert ((after["frame"] > now) & (after["frame"] <= now + 8)).all()
        # a run goes on unless its goal was missed by more than 0.5 m; then (or after its last goal) a fresh one
        went_on = (left > 0) & (infos["joint_error_m"] <= 0.5)
        assert (env._run_left[went_on] == left[went_on] - 1).all() and (env._run_left[~went_on] == 3).all()
        assert (gap[went_on] <= 8).all() and (gap[went_on] >= 1).all()
        step = (after["target"] - before["target"])[went_on, :2]
        g = gap[went_on]
        # the path's step is at most max_speed x the gap, and its velocity changed by at most 1 m/s^2 x the gap
        assert (step.norm(dim=-1) <= 1.2 * g / FPS + 1e-5).all()
        assert ((step * FPS / g[:, None] - velocity[went_on]).norm(dim=-1) <= 1.0 * g / FPS + 1e-5).all()
        assert (after["target"][went_on, 2] == before["target"][went_on, 2]).all()
        checked += int(went_on.sum())
    assert checked >= 8


def test_a_run_of_near_goals_moves_as_its_velocity_model_says(tiny_model):
    env = make(tiny_model, 3, near_share=1.0, near_run=[2, 2], max_speed=1.2)
    env.reset(seed=0)
    idx = torch.arange(3)
    env._run_vel[:] = torch.tensor([[0.0, 0.0], [0.0, 0.0], [3.0, 0.0]])
    env._run_speed[:] = torch.tensor([1.2, 1.2, 0.0])
    env._run_heading[:] = torch.tensor([0.0, math.pi / 2, 0.0])
    env._run_turn[:] = 0.0
    # from rest toward 1.2 m/s along +x (+y): 1 m/s^2 for 1 s gives 1 m/s, then 0.2 m/s more within 0.5 s
    step = env._run_step(idx, torch.tensor([30, 30, 15]))
    assert step.flatten().tolist() == pytest.approx([1.0, 0.0, 0.0, 1.0, 0.6, 0.0], abs=1e-5)  # 2.5 m/s: cut to 1.2
    step = env._run_step(idx, torch.tensor([15, 15, 15]))
    assert step.flatten().tolist() == pytest.approx([0.6, 0.0, 0.0, 0.6, 0.35, 0.0], abs=1e-5)
    # a goal missed by more than 0.5 m ends the run: the next goal is a fresh one, drawn from the body
    env._run_left[:] = 1
    env._due[:] = True
    env._step_error[:] = torch.tensor([0.1, 0.6, 0.2])
    env._advance_task(torch.zeros(3, dtype=torch.bool))
    assert env._run_left.tolist() == [0, 1, 0]


def test_a_run_of_footsteps_alternates_feet_one_stride_apart_at_the_runs_cadence(tiny_model):
    env = make(tiny_model, 6, joints=("left_foot", "right_foot"), near_share=1.0, step_run=[8, 8],
               step_length=[0.5, 0.7], step_width=0.2, turn_deg_s=0.0, max_episode_steps=64)
    env.reset(seed=3)
    assert env._run_left.tolist() == [7] * 6
    first = env.current_goal()
    pelvis = env.history_world()[:, -1, 0, :2]
    forward = (first["target"][:, :2] - pelvis)
    assert (forward[:, 1] > 0).all()  # the first stone lies ahead (the episode starts facing +y)
    checked = 0
    for k in range(12):
        before, slot = env.current_goal(), env._joint[:, 0].clone()
        left, stride, speed = env._run_left.clone(), env._run_stride.clone(), env._run_speed.clone()
        _, _, _, _, infos = env.step(actions(6, k))
        after = env.current_goal()
        went_on = infos["goal_due"] & (left > 0) & (infos["joint_error_m"] <= 0.5)
        if not bool(went_on.any()):
            continue
        # the other foot, one stride on along a straight path, half the width to the other side
        assert (env._joint[went_on, 0] + slot[went_on] == 3).all()  # left_foot 1 <-> right_foot 2
        step = (after["target"] - before["target"])[went_on, :2]
        assert step.norm(dim=-1) == pytest.approx(torch.hypot(stride[went_on], torch.tensor(0.2)), abs=1e-4)
        gap = (after["frame"] - before["frame"])[went_on]
        stride_frames = torch.ceil(stride[went_on] / speed[went_on] * FPS).long()
        due = torch.maximum(stride_frames, 8 * (k + 1) - before["frame"][went_on] + 1)
        assert gap.tolist() == due.tolist()
        assert ((speed >= 0.6 - 1e-6) & (speed <= 1.2 + 1e-6)).all() and after["planar"].all()
        checked += int(went_on.sum())
    assert checked >= 6


def test_footsteps_take_single_goals_unless_step_run_asks_for_runs(tiny_model):
    env = make(tiny_model, 8, joints=("left_foot", "right_foot"), near_share=1.0, max_episode_steps=16)
    env.reset(seed=0)
    assert env._run_left.tolist() == [0] * 8 and (env._run_stride == 0).all()


def test_reward_terms_of_the_joint_error():
    from latentrl.rewards import terms

    assert terms.joint_progress(torch.tensor([1.0, 0.5]), torch.tensor([0.25, 0.75])).tolist() == [0.75, -0.25]
    out = terms.joint_arrival(torch.tensor([0.0, 0.1, math.nan]))
    assert out.tolist() == pytest.approx([1.0, math.exp(-1.0), 0.0])


def write(tmp_path, data):
    f = tmp_path / "goals.json"
    f.write_text(json.dumps(data))
    return f


GOOD = {"text": "walk", "goals": [{"joint": "pelvis", "target": [0, 2, 0.86], "time": 2.0}]}


@pytest.mark.parametrize("data,match", [
    ({"text": "walk"}, r"expected a non-empty list of entries"),
    ([{**GOOD, "goal": []}], r"entry 0: unknown field 'goal' \(did you mean 'goals'\?\)"),
    ([{"goals": GOOD["goals"]}], r"entry 0: missing field 'text'"),
    ([{**GOOD, "goals": []}], r"entry 0: field 'goals' must be a list of 1 to 1000 goals"),
    ([{**GOOD, "goals": [{"joint": "left_hnd", "target": [0, 1, 1], "time": 1}]}],
     r"entry 0, goal 0: field 'joint' must be one of .*did you mean 'left_hand'"),
    ([{**GOOD, "goals": [{"joint": "left_foot", "target": [0, 1, 0], "time": 1}]}],
     r"entry 0, goal 0: field 'target' must be \[x, y\] \(a foot's target is on the floor\)"),
    ([{**GOOD, "goals": [{"joint": "head", "target": [0, "a", 1], "time": 1}]}], r"field 'target' must be"),
    ([{**GOOD, "goals": [{"joint": "head", "target": [0, 1, 1], "time": "soon"}]}],
     r"entry 0, goal 0: field 'time' must be seconds in \(0, 3600\] or \"asap\", got 'soon'"),
    ([{**GOOD, "goals": [GOOD["goals"][0], {"joint": "head", "target": [0, 1, 1], "time": 1.5}]}],
     r"entry 0, goal 1: field 'time' must be after the previous timed goal \(2 s\), got 1.5"),
])
def test_joint_goal_file_errors_name_file_entry_goal_and_field(tmp_path, data, match):
    f = write(tmp_path, data)
    with pytest.raises(DataError, match=match) as err:
        load_joint_goals(f)
    assert str(err.value).startswith(str(f)) and "\n" not in str(err.value)


def test_joint_goal_file_loads_targets_times_and_asap(tmp_path):
    data = [{"text": "walk", "goals": [{"joint": "pelvis", "target": [0, 2, 0.86], "time": 2.0},
                                       {"joint": "right_foot", "target": [0.1, 2.5], "time": "asap"}]}]
    (entry,) = load_joint_goals(write(tmp_path, data))
    assert entry.goals[0] == JointGoal("pelvis", (0.0, 2.0, 0.86), 2.0) and not entry.goals[0].planar
    assert entry.goals[1].time is None and entry.goals[1].planar
    assert goal_frame(2.0) == 60 and goal_frame(0.001) == 1


@pytest.mark.parametrize("change,match", [
    ({"joints": ["pelvis", "left_hnd"]}, r"joints: unknown joint 'left_hnd' \(did you mean 'left_hand'\?\)"),
    ({"radius": 0}, r"radius: must be metres > 0, got 0"),
    ({"near_share": 1.5}, r"near_share: must be a share in \[0, 1\]"),
    ({"near_run": [4, 2]}, r"near_run: must be \[min, max\] goals with 1 <= min <= max <= 1000, got \[4, 2\]"),
    ({"near_run": [1.5, 2]}, r"near_run: must be \[min, max\] goals"),
    ({"step_run": [0, 4]}, r"step_run: must be \[min, max\] footsteps with 1 <= min <= max <= 1000, got \[0, 4\]"),
    ({"step_length": [0.7, 0.5]}, r"step_length: must be \[min, max\] metres with 0.05 <= min <= max <= 2"),
    ({"step_width": 1.5}, r"step_width: must be metres in \[0, 1\], got 1.5"),
    ({"turn_deg_s": -1.0}, r"turn_deg_s: must be degrees per second in \[0, 360\], got -1.0"),
    ({"far_time": [4.0, 1.0]}, r"far_time: must be \[min, max\]"),
    ({"distance": [-1.0, 2.0]}, r"distance: must be \[min, max\] with 0 <= min <= max"),
    ({"max_speed": 0}, r"max_speed: must be m/s > 0"),
])
def test_config_section_errors_are_one_line_naming_the_field(change, match):
    cfg = ReachJointConfig(**change)
    with pytest.raises(ConfigError, match=match) as err:
        cfg.validate()
    assert "\n" not in str(err.value)


def test_env_config_section_builds_the_env(tiny_model):
    from latentrl.config import from_dict
    from latentrl.envs.config import EnvConfig, build

    cfg = from_dict(EnvConfig, {"task": "reach_joint", "num_envs": 2,
                                "reach_joint": {"joints": ["left_hand", "head"], "radius": 0.05,
                                                "near_run": [2, 8], "turn_deg_s": 20.0, "step_run": [2, 6],
                                                "step_length": [0.4, 0.6], "step_width": 0.2}}, "env")
    cfg.validate()
    env = build(cfg, "cpu", motion=tiny_model)
    assert isinstance(env, ReachJointEnv) and env.joints == ("left_hand", "head") and env.radius == 0.05
    assert env.near_run == (2, 8) and env.turn == pytest.approx(math.radians(20.0))
    assert env.step_run == (2, 6) and env.step_length == (0.4, 0.6) and env.step_width == 0.2
    with pytest.raises(ConfigError, match=r"^env: reach_joint.far_time: must be \[min, max\]"):
        from_dict(EnvConfig, {"task": "reach_joint", "reach_joint": {"far_time": [2.0]}}, "env")


@pytest.mark.filterwarnings("ignore:.*(symmetric and normalized|infinity|unwrapped|precision):UserWarning")
def test_gymnasium_id_makes_a_single_env_and_a_vector_env(tiny_model):
    env = gym.make("latentrl/ReachJoint-v0", motion=tiny_model, joints=("pelvis", "right_foot"))
    check_env(env.unwrapped, skip_render_check=True)
    obs, _ = env.reset(seed=0)
    assert isinstance(obs, np.ndarray) and obs.shape == env.observation_space.shape
    obs, reward, terminated, truncated, info = env.step(env.action_space.sample())
    assert np.isfinite(reward) and isinstance(info["is_success"], bool)
    env.close()
    vec = gym.make_vec("latentrl/ReachJoint-v0", num_envs=3, motion=tiny_model)
    assert isinstance(vec, ReachJointEnv) and vec.num_envs == 3 and vec.max_episode_steps == 64


def test_planar_joints_get_floor_targets_and_a_planar_observation(tiny_model):
    env = make(tiny_model, 4, joints=("pelvis",), planar=("pelvis",))
    obs, _ = env.reset(seed=0)
    goal = env.current_goal()
    assert goal["planar"].all() and (goal["target"][:, 2] == 0).all()
    assert obs[:, slice(*env.observation_fields["planar"])].flatten().tolist() == [1.0] * 4
    assert obs[:, slice(*env.observation_fields["goal_vec"])][:, 2].abs().max() < 1e-6
    with pytest.raises(ConfigError, match=r"planar: unknown joint 'pelvs'"):
        ReachJointConfig(planar=["pelvs"]).validate()
