"""``latentrl bench optimize`` rate rows: problems per minute of the solver at several batch sizes."""

import json

import pytest

from latentrl.app.bench.optimize import OptimizeBenchRequest, bench_optimize, rate_from_trace


def test_rate_from_trace_takes_the_median_step_after_the_warm_up_and_counts_the_rest_once():
    # steps end at 3.0 (warm-up), 4.0, 5.5, 6.5 s: steps of 1.0, 1.5, 1.0 -> median 1.0; 0.5 s outside the steps
    row = rate_from_trace([3.0, 4.0, 5.5, 6.5], wall=7.0, batch=8)
    assert row["seconds_per_step"] == 1.0 and row["fixed_seconds"] == pytest.approx(0.5)
    assert row["seconds_per_batch_100_steps"] == pytest.approx(100.5)
    assert row["seconds_per_problem_100_steps"] == pytest.approx(100.5 / 8)
    assert row["problems_per_minute"] == pytest.approx(60 * 8 / 100.5)
    with pytest.raises(ValueError):
        rate_from_trace([1.0], wall=1.0, batch=1)


def test_bench_optimize_rate_rows_solve_each_batch_and_compare_it_with_batch_1(tmp_path, capsys):
    out = tmp_path / "b.json"
    req = OptimizeBenchRequest(skip_suites=True, models=[], batches=[1, 2], cost_steps=1, device=["cpu"],
                               json=str(out))
    assert bench_optimize(req) == 0
    rows = json.loads(out.read_text())["rate"]
    assert [r["batch"] for r in rows] == [1, 2] and all(r["frames"] == 64 for r in rows)
    for r in rows:
        assert r["problems_per_minute"] > 0 and r["seconds_per_step"] > 0 and r["dart_ratio"] > 0
    assert rows[0]["vs_batch_1"] == 1.0 and rows[1]["vs_batch_1"] > 0
    printed = capsys.readouterr().out
    assert "x batch 1 (same run)" in printed and "RTX 4090" in printed
