"""Aggregation and report files on hand-made episode results with known answers."""

import json
import math

import numpy as np
import pytest

from latentrl.envs.path import WaypointPath
from latentrl.errors import DataError
from latentrl.evaluation import report as R
from latentrl.evaluation.runner import EpisodeResult, EvalSettings, PathResult, SuiteResult

SETTINGS = EvalSettings(episodes=2, max_steps=10)  # budget: (2 + 80) / 30 s
PATH = WaypointPath(((0.0, 3.0, 0.0), (4.0, 3.0, 0.0)), ("walk", "run"))


def episode(i: int, reach: float | None, skate: float = 1.0, suite: str = "s", path: int = 0) -> EpisodeResult:
    """A successful episode reaching the end at ``reach`` s, or (None) a timeout at the budget time."""
    ok = reach is not None
    metrics = {"skate_cm_s": skate, "skate_xy_cm_s": skate / 2, "floor_cm": 2.0, "jerk": 30.0,
               "penetration_mm": 0.0, "floating_mm": 1.0, "skating_mm": 0.5}
    return EpisodeResult(suite, path, i, ok, "success" if ok else "timeout", 4 if ok else 10,
                         reach if ok else SETTINGS.budget_s, [1.0, reach], 0.1 if ok else 2.0, metrics,
                         np.zeros((5, 2)))


def suite(name: str, *paths_eps) -> SuiteResult:
    paths = [PathResult(name, k, PATH, list(eps), 1.0) for k, eps in enumerate(paths_eps)]
    return SuiteResult(name, f"{name}.json", paths)


def test_timeouts_count_as_failures_with_the_budget_time():
    p = suite("s", [episode(0, 2.0), episode(1, None)]).paths[0]
    m = R.path_metrics(p)
    assert m["success_rate"]["mean"] == 0.5
    assert m["reach_time_s"]["mean"] == pytest.approx((2.0 + SETTINGS.budget_s) / 2)
    assert m["reach_time_success_s"] == {"mean": 2.0, "ci95": 0.0}


def test_suite_and_overall_use_dart_aggregation():
    # Path 0 skates 1 and 3, path 1 skates 3 and 5 -> episode-index means 2 and 4 -> 3 +- 1.96/sqrt(2).
    s = suite("s", [episode(0, 2.0, 1.0), episode(1, 4.0, 3.0)], [episode(0, 6.0, 3.0), episode(1, None, 5.0)])
    m = R.pooled_metrics(s.paths)
    assert m["skate_cm_s"] == {"mean": 3.0, "ci95": pytest.approx(1.96 / math.sqrt(2))}
    assert m["success_rate"]["mean"] == 0.75
    assert m["reach_time_success_s"]["mean"] == pytest.approx(4.0)  # pooled over the 3 successes
    assert set(m) == set(R.METRICS)


def test_waypoint_times_cover_only_episodes_that_reached():
    wps = R.waypoint_times(suite("s", [episode(0, 2.0), episode(1, None)]).paths[0])
    assert wps[0]["mean"] == 1.0 and wps[0]["reached_rate"] == 1.0
    assert wps[1]["mean"] == 2.0 and wps[1]["reached_rate"] == 0.5


def make_report(*suites: SuiteResult) -> dict:
    return R.build_report(list(suites), SETTINGS, policy={"path": "p.pt", "sha256": "ab" * 32, "iteration": 3},
                          motion={"source": "m.pt", "sha256": "cd" * 32},
                          speed={"1": {"batch": 1, "ms_per_step": 10.0, "frames_per_s": 800.0, "env_steps_per_s": 100}},
                          hardware={"cpu": "test cpu", "cpu_count": 2})


def test_report_files_are_written_and_well_formed(tmp_path):
    data = make_report(suite("dart_walk_long", [episode(0, 2.0), episode(1, None)], [episode(0, 3.0), episode(1, 5.0)]),
                       suite("mixed_text", [episode(0, None), episode(1, None)]))
    js, md = R.write_report(tmp_path, data)
    loaded = json.loads(js.read_text())  # strict JSON: no NaN
    assert loaded == R.load_report(tmp_path)
    for key in ("format", "latentrl_version", "policy", "motion", "settings", "hardware", "speed", "suites", "overall"):
        assert key in loaded
    assert loaded["policy"]["sha256"] and loaded["motion"]["sha256"]
    assert loaded["settings"]["max_steps"] == 10 and loaded["settings"]["budget_s"] == pytest.approx(82 / 30)
    for block in [*(s["metrics"] for s in loaded["suites"].values()), loaded["overall"]["metrics"]]:
        for name in ("success_rate", "reach_time_s", "skate_cm_s", "floor_cm", "jerk"):
            assert set(block[name]) == {"mean", "ci95"}
    assert loaded["suites"]["mixed_text"]["metrics"]["reach_time_success_s"]["mean"] is None  # NaN -> null
    path0 = loaded["suites"]["dart_walk_long"]["paths"][0]
    assert path0["episodes"][1]["end"] == "timeout" and len(path0["waypoint_reach_time_s"]) == 2
    text = md.read_text()
    results = text.split("## Results")[1].split("## Per-waypoint")[0]
    rows = [line for line in results.splitlines() if line.startswith("| dart_walk_long |")]
    assert len(rows) == 2 and rows[0].startswith("| dart_walk_long | 0 (walk, run) | 0.50 ± 0.69 |")  # one row per path
    assert "| **mixed_text** | all |" in text and "| **overall** | all |" in text
    assert "DART paper, Table 4 (walk)" in text and "17.08" in text
    assert "budget time" in text and "| 1 | 800 | 10.0 |" in text


def test_load_report_errors_name_the_file(tmp_path):
    with pytest.raises(DataError, match="report not found"):
        R.load_report(tmp_path)
    bad = tmp_path / "report.json"
    bad.write_text('{"format": "other"}')
    with pytest.raises(DataError, match="not a latentrl evaluation report"):
        R.load_report(bad)


def test_compare_puts_reports_side_by_side(tmp_path):
    a = make_report(suite("dart_run_long", [episode(0, 2.0), episode(1, 2.0)]))
    b = make_report(suite("dart_run_long", [episode(0, None), episode(1, 4.0)]))
    b["settings"]["episodes"] = 64
    R.write_report(tmp_path / "alpha", a)
    R.write_report(tmp_path / "beta", b)
    table = R.compare_reports([tmp_path / "alpha", tmp_path / "beta" / "report.json"])
    lines = table.splitlines()
    assert "| dart_run_long | alpha | 1.00 ± 0.00 |" in lines[2] and "| dart_run_long | beta | 0.50" in lines[3]
    assert any(line.startswith("| overall | beta |") for line in lines)
    assert "Note: `episodes` differs" in table
