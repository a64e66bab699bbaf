"""``latentrl bench rollout``: its rows and its compiled figure (small batches, the embedded model)."""

import json

import torch

from latentrl.app.bench.rollout import RolloutBenchRequest, bench_rollout


def test_compile_adds_a_compiled_row_that_matches_the_eager_sampler(tmp_path, monkeypatch):
    """Traced with the eager backend (no C++ build in the fast suite): one graph, same numbers."""
    real = torch.compile
    monkeypatch.setattr(torch, "compile", lambda fn, **kw: real(fn, **{**kw, "backend": "eager"}))
    out = tmp_path / "rollout.json"
    req = RolloutBenchRequest(batches=[2], models=["default"], device=["cpu"], repeats=1, compile=True, json=str(out))
    assert bench_rollout(req) == 0
    rows = json.loads(out.read_text())["models"]["default"]["results"]
    eager, compiled = rows
    assert "compiled" not in eager and compiled["compiled"] is True and compiled["packed"] is False
    assert compiled["batch"] == eager["batch"] == 2 and compiled["primitives_per_s"] > 0
    assert compiled["max_abs_diff_vs_eager"] < 1e-4


def test_packed_adds_packed_and_compiled_packed_rows_that_match_the_unpacked_sampler(tmp_path, monkeypatch):
    """``--packed``: the same sampler with oneDNN-packed weights, eager and (eager-backend) compiled."""
    real = torch.compile
    monkeypatch.setattr(torch, "compile", lambda fn, **kw: real(fn, **{**kw, "backend": "eager"}))
    out = tmp_path / "rollout.json"
    req = RolloutBenchRequest(batches=[2], models=["default"], device=["cpu"], repeats=1, compile=True, packed=True,
                              json=str(out))
    assert bench_rollout(req) == 0
    rows = json.loads(out.read_text())["models"]["default"]["results"]
    assert [(r.get("compiled", False), r.get("packed", False)) for r in rows] == [
        (False, False), (True, False), (False, True), (True, True)]
    for row in rows[2:]:
        assert row["max_abs_diff_vs_plain"] < 1e-4 and row["primitives_per_s"] > 0
    assert rows[3]["max_abs_diff_vs_eager"] < 1e-4


def test_packed_without_compile_adds_one_packed_row(tmp_path):
    out = tmp_path / "rollout.json"
    req = RolloutBenchRequest(batches=[2], models=["default"], device=["cpu"], repeats=1, packed=True, json=str(out))
    assert bench_rollout(req) == 0
    rows = json.loads(out.read_text())["models"]["default"]["results"]
    assert [r.get("packed", False) for r in rows] == [False, True] and rows[1]["compiled"] is False


def test_amp_with_compile_adds_eager_and_compiled_autocast_rows_with_their_error(tmp_path, monkeypatch):
    """``--amp bf16 --compile``: bf16 autocast eager and compiled, each with its difference from plain fp32."""
    real = torch.compile
    monkeypatch.setattr(torch, "compile", lambda fn, **kw: real(fn, **{**kw, "backend": "eager"}))
    out = tmp_path / "rollout.json"
    req = RolloutBenchRequest(batches=[2], models=["default"], device=["cpu"], repeats=1, amp=["bf16"], compile=True,
                              json=str(out))
    assert bench_rollout(req) == 0
    rows = json.loads(out.read_text())["models"]["default"]["results"]
    assert [(r.get("amp"), r.get("compiled", False)) for r in rows] == [
        (None, False), (None, True), ("bf16", False), ("bf16", True)]
    for row in rows[2:]:
        # bf16 really changes the numbers (a row that silently ran fp32 would show 0), but not wildly
        assert 0 < row["rel_diff_vs_plain"] < 0.2 and row["max_abs_diff_vs_plain"] > 0
    assert rows[3]["max_abs_diff_vs_eager"] < 1e-3
    assert "max_abs_diff_vs_plain" not in rows[1]


def test_cuda_graph_rows_are_cuda_only(tmp_path):
    """``--cuda-graph`` adds no row on the CPU (nothing to capture there); scripts/gpu_check.sh times it on CUDA."""
    out = tmp_path / "rollout.json"
    req = RolloutBenchRequest(batches=[2], models=["default"], device=["cpu"], repeats=1, cuda_graph=True,
                              json=str(out))
    assert bench_rollout(req) == 0
    rows = json.loads(out.read_text())["models"]["default"]["results"]
    assert len(rows) == 1 and "cuda_graph" not in rows[0]


def test_dart_runs_pair_each_cuda_device_with_fp32_and_dart_s_own_fp16():
    from latentrl.app.bench.rollout import _dart_runs

    assert _dart_runs(["cpu"]) == [("cpu", "fp32")]
    assert _dart_runs(["cpu", "cuda"]) == [("cpu", "fp32"), ("cuda", "fp32"), ("cuda", "fp16")]
