"""ReachJoint evaluation: the error at the goal time and the footstep at touchdown on hand-made joints, the shipped
suites, the runner's report and paths.png, ``latentrl eval`` of a ReachJoint policy and the training hook."""

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from latentrl.envs.reach_joint import JOINTS, JointGoal, JointGoalEntry, load_joint_goals
from latentrl.envs.tasks import task_spec
from latentrl.evaluation import joint_goals as J
from latentrl.evaluation.config import EvalSettings
from latentrl.resources import suites_folder


def still_body(frames: int) -> np.ndarray:
    """(T, 22, 3): every joint at the origin 1 m up, feet on the floor."""
    j = np.zeros((frames, 22, 3), np.float32)
    j[:, :, 2] = 1.0
    j[:, [JOINTS["left_foot"], JOINTS["right_foot"]], 2] = 0.0
    return j


def test_errors_at_the_goal_time_split_near_and_far():
    j = still_body(2 + 60)
    j[:, JOINTS["pelvis"], 1] = np.arange(len(j)) * 0.01  # the pelvis walks +y at 0.3 m/s: 1 cm a frame
    entry = JointGoalEntry("walk", (JointGoal("pelvis", (0.0, 0.31), 1.0),  # frame 30 (clip 31): y = 0.31
                                    JointGoal("pelvis", (0.0, 0.40, 1.0), 1.2),  # frame 36, 6 after: near
                                    JointGoal("pelvis", (0.0, 0.10), 2.0)))  # frame 60: 0.5 m off, far
    metrics, detail = J.goal_metrics(j, entry, [30, 36, 60], J.JointGoalCriteria(radius_m=0.1))
    assert detail["error_cm"] == pytest.approx([0.0, 3.0, 51.0], abs=1e-4)
    assert metrics["err_near_cm"] == pytest.approx(3.0, abs=1e-4)
    assert metrics["err_far_cm"] == pytest.approx(25.5, abs=1e-4)  # (0 + 51) / 2
    assert metrics["reached"] == pytest.approx(2 / 3) and metrics["success"] == 0.0
    assert metrics["footstep_err_cm"] is None and metrics["steps_reached"] is None
    # a goal that never became due counts as missed
    missed, _ = J.goal_metrics(j, entry, [30, 36, -1], J.JointGoalCriteria(radius_m=1.0))
    assert missed["success"] == 0.0 and missed["reached"] == pytest.approx(2 / 3)


def test_footstep_error_is_measured_at_the_touchdown_nearest_the_goal_time():
    j = still_body(2 + 40)
    right = JOINTS["right_foot"]
    j[:, right, 2] = 0.1  # swinging ...
    j[2 + 20:, right, 2] = 0.0  # ... until it lands at frame 20 (clip 22), 5 frames before its goal time
    j[2 + 20:, right, :2] = [0.05, 0.5]
    j[:2 + 20, right, :2] = [0.0, 0.0]
    left = JOINTS["left_foot"]
    j[:, left, 2] = 0.0  # planted all along: no touchdown
    entry = JointGoalEntry("walk", (JointGoal("right_foot", (0.0, 0.5), 25 / 30),
                                    JointGoal("left_foot", (0.0, 0.0), 35 / 30)))
    metrics, detail = J.goal_metrics(j, entry, [25, 35], J.JointGoalCriteria(radius_m=0.1))
    assert detail["touchdown_err_cm"][0] == pytest.approx(5.0, abs=1e-4) and detail["touchdown_err_cm"][1] is None
    assert metrics["steps_reached"] == 0.5 and metrics["success"] == 0.0
    # the missed step counts its goal-time error: the left foot sits on its target
    assert metrics["footstep_err_cm"] == pytest.approx((5.0 + 0.0) / 2, abs=1e-4)
    assert J.touchdown(j[:, right, 2], 27, 0, 41, 0.03) == 22
    assert J.touchdown(j[:, right, 2], 27, 22, 41, 0.03) is None  # the window starts after the landing


def test_a_footstep_onto_a_box_top_touches_down_on_the_box():
    """On a scene the touchdown is the contact onset over the ground under the foot; the flat floor sees none."""
    from latentrl.scenes import Box, Scene, SceneBatch

    j = still_body(2 + 40)
    right = JOINTS["right_foot"]
    j[:, right, 2] = 0.45  # swinging over the box ...
    j[2 + 20:, right, 2] = 0.3  # ... until it lands on its 0.3 m top at frame 20 (clip 22)
    j[:, right, :2] = [0.0, 0.5]
    entry = JointGoalEntry("walk", (JointGoal("right_foot", (0.0, 0.5), 25 / 30),))
    box = SceneBatch.from_scenes([Scene((Box((0.0, 0.5), (0.4, 0.4, 0.3)),))])
    flat, flat_detail = J.goal_metrics(j, entry, [25], J.JointGoalCriteria(radius_m=0.1))
    assert flat_detail["touchdown_err_cm"] == [None] and flat["steps_reached"] == 0.0
    on_box, detail = J.goal_metrics(j, entry, [25], J.JointGoalCriteria(radius_m=0.1), terrain=box)
    assert detail["touchdown_err_cm"] == [pytest.approx(0.0, abs=1e-4)] and on_box["success"] == 1.0
    # A box elsewhere: the foot at 0.3 m hovers over the floor, as on the flat floor.
    far = SceneBatch.from_scenes([Scene((Box((9.0, 9.0), (0.4, 0.4, 0.3)),))])
    _, far_detail = J.goal_metrics(j, entry, [25], J.JointGoalCriteria(radius_m=0.1), terrain=far)
    assert far_detail["touchdown_err_cm"] == [None]


def test_shipped_suites_load_and_the_spec_has_the_evaluator():
    import latentrl.evaluation.tasks  # noqa: F401  (attaches the evaluators)

    spec = task_spec("reach_joint")
    assert spec.suite_kind == "joint_goals" and spec.evaluator.suite_kind == "joint_goals"
    for name in ("pelvis_near", "pelvis_far", "stepping_stones", "hands_walk"):
        entries = load_joint_goals(suites_folder("joint_goals") / f"{name}.json")
        assert entries and all(e.text == "walk" for e in entries)
    hands = load_joint_goals(suites_folder("joint_goals") / "hands_walk.json")
    assert {g.joint for e in hands for g in e.goals} == {"left_hand", "right_hand", "head"}
    assert not any(g.planar for e in hands for g in e.goals)  # 3-D points
    near = load_joint_goals(suites_folder("joint_goals") / "pelvis_near.json")
    for entry in near:  # every goal within one step of the previous
        times = [0.0, *(g.time for g in entry.goals)]
        assert max(np.diff(times)) <= 8 / 30 + 1e-9
    stones = load_joint_goals(suites_folder("joint_goals") / "stepping_stones.json")
    for entry in stones:
        feet = [g.joint for g in entry.goals]
        assert all(a != b for a, b in zip(feet, feet[1:])) and all(g.planar for g in entry.goals)
    assert any(g.time is None for g in stones[1].goals)


def zero_policy(obs: torch.Tensor) -> torch.Tensor:
    return torch.zeros(obs.shape[0], 16)


def test_runner_scores_each_goal_and_writes_the_report_and_png(tiny_model, tmp_path):
    import latentrl.evaluation.tasks as T

    entry = JointGoalEntry("walk", (JointGoal("pelvis", (0.0, 0.2), 0.3), JointGoal("left_foot", (0.0, 0.5), None)))
    suite = tmp_path / "mini_goals.json"
    suite.write_text(json.dumps([{"text": "walk", "goals": [{"joint": "pelvis", "target": [0.0, 0.2], "time": 0.3},
                                                            {"joint": "left_foot", "target": [0.0, 0.5],
                                                             "time": "asap"}]}]))
    settings = EvalSettings(episodes=2, max_steps=20)
    run = T.JOINT_GOALS.run(zero_policy, tiny_model, [suite], settings, observe_next=False)
    (name, _, (result,)), = run.suites
    assert name == "mini_goals" and result.entry == entry and len(result.episodes) == 2
    ep = result.episodes[0]
    assert set(ep.metrics) == set(J.UNITS) and ep.end in ("complete", "lost")
    assert ep.detail["frame"][0] == 9 and ep.detail["frame"][1] > 9  # the asap goal got its time when current
    f0, f1 = ep.detail["frame"]
    far = [ep.detail["error_cm"][0]] + ([ep.detail["error_cm"][1]] if f1 - f0 > 8 else [])  # 9 frames: far
    assert ep.metrics["err_far_cm"] == pytest.approx(np.mean(far))
    lines = T.JOINT_GOALS.report(run, settings, tmp_path / "out", policy="p", motion="m", hardware="h")
    data = json.loads((tmp_path / "out" / "report.json").read_text())
    assert data["task"] == "reach_joint" and data["overall"]["reached"]["n"] == 2
    assert (tmp_path / "out" / "paths.png").stat().st_size > 1000 and "paths.png" in lines[-1]
    assert any(line.startswith("| mini_goals | 0: walk, 2 goals (pelvis, left_foot), asap goals |") for line in lines)
    # the motions carry the targets and their joints, for the viewer's markers
    T.JOINT_GOALS.run(zero_policy, tiny_model, [suite], settings, observe_next=False, out_dir=tmp_path / "m",
                      motions=True)
    from latentrl.motion.clip import MotionClip

    clip = MotionClip.load(next((tmp_path / "m").rglob("*.npz")))
    assert clip.waypoints.tolist() == [pytest.approx([0.0, 0.2, 0.0]), pytest.approx([0.0, 0.5, 0.0])]
    assert np.asarray(clip.meta["waypoint_joints"]).tolist() == [0, 10]  # pelvis, left foot (SMPL)


def test_paths_png_of_joint_goals_draws_each_episodes_scene(tiny_model, tmp_path):
    """Random obstacles differ per episode: each result keeps its episodes' scenes, and the figure draws every
    object of each distinct scene as a footprint (the path evaluation's drawing)."""
    import matplotlib.pyplot as plt

    from latentrl.evaluation.plots import draw_scenes
    from latentrl.scenes import scene_from_json

    entry = JointGoalEntry("walk", (JointGoal("pelvis", (0.0, 2.0), 1.0),))
    settings = EvalSettings(episodes=3, max_steps=8)
    settings.scene, settings.observe_scene = {"random_obstacles": {"count": [3, 3]}}, False
    result = J.run_entry(zero_policy, tiny_model, entry, settings)
    assert len(result.scenes) == 3 and len(set(result.scenes)) == 3  # each episode its own obstacles
    objects = sum(len(scene_from_json(text).objects) for text in result.scenes)
    fig = J.goals_figure([("s", "f", [result])])
    assert len(fig.axes[0].patches) == objects
    plt.close(fig)
    fig, ax = plt.subplots()
    draw_scenes(ax, [*result.scenes, result.scenes[0], None])  # a repeat and a flat episode add nothing
    assert len(ax.patches) == objects
    plt.close(fig)
    assert J.save_png(tmp_path / "paths.png", [("s", "f", [result])]).stat().st_size > 1000


def test_env_errors_match_the_offline_metric(tiny_model):
    entry = JointGoalEntry("walk", (JointGoal("pelvis", (0.1, 0.3, 0.9), 0.5),
                                    JointGoal("right_hand", (0.2, 0.6, 1.0), 1.0)))
    settings = EvalSettings(episodes=2, max_steps=12)
    result = J.run_entry(zero_policy, tiny_model, entry, settings)
    env = J.make_env(tiny_model, entry, 2, settings)
    from latentrl.evaluation.episodes import rollout

    rollout(env, zero_policy, 6, 0)
    record, _ = env.goal_record()
    assert result.episodes[0].detail["error_cm"] == pytest.approx((record[0] * 100).tolist(), abs=1e-3)


def reach_joint_policy(eval_files, tiny_model, tmp_path, eval_section: dict | None = None) -> Path:
    """An untrained ReachJoint policy on the tiny model, saved as a checkpoint (with an ``eval:`` section)."""
    from latentrl.envs.reach_joint import ReachJointEnv
    from latentrl.motion.checkpoint import file_sha256
    from latentrl.ppo.checkpoint import make_checkpoint, save_checkpoint
    from latentrl.ppo.config import PolicyConfig
    from latentrl.ppo.policy import ActorCritic

    env = ReachJointEnv(1, motion=tiny_model)
    torch.manual_seed(0)
    policy = ActorCritic(env.single_observation_space.shape[0], env.single_action_space.shape[0],
                         PolicyConfig(latent_dim=32), env.metadata["observation_layout"])
    motion = eval_files["motion"]
    state = make_checkpoint(trainer="native", iteration=0, env_steps=0, elapsed_s=0.0, policy=policy,
                            optimizer=torch.optim.Adam(policy.parameters()),
                            config={"env": {"task": "reach_joint", "texts": ["walk"]},
                                    **({"eval": eval_section} if eval_section else {})},
                            motion={"path": str(motion), "sha256": file_sha256(motion)})
    return save_checkpoint(state, tmp_path / "reach_joint.pt")


def test_latentrl_eval_runs_a_reach_joint_policy(eval_files, tiny_model, tmp_path, capsys):
    from latentrl.app.cli import main

    ckpt = reach_joint_policy(eval_files, tiny_model, tmp_path)
    motion = eval_files["motion"]
    suite = tmp_path / "goals_mini.json"
    suite.write_text(json.dumps([{"text": "walk", "goals": [{"joint": "pelvis", "target": [0, 0.3], "time": 0.5}]}]))
    out = tmp_path / "out"
    code = main(["eval", str(ckpt), "--motion", str(motion), "--paths", str(suite), "--episodes", "2",
                 "--device", "cpu", "--out", str(out), "--render", "0"])
    assert code == 0
    report = json.loads((out / "report.json").read_text())
    assert report["task"] == "reach_joint" and report["suites"][0]["name"] == "goals_mini"
    assert report["overall"]["err_far_cm"]["n"] == 2 and (out / "paths.png").is_file()
    assert "wrote" in capsys.readouterr().out


def test_latentrl_eval_scene_puts_joint_goals_among_objects_and_reports_collisions(eval_files, tiny_model, tmp_path):
    """A box around the start pose: every episode collides, and the motions carry the scene; a box far away changes
    no metric; without --scene the report has no scene metrics."""
    from latentrl.app.cli import main
    from latentrl.render import load_motion_npz
    from latentrl.scenes import scene_from_json

    ckpt = reach_joint_policy(eval_files, tiny_model, tmp_path)
    suite = tmp_path / "goals_mini.json"
    suite.write_text(json.dumps([{"text": "walk", "goals": [{"joint": "pelvis", "target": [0, 0.3], "time": 0.5}]}]))
    scene = tmp_path / "crate.json"
    scene.write_text(json.dumps({"format": "latentrl.scene/1", "objects": [
        {"type": "box", "center": [0.0, 0.0], "size": [1.5, 1.5, 2.5]}]}))
    args = ["eval", str(ckpt), "--motion", str(eval_files["motion"]), "--paths", str(suite), "--episodes", "2",
            "--device", "cpu", "--render", "0", "--deterministic"]
    assert main([*args, "--out", str(tmp_path / "flat")]) == 0
    assert main([*args, "--out", str(tmp_path / "boxed"), "--scene", str(scene)]) == 0
    flat, boxed = (json.loads((tmp_path / d / "report.json").read_text()) for d in ("flat", "boxed"))
    assert "collision" not in flat["overall"] and "collision" not in flat["units"]
    assert boxed["overall"]["collision"]["mean"] == 1.0 and boxed["units"]["collision"] == "share"
    assert boxed["overall"]["scene_penetration_max_cm"]["mean"] > 10
    episode = boxed["suites"][0]["entries"][0]["episodes"][0]
    clip = load_motion_npz(tmp_path / "boxed" / episode["motion_file"])
    assert scene_from_json(str(clip["scene"])).objects[0].size[2] == 2.5
    # the policy was trained without a scene and does not observe it: a box far away changes nothing but the report
    far = tmp_path / "far.json"
    far.write_text(json.dumps({"format": "latentrl.scene/1", "objects": [
        {"type": "box", "center": [8.0, 8.0], "size": [0.5, 0.5, 1.0]}]}))
    assert main([*args, "--out", str(tmp_path / "far"), "--scene", str(far)]) == 0
    away = json.loads((tmp_path / "far" / "report.json").read_text())
    assert away["overall"]["collision"]["mean"] == 0.0
    for key in ("err_far_cm", "skate_cm_s", "floor_cm"):
        assert away["overall"][key]["mean"] == pytest.approx(flat["overall"][key]["mean"], abs=1e-6)
    # refined, then filtered: the filter leaves the refiner's clear plan alone, and the report records both
    both = [*args, "--scene", str(far), "--refine", "2", "--refine-horizon", "1"]
    assert main([*both, "--out", str(tmp_path / "refined")]) == 0
    assert main([*both, "--out", str(tmp_path / "filtered"), "--avoid", "2", "--avoid-horizon", "1"]) == 0
    refined, filtered = (json.loads((tmp_path / d / "report.json").read_text()) for d in ("refined", "filtered"))
    assert filtered["avoid"]["steps"] == 2 and filtered["refine"] == refined["refine"]
    assert filtered["overall"] == refined["overall"]


def test_training_runs_the_joint_goal_evaluator_periodically(tiny_model, tmp_path):
    from latentrl.app.train import TrainConfig, make_eval_hook
    from latentrl.envs.config import build
    from latentrl.ppo.config import PolicyConfig
    from latentrl.ppo.policy import ActorCritic

    suite = tmp_path / "hook.json"
    suite.write_text(json.dumps([{"text": "walk", "goals": [{"joint": "pelvis", "target": [0, 0.3], "time": 0.5}]}]))
    cfg = TrainConfig()
    cfg.env.task, cfg.env.num_envs = "reach_joint", 1
    cfg.ppo.eval_every, cfg.eval.paths, cfg.eval.episodes = 1, [str(suite)], 1
    env = build(cfg.env, "cpu", motion=tiny_model)
    policy = ActorCritic(env.single_observation_space.shape[0], 16, PolicyConfig(latent_dim=32),
                         env.metadata["observation_layout"])
    report = make_eval_hook(cfg, tiny_model, "cpu")(policy)
    assert {"err_far_cm", "reached", "skate_cm_s"} <= set(report.metrics)


def test_latentrl_list_shows_the_task_and_its_suites(capsys):
    from latentrl.app.cli import main

    assert main(["list", "suites"]) == 0
    line = next(ln for ln in capsys.readouterr().out.splitlines() if ln.split()[:1] == ["joint_goals"])
    assert "reach_joint" in line
    assert "pelvis_far, pelvis_near, stepping_stones" in line


def test_latentrl_eval_refine_runs_the_refiner_and_records_its_settings(eval_files, tiny_model, tmp_path, capsys):
    from latentrl.app.cli import main

    ckpt = reach_joint_policy(eval_files, tiny_model, tmp_path)
    suite = tmp_path / "goals_mini.json"
    suite.write_text(json.dumps([{"text": "walk", "goals": [{"joint": "pelvis", "target": [0, 0.3], "time": 0.2}]}]))
    args = ["eval", str(ckpt), "--motion", str(eval_files["motion"]), "--paths", str(suite), "--episodes", "2",
            "--device", "cpu", "--render", "0", "--deterministic"]
    for refine, out in ((0, tmp_path / "plain"), (3, tmp_path / "refined")):
        assert main([*args, "--out", str(out), "--refine", str(refine), "--refine-horizon", "1"]) == 0
    plain, refined = (json.loads((tmp_path / d / "report.json").read_text()) for d in ("plain", "refined"))
    assert "refine" not in plain
    assert refined["refine"] == {"steps": 3, "start": "policy", "horizon": 1, "lr": 0.1, "pace": 0.5,
                                  "prior": 0.1, "land": 0, "skate": 0.0, "policy_joints": ["pelvis"]}
    errors = [r["suites"][0]["entries"][0]["episodes"][0]["detail"]["error_cm"][0] for r in (plain, refined)]
    assert errors[1] < errors[0]  # the refiner moved the noise toward the goal
    capsys.readouterr()
    assert main([*args, "--out", str(tmp_path / "bad"), "--refine", "1", "--refine-horizon", "0"]) == 2
    assert "--refine-horizon: expected 1-16 primitives, got 0" in capsys.readouterr().err


def test_a_policy_stores_its_refinement_and_the_flags_override_it(eval_files, tiny_model, tmp_path, capsys):
    from latentrl.app.cli import main

    ckpt = reach_joint_policy(eval_files, tiny_model, tmp_path, {"refine": 2, "refine_horizon": 1,
                                                                 "refine_start": "zeros", "refine_skate": 0.5,
                                                                 "refine_pace": 2.0, "refine_land": 6})
    suite = tmp_path / "goals_mini.json"
    suite.write_text(json.dumps([{"text": "walk", "goals": [{"joint": "pelvis", "target": [0, 0.3], "time": 0.2}]}]))
    args = ["eval", str(ckpt), "--motion", str(eval_files["motion"]), "--paths", str(suite), "--episodes", "1",
            "--device", "cpu", "--render", "0"]
    assert main([*args, "--out", str(tmp_path / "stored")]) == 0
    out = capsys.readouterr().out
    assert "--refine 2 (the policy's stored evaluation setting; --refine overrides)" in out
    assert "--refine-start zeros (the policy's stored evaluation setting; --refine-start overrides)" in out
    stored = json.loads((tmp_path / "stored" / "report.json").read_text())["refine"]
    assert stored["horizon"] == 1 and stored["start"] == "zeros" and stored["skate"] == 0.5 and stored["pace"] == 2.0
    assert stored["land"] == 6
    assert main([*args, "--out", str(tmp_path / "flag"), "--refine-start", "policy", "--refine-skate", "0",
                 "--refine-pace", "0", "--refine-land", "0"]) == 0
    flagged = json.loads((tmp_path / "flag" / "report.json").read_text())["refine"]
    assert flagged["start"] == "policy" and flagged["skate"] == 0.0 and flagged["pace"] == 0.0 and flagged["land"] == 0
    assert main([*args, "--out", str(tmp_path / "bad"), "--refine-pace", "-1"]) == 2
    assert "--refine-pace: expected a weight in [0, 1000], got -1.0" in capsys.readouterr().err
    assert main([*args, "--out", str(tmp_path / "bad"), "--refine-land", "17"]) == 2
    assert "--refine-land: expected 0-16 frames, got 17" in capsys.readouterr().err
    assert main([*args, "--out", str(tmp_path / "off"), "--refine", "0"]) == 0
    assert "refine" not in json.loads((tmp_path / "off" / "report.json").read_text())


@pytest.mark.parametrize("field, value, match", [
    ("refine", -1, r"refine: must be 0-1000 optimizer steps \(or null: off\), got -1"),
    ("refine_horizon", 17, r"refine_horizon: must be 1-16 primitives \(or null: 3\), got 17"),
    ("refine_skate", -1.0, r"refine_skate: must be a weight in \[0, 1000\] \(or null: 0\), got -1.0"),
    ("refine_start", "random", r"refine_start: must be policy, zeros or auto \(or null: policy\), got 'random'"),
    ("refine_pace", float("nan"), r"refine_pace: must be a weight in \[0, 1000\] \(or null: 0.5\), got nan"),
    ("refine_land", 17, r"refine_land: must be 0-16 frames \(or null: 0\), got 17"),
])
def test_eval_config_refine_fields_are_checked(field, value, match):
    from latentrl.errors import ConfigError
    from latentrl.evaluation.config import EvalConfig

    with pytest.raises(ConfigError, match=match):
        EvalConfig(**{field: value}).validate()
