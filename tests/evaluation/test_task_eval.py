"""Joystick and TimedPath evaluations: metric kernels with known answers, runners and ``latentrl eval`` end to end."""

import json
import math

import numpy as np
import pytest
import torch

from latentrl.envs.joystick import STEP_SECONDS, CommandTimeline
from latentrl.envs.timed import TimedPath
from latentrl.evaluation import joystick, timed
from latentrl.evaluation.config import EvalSettings
from latentrl.evaluation.task_eval import build_task_report, write_task_report
from tests.helpers import rest_joints


def walked(velocities) -> torch.Tensor:
    """(2 + 8 S, 22, 3) a rest body whose pelvis moves at the given (S, 2) per-step velocities (m/s), feet lifted."""
    per_frame = torch.as_tensor(velocities, dtype=torch.float32).repeat_interleave(8, dim=0) / 30
    offsets = torch.cat((torch.zeros(2, 2), per_frame.cumsum(0)))
    joints = rest_joints()[None].repeat(len(offsets), 1, 1)
    joints[..., :2] += offsets[:, None]
    joints[..., 2] += 0.1 - joints[..., 2].min()
    return joints


def test_tracking_a_timeline_exactly_scores_zero_error_and_one_step_settles():
    # heading 0 (+y) at 1 m/s, then heading 90 (-x) at 1.5 m/s from step 4
    timeline = CommandTimeline("walk", ((0.0, 0.0, 1.0), (4 * STEP_SECONDS, 90.0, 1.5)), 12 * STEP_SECONDS)
    velocity = [[0.0, 1.0]] * 4 + [[-1.5, 0.0]] * 8
    joints = walked(velocity)
    torch.testing.assert_close(joystick.step_velocity(joints, 12), torch.tensor(velocity), atol=1e-5, rtol=0)
    criteria = joystick.TrackingCriteria(settle_window_s=1.0)
    metrics, detail = joystick.joystick_metrics(joints, timeline, 12, criteria)
    assert metrics["heading_err_deg"] == pytest.approx(0.0, abs=1e-3)
    assert metrics["speed_err_m_s"] == pytest.approx(0.0, abs=1e-4)
    assert metrics["settle_s"] == pytest.approx(STEP_SECONDS) and metrics["unsettled"] == 0.0
    assert detail["settle_s"] == [pytest.approx(STEP_SECONDS)]
    assert metrics["floor_cm"] == pytest.approx(10.0, abs=0.5)


def test_moving_90_degrees_off_and_too_slow_has_the_expected_errors_and_never_settles():
    timeline = CommandTimeline("walk", ((0.0, 0.0, 1.0), (2 * STEP_SECONDS, 0.0, 1.2)), 10 * STEP_SECONDS)
    joints = walked([[0.7, 0.0]] * 10)  # +x is heading -90: 90 degrees to the right of the command, 0.3-0.5 m/s slow
    metrics, _ = joystick.joystick_metrics(joints, timeline, 10, joystick.TrackingCriteria(settle_window_s=0.0))
    assert metrics["heading_err_deg"] == pytest.approx(90.0, abs=1e-3)
    assert metrics["speed_err_m_s"] == pytest.approx((2 * 0.3 + 8 * 0.5) / 10, abs=1e-4)
    assert metrics["settle_s"] is None and metrics["unsettled"] == 1.0


def test_settle_times_per_command():
    ok = torch.tensor([False, True, False, False, False, True, True])
    assert joystick.settle_times(ok, [0, 3, 6], 0.5) == [1.0, 1.5, 0.5]
    assert joystick.settle_times(ok, [2, 4], 1.0) == [None, 2.0]


def test_timed_metrics_success_needs_every_waypoint_on_time():
    joints = walked([[0.0, 1.0]] * 2)
    on_time = timed.timed_metrics([0.5, -0.9], 1.0, joints)
    assert on_time["success"] == 1.0 and on_time["arrival_err_s"] == pytest.approx(0.7)
    assert on_time["late_s"] == pytest.approx(-0.2) and on_time["reached"] == 1.0
    assert timed.timed_metrics([0.5, 1.5], 1.0, joints)["success"] == 0.0
    missed = timed.timed_metrics([0.2, None], 1.0, joints)
    assert missed["success"] == 0.0 and missed["reached"] == 0.5 and missed["arrival_err_s"] == pytest.approx(0.2)


def zero_policy(obs: torch.Tensor) -> torch.Tensor:
    return torch.zeros(obs.shape[0], 16)


def test_joystick_and_timed_runners_produce_every_metric_and_a_report(tiny_model, tmp_path):
    settings = EvalSettings(episodes=2, max_steps=20)
    tl = tmp_path / "mini_joy.json"
    tl.write_text(json.dumps([{"text": "walk", "duration": 1.5, "commands": [
        {"t": 0, "heading_deg": 0, "speed": 1.0}, {"t": 0.5, "heading_deg": 45, "speed": 1.2}]}]))
    suites = joystick.run_suites(zero_policy, tiny_model, [tl], settings,
                                 criteria=joystick.TrackingCriteria(settle_window_s=0.5))
    (name, _, results), = suites
    assert name == "mini_joy" and len(results[0].episodes) == 2
    ep = results[0].episodes[0]
    assert ep.end == "complete" and ep.steps == math.ceil(1.5 / STEP_SECONDS)
    assert set(ep.metrics) == set(joystick.UNITS) and np.isfinite(ep.metrics["heading_err_deg"])
    report = build_task_report("joystick", suites, settings, joystick.UNITS, joystick.DEFINITIONS)
    js, md = write_task_report(tmp_path / "out", report)
    data = json.loads(js.read_text())
    assert data["format"] == "latentrl.eval.task/1" and data["overall"]["heading_err_deg"]["n"] == 2
    assert "| mini_joy | 0: walk, 2 commands, 1.5 s |" in md.read_text()

    path = TimedPath(((0.0, 0.0, 0.0), (0.0, 30.0, 0.0)), ("walk", "walk"), (0.2, 1.0))  # the first at the start
    result = timed.run_path(zero_policy, tiny_model, path, settings,
                            criteria=timed.TimingCriteria(late_limit_s=0.5))
    ep = result.episodes[0]
    assert ep.end == "timeout" and ep.steps == math.ceil(1.5 / STEP_SECONDS)
    first, second = ep.detail["arrival_err_s"]
    assert first == pytest.approx(1 / 30 - 0.2) and second is None  # reached at the first new frame, 0.17 s early
    assert ep.metrics["success"] == 0.0 and ep.metrics["reached"] == 0.5


@pytest.fixture(scope="module")
def task_policies(eval_files, tiny_model, tmp_path_factory):
    """Fresh policies whose checkpoints store a joystick and a timed env config."""
    from latentrl.envs.joystick import JoystickEnv
    from latentrl.envs.timed import TimedPathEnv
    from latentrl.motion.checkpoint import file_sha256
    from latentrl.ppo.checkpoint import make_checkpoint, save_checkpoint
    from latentrl.ppo.config import PolicyConfig
    from latentrl.ppo.policy import ActorCritic

    root, out = tmp_path_factory.mktemp("task_policies"), {}
    motion = eval_files["motion"]
    for task, env in (("joystick", JoystickEnv(1, motion=tiny_model)), ("timed", TimedPathEnv(1, motion=tiny_model))):
        torch.manual_seed(0)
        policy = ActorCritic(env.single_observation_space.shape[0], env.single_action_space.shape[0],
                             PolicyConfig(latent_dim=32), env.metadata["observation_layout"])
        state = make_checkpoint(trainer="native", iteration=0, env_steps=0, elapsed_s=0.0, policy=policy,
                                optimizer=torch.optim.Adam(policy.parameters()),
                                config={"env": {"task": task, "texts": ["walk"]}},
                                motion={"path": str(motion), "sha256": file_sha256(motion)})
        out[task] = save_checkpoint(state, root / f"{task}.pt")
    return out


@pytest.mark.parametrize("task,suite", [("joystick", "joystick"), ("timed", "timed")])
def test_latentrl_eval_picks_the_evaluator_from_the_stored_env_config(task_policies, eval_files, tmp_path, task,
                                                                       suite, capsys):
    from latentrl.app.cli import main

    suite_file = tmp_path / f"{suite}_mini.json"
    if task == "joystick":
        suite_file.write_text(json.dumps([{"text": "walk", "duration": 0.8,
                                           "commands": [{"t": 0, "heading_deg": 0, "speed": 1.0}]}]))
    else:
        suite_file.write_text(json.dumps([{"goal_location": [[0, 0, 0]], "goal_text": ["walk"], "goal_time": [0.5]}]))
    out = tmp_path / "out"
    code = main(["eval", str(task_policies[task]), "--motion", str(eval_files["motion"]), "--paths", str(suite_file),
                 "--episodes", "2", "--device", "cpu", "--out", str(out), "--render", "0"])
    assert code == 0
    report = json.loads((out / "report.json").read_text())
    assert report["task"] == task and report["suites"][0]["name"] == f"{suite}_mini"
    assert sorted(p.name for p in (out / "motions").glob("*.npz")) == [f"{suite}_mini_0_ep000.npz",
                                                                       f"{suite}_mini_0_ep001.npz"]
    if task == "timed":
        assert report["overall"]["success"]["mean"] == 1.0  # the only waypoint is at the start: reached 0.47 s early
    assert "wrote" in capsys.readouterr().out


@pytest.mark.parametrize("task", ["joystick", "timed"])
def test_latentrl_eval_scene_puts_joystick_and_timed_episodes_among_objects(task_policies, eval_files, tmp_path, task):
    """A box around the start pose: every episode collides, and its motions carry the scene; a box far away changes
    no metric of the blind policy; a flat report has no scene metrics."""
    from latentrl.app.cli import main
    from latentrl.render import load_motion_npz
    from latentrl.scenes import scene_from_json

    suite = tmp_path / f"{task}_mini.json"
    timeline = [{"text": "walk", "duration": 0.8, "commands": [{"t": 0, "heading_deg": 0, "speed": 1.0}]}]
    timed_path = [{"goal_location": [[0, 1, 0]], "goal_text": ["walk"], "goal_time": [0.5]}]
    suite.write_text(json.dumps(timeline if task == "joystick" else timed_path))
    crate, far = tmp_path / "crate.json", tmp_path / "far.json"
    crate.write_text(json.dumps({"format": "latentrl.scene/1", "objects": [
        {"type": "box", "center": [0.0, 0.0], "size": [1.5, 1.5, 2.5]}]}))
    far.write_text(json.dumps({"format": "latentrl.scene/1", "objects": [
        {"type": "box", "center": [8.0, 8.0], "size": [0.5, 0.5, 1.0]}]}))
    args = ["eval", str(task_policies[task]), "--motion", str(eval_files["motion"]), "--paths", str(suite),
            "--episodes", "2", "--device", "cpu", "--render", "0", "--deterministic"]
    for name, extra in (("flat", []), ("boxed", ["--scene", str(crate)]), ("far", ["--scene", str(far)])):
        assert main([*args, "--out", str(tmp_path / name), *extra]) == 0
    flat, boxed, away = (json.loads((tmp_path / d / "report.json").read_text()) for d in ("flat", "boxed", "far"))
    assert "collision" not in flat["overall"] and "collision" not in flat["units"]
    assert boxed["overall"]["collision"]["mean"] == 1.0 and boxed["units"]["scene_penetration_max_cm"] == "cm"
    assert boxed["overall"]["scene_penetration_max_cm"]["mean"] > 10
    episode = boxed["suites"][0]["entries"][0]["episodes"][0]
    clip = load_motion_npz(tmp_path / "boxed" / episode["motion_file"])
    assert scene_from_json(str(clip["scene"])).objects[0].size[2] == 2.5
    assert away["overall"]["collision"]["mean"] == 0.0
    for key, value in flat["overall"].items():
        assert away["overall"][key]["mean"] == pytest.approx(value["mean"], abs=1e-6, nan_ok=True), key
    # the scene filter leaves a plan clear of every object alone, and the report says it ran
    assert main([*args, "--out", str(tmp_path / "filtered"), "--scene", str(far), "--avoid", "2",
                 "--avoid-horizon", "1"]) == 0
    filtered = json.loads((tmp_path / "filtered" / "report.json").read_text())
    assert filtered["avoid"]["steps"] == 2 and "avoid" not in away
    assert filtered["overall"] == away["overall"]


def test_random_obstacles_for_a_joystick_policy_is_a_one_line_error(task_policies, eval_files, tmp_path, capsys):
    from latentrl.app.cli import main

    code = main(["eval", str(task_policies["joystick"]), "--motion", str(eval_files["motion"]), "--scene",
                 "random_obstacles", "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "--scene: a joystick policy takes a scene file or name" in err
    assert not (tmp_path / "x").exists()


def test_shipped_task_suites_resolve_by_name():
    from latentrl.app.evaluate import resolve_path_files

    assert [p.name for p in resolve_path_files(["joystick_walk"], "joystick")] == ["joystick_walk.json"]
    assert [p.name for p in resolve_path_files(None, "timed", ("timed_walk",))] == ["timed_walk.json"]


def test_training_runs_the_task_evaluator_periodically(tiny_model, tmp_path):
    from latentrl.app.train import TrainConfig, make_eval_hook
    from latentrl.envs.config import build
    from latentrl.ppo.config import PolicyConfig
    from latentrl.ppo.policy import ActorCritic

    timeline = tmp_path / "hook.json"
    timeline.write_text(json.dumps([{"text": "walk", "duration": 3.0,  # past the 2 s settle window
                                     "commands": [{"t": 0, "heading_deg": 0, "speed": 1.0}]}]))
    cfg = TrainConfig()
    cfg.env.task, cfg.env.num_envs = "joystick", 1
    cfg.ppo.eval_every, cfg.eval.paths, cfg.eval.episodes = 1, [str(timeline)], 1
    env = build(cfg.env, "cpu", motion=tiny_model)
    policy = ActorCritic(env.single_observation_space.shape[0], 16, PolicyConfig(latent_dim=32),
                         env.metadata["observation_layout"])
    report = make_eval_hook(cfg, tiny_model, "cpu")(policy)
    assert {"heading_err_deg", "speed_err_m_s", "skate_cm_s", "floor_cm"} <= set(report.metrics)
    assert not report.stop


def test_latentrl_eval_route_guides_a_timed_policy_around_a_wall_and_leaves_a_clear_way_alone(
        task_policies, eval_files, tmp_path):
    """``--route`` on a timed policy: a box far away changes no metric (the policy sees its waypoint); a wall
    between the start and the waypoint turns the goal it sees, so the episode differs; a joystick has no goal."""
    from latentrl.app.cli import main

    suite = tmp_path / "timed_mini.json"
    suite.write_text(json.dumps([{"goal_location": [[0, 3, 0]], "goal_text": ["walk"], "goal_time": [2.0]}]))
    wall, far = tmp_path / "wall.json", tmp_path / "far.json"
    wall.write_text(json.dumps({"format": "latentrl.scene/1", "objects": [
        {"type": "box", "center": [0.3, 1.5], "size": [1.6, 0.3, 1.5]}]}))
    far.write_text(json.dumps({"format": "latentrl.scene/1", "objects": [
        {"type": "box", "center": [8.0, 8.0], "size": [0.5, 0.5, 1.0]}]}))
    args = ["eval", str(task_policies["timed"]), "--motion", str(eval_files["motion"]), "--paths", str(suite),
            "--episodes", "1", "--max-steps", "4", "--device", "cpu", "--render", "0", "--deterministic"]
    runs = {"far": ["--scene", str(far)], "far_route": ["--scene", str(far), "--route", "0.5"],
            "wall": ["--scene", str(wall)], "wall_route": ["--scene", str(wall), "--route", "0.5"]}
    for name, extra in runs.items():
        assert main([*args, "--out", str(tmp_path / name), *extra]) == 0
    reports = {name: json.loads((tmp_path / name / "report.json").read_text()) for name in runs}
    assert reports["far_route"]["settings"]["route"] == 0.5 and reports["far"]["settings"]["route"] is None
    assert reports["far_route"]["overall"] == reports["far"]["overall"]
    assert reports["wall_route"]["overall"] != reports["wall"]["overall"]
