"""The runner on the tiny real motion model with a fresh policy: outcomes, censoring, cut motions, seeding."""

from types import SimpleNamespace

import matplotlib.pyplot as plt
import pytest
import torch

from latentrl.envs.path import WaypointPath
from latentrl.errors import CheckpointError, DataError
from latentrl.evaluation.runner import (
    EvalSettings,
    fit_policy,
    frames_after,
    load_suites,
    measure_speed,
    policy_fn,
    run_path,
    run_suites,
    training_eval_hook,
)
from latentrl.monitor import EVAL_METRICS, EVAL_TRAJECTORIES
from tests.evaluation.conftest import FAR, NEAR, fresh_policy, write_paths


def as_path(entry: dict) -> WaypointPath:
    return WaypointPath(tuple(tuple(map(float, w)) for w in entry["goal_location"]), tuple(entry["goal_text"]))


@pytest.fixture(scope="module")
def act(tiny_model):
    return policy_fn(fresh_policy(tiny_model))


def test_timed_out_episode_is_a_failure_with_the_budget_time(tiny_model, act):
    settings = EvalSettings(episodes=2, max_steps=3)
    result = run_path(act, tiny_model, as_path(FAR), settings, suite="far")
    assert settings.budget_s == pytest.approx(frames_after(3) / 30) == pytest.approx(26 / 30)
    for ep in result.episodes:
        assert not ep.success and ep.end == "timeout" and ep.steps == 3
        assert ep.reach_time_s == settings.budget_s  # censored, not dropped
        assert ep.waypoint_times_s == [pytest.approx(10 / 30), None]  # first waypoint (at the start) in step 1
        assert ep.final_dist_m > 30.0
        assert ep.pelvis_xy.shape == (26, 2)


def test_success_ends_the_episode_at_the_final_waypoint(tiny_model, act):
    motions = []
    result = run_path(act, tiny_model, as_path(NEAR), EvalSettings(episodes=2, max_steps=5), suite="near",
                      sink=lambda ep, m: motions.append(m) or f"ep{ep.episode}")
    for ep, motion in zip(result.episodes, motions):
        assert ep.success and ep.end == "success" and ep.steps == 1
        assert ep.reach_time_s == pytest.approx(10 / 30)  # DART: frames / 30, the 2 seed frames included
        assert ep.final_dist_m < 0.3  # DART's check agrees with the env's
        assert len(motion["joints"]) == frames_after(ep.steps) and len(motion["actions"]) == ep.steps
        assert len(motion["texts"]) == len(motion["primitive"]) == len(motion["joints"])
        assert motion["waypoints"].shape == (1, 3) and ep.motion_file == f"ep{ep.episode}"
        assert set(ep.metrics) >= {"skate_cm_s", "floor_cm", "jerk", "penetration_mm", "floating_mm", "skating_mm"}


def test_seeded_evaluation_repeats_exactly(tiny_model, act):
    settings = EvalSettings(episodes=2, max_steps=2, seed=3)
    a = run_path(act, tiny_model, as_path(FAR), settings, suite="s", index=1)
    b = run_path(act, tiny_model, as_path(FAR), settings, suite="s", index=1)
    assert [e.metrics for e in a.episodes] == [e.metrics for e in b.episodes]
    c = run_path(act, tiny_model, as_path(FAR), settings, suite="s", index=2)  # another path, another seed
    assert [e.metrics for e in a.episodes] != [e.metrics for e in c.episodes]


def test_deterministic_policy_takes_the_mean(tiny_model):
    policy = fresh_policy(tiny_model)
    obs = torch.zeros(3, policy.obs_dim)
    mean = policy(obs).mean
    assert torch.equal(policy_fn(policy, deterministic=True)(obs), mean)
    assert not torch.equal(policy_fn(policy)(obs), mean)


def test_run_suites_checks_every_file_before_running(tmp_path, tiny_model, act):
    good = write_paths(tmp_path, [NEAR], "good.json")
    broken = {"goal_location": [[0, 1, 0], [1, 2]], "goal_text": ["walk", "run"]}
    bad = write_paths(tmp_path, [NEAR, broken], "bad.json")
    calls = []
    with pytest.raises(DataError, match=r"bad.json: path 1, waypoint 1: field 'goal_location'"):
        run_suites(act, tiny_model, [good, bad], EvalSettings(episodes=1, max_steps=1),
                   sink=lambda ep, m: calls.append(ep))
    assert calls == []


def test_fit_policy_recognises_layouts_and_refuses_misfits(tiny_model):
    settings = EvalSettings()
    plain, nxt = fresh_policy(tiny_model), fresh_policy(tiny_model, observe_next=True)
    assert fit_policy(plain.obs_dim, plain.action_dim, tiny_model, settings) is False
    assert fit_policy(nxt.obs_dim, nxt.action_dim, tiny_model, settings) is True
    with pytest.raises(CheckpointError, match="16 values"):
        fit_policy(plain.obs_dim, 256, tiny_model, settings)
    with pytest.raises(CheckpointError, match="observations"):
        fit_policy(plain.obs_dim + 1, plain.action_dim, tiny_model, settings)


def test_measure_speed_reports_frames_per_second(tiny_model, act):
    out = measure_speed(act, tiny_model, as_path(FAR), EvalSettings(), [1, 2, 2], repeats=2)
    assert list(out) == ["1", "2"]
    for row in out.values():
        assert row["frames_per_s"] == pytest.approx(8 * row["batch"] / (row["ms_per_step"] / 1e3))


def test_load_suites_can_replace_every_text(tmp_path):
    [(file, paths)] = load_suites([write_paths(tmp_path, [NEAR, FAR])], text="run")
    assert file.name == "paths.json" and [p.texts for p in paths] == [("run",), ("run", "run")]


def test_training_eval_hook_reports_metrics_figure_and_stop(tmp_path, tiny_model):
    files = [write_paths(tmp_path, [NEAR])]
    env_cfg = SimpleNamespace(task="reach", guidance_scale=5.0, observe_next=False)
    eval_cfg = SimpleNamespace(episodes=2, max_steps=2, deterministic=True, text=None, success_target=0.9)
    report = training_eval_hook(files, tiny_model, env_cfg, eval_cfg)(fresh_policy(tiny_model))
    assert set(EVAL_METRICS) <= set(report.metrics) and report.metrics["success_rate"] == 1.0
    assert report.stop and EVAL_TRAJECTORIES in report.figures
    plt.close(report.figures[EVAL_TRAJECTORIES])
