"""Every shipped policy loads on the embedded model it was trained on and drives one short path of its own skill.

The cards' headline numbers come from ``latentrl eval policies/<name>.pt --paths dart_<skill>_long
--episodes 32 --max-steps 256`` (each card names its command); this test keeps the files loadable and on
the model they were trained on, with one cheap deterministic episode each.
"""

import json
from pathlib import Path

import pytest
import torch

from latentrl.app.cli import main
from latentrl.evaluation.trained import stored_env
from latentrl.motion.checkpoint import default_model_path, file_sha256

ROOT = Path(__file__).resolve().parents[2]
POLICIES = {  # name -> (suite, step budget for path 0: 5 waypoints 4 m apart along +y)
    "reach_walk_default": ("dart_walk_long", 64),  # 13.2 s on path 0
    "reach_run_default": ("dart_run_long", 48),  # 7.3 s on path 0
    "reach_hop_left_default": ("dart_hop_long", 128),  # 16.2 s on path 0
    "path_mixed_default": ("mixed_skills", 96),  # walk, run, hop on left leg along +y: 30 m (23.9 s)
    "reach_obstacles_default": ("reach_obstacles", 64),  # one goal 3.4 m ahead among 3-8 random objects: ~5 s
    "path_maze_default": ("maze", 112),  # maze_a's route of 11 cell centres, 22 m between 1.8 m corridors: ~22 s
    "path_stairs_default": ("stairs", 64),  # stairs_10: up five 0.10 m steps, a landing, down five: 6.7 m, ~5 s
}
SHIPPED = [name for name in POLICIES if (ROOT / "policies" / f"{name}.pt").is_file()]


JOYSTICK_POLICIES = ["joystick_walk_default"]
TIMED_POLICIES = ["timed_walk_default"]
REACH_JOINT_POLICIES = ["reach_joint_default"]
TASK_POLICIES = {*JOYSTICK_POLICIES, *TIMED_POLICIES, *REACH_JOINT_POLICIES}  # tested by their own tests below


def test_every_shipped_policy_is_tested_here():
    shipped = {p.stem for p in (ROOT / "policies").glob("*.pt")}
    assert shipped == set(POLICIES) | TASK_POLICIES, shipped ^ (set(POLICIES) | TASK_POLICIES)
    assert all(name.endswith("_default") for name in shipped)  # older versions live in zoo/ (zoo/README.md)


def _evaluate_first_entry(name: str, task_dir: str, suite: str, tmp_path, *eval_args: str) -> tuple[dict, dict]:
    """Check policies/<name>.pt and its card against the model it was trained on, evaluate it on the first
    entry of tasks/<task_dir>/<suite>.json (one deterministic episode), and return (checkpoint, report)."""
    state = torch.load(ROOT / "policies" / f"{name}.pt", weights_only=True, map_location="cpu")
    assert state["motion"]["sha256"] == file_sha256(default_model_path("default")), "trained on another model"
    assert stored_env(ROOT / "policies" / f"{name}.pt").motion == "default"  # what eval loads without --motion
    card = (ROOT / "policies" / f"{name}.md").read_text()
    assert state["motion"]["sha256"][:16] in card and f"--paths {suite}" in card
    entries = json.loads((ROOT / "latentrl" / "tasks" / task_dir / f"{suite}.json").read_text())
    (tmp_path / "first.json").write_text(json.dumps(entries[:1]))
    out = tmp_path / "eval"
    code = main(["eval", str(ROOT / "policies" / f"{name}.pt"), "--paths", str(tmp_path / "first.json"),
                 "--episodes", "1", *eval_args, "--deterministic", "--no-render", "--no-motions", "--out", str(out)])
    assert code == 0
    return state, json.loads((out / "report.json").read_text())


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_policy_drives_its_first_path(name, tmp_path):
    suite, budget = POLICIES[name]
    _, report = _evaluate_first_entry(name, "paths", suite, tmp_path, "--max-steps", str(budget))
    episode = report["suites"]["first"]["paths"][0]["episodes"][0]
    # the last waypoint is 20 m (mixed: 30 m) ahead: a working policy ends far closer to it than it started
    assert episode["final_dist_m"] < 10.0, episode
    if name in ("reach_obstacles_default", "path_maze_default"):  # among objects: there without touching one
        assert episode["success"] and episode["collision"] == 0, episode
        assert report["avoid"]["steps"] == 16  # with the scene filter its card's figures were taken with
    if name == "path_stairs_default":  # over the stairs and down again, the feet never inside a tread
        assert episode["success"] and episode["penetration_mm"] < 10.0, episode


def _first_entry_metrics(name: str, task: str, suite: str, tmp_path) -> dict:
    """A task policy (trained with the foot lock) on the first entry of tasks/<task>/<suite>.json: its metrics."""
    state, report = _evaluate_first_entry(name, task, suite, tmp_path)
    assert state["config"]["env"]["foot_lock"] is True  # the card's skate figure is measured with the lock
    assert report["task"] == task
    return report["suites"][0]["entries"][0]["metrics"]


@pytest.mark.parametrize("name", TIMED_POLICIES)
def test_shipped_timed_policy_reaches_the_first_timed_path(name, tmp_path):
    """A timed policy (policies/timed_walk_*.md) on the first entry of tasks/timed/timed_walk.json."""
    metrics = _first_entry_metrics(name, "timed", "timed_walk", tmp_path)
    assert metrics["reached"]["mean"] > 0.5, metrics  # most waypoints of the 9.5 s line reached


@pytest.mark.parametrize("name", JOYSTICK_POLICIES)
def test_shipped_joystick_policy_follows_the_first_timeline(name, tmp_path):
    """A joystick policy (policies/joystick_walk_*.md) on the first timeline of joystick_walk.json."""
    metrics = _first_entry_metrics(name, "joystick", "joystick_walk", tmp_path)
    # its card measures 11.2 deg / 0.13 m/s on this timeline (32 stochastic episodes); the timeline turns by 90 deg
    # at each of its 4 command changes, so a policy that ignores
    # them lands far above these bounds
    assert metrics["heading_err_deg"]["mean"] < 30.0 and metrics["speed_err_m_s"]["mean"] < 0.3, metrics


@pytest.mark.parametrize("name", REACH_JOINT_POLICIES)
def test_shipped_reach_joint_policy_lands_the_first_far_goal_with_its_stored_refinement(name, tmp_path):
    """A ReachJoint policy (policies/reach_joint_default.md) on pelvis_far's first goal: the pelvis on a spot
    1.35 m ahead at 2 s, refined as the policy stores it (its card: 0.89 cm on this entry, skate 3.38 cm/s)."""
    state, report = _evaluate_first_entry(name, "joint_goals", "pelvis_far", tmp_path)
    stored = state["config"]["eval"]
    assert report["refine"]["steps"] == stored["refine"] > 0
    assert (report["refine"]["skate"], report["refine"]["pace"], report["refine"]["start"]) == (
        stored["refine_skate"], stored["refine_pace"], stored["refine_start"])
    metrics = report["suites"][0]["entries"][0]["metrics"]
    assert metrics["success"]["mean"] == 1.0 and metrics["err_far_cm"]["mean"] < 5.0, metrics
