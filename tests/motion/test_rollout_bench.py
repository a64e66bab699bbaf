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


def test_interleave_alternates_ours_and_the_peer_round_by_round():
    from latentrl.app.bench.rollout import interleave

    calls = []
    order = interleave(3, lambda r: calls.append(("ours", r)), lambda r: calls.append(("peer", r)) or True)
    assert calls == [("ours", 0), ("peer", 0), ("ours", 1), ("peer", 1), ("ours", 2), ("peer", 2)]
    assert order == ["ours 0", "peer 0", "ours 1", "peer 1", "ours 2", "peer 2"]
    # no peer: one round of ours, nothing more
    calls.clear()
    assert interleave(5, lambda r: calls.append(("ours", r)), lambda r: False) == ["ours 0"]
    assert calls == [("ours", 0)]


def test_ratio_spread_is_the_median_of_same_round_ratios_with_min_max_and_quartiles():
    import pytest

    from latentrl.app.bench.rollout import ratio_spread

    # the peer's time swings 2.0-5.8 s with the load while ours follows it: same-round ratios stay near 4
    stats = ratio_spread([2000.0, 5800.0, 4000.0, 3000.0, 2400.0], [500.0, 1450.0, 800.0, 750.0, 600.0])
    assert stats["rounds"] == pytest.approx([4.0, 4.0, 5.0, 4.0, 4.0])
    assert stats["median"] == 4.0 and stats["min"] == 4.0 and stats["max"] == 5.0
    assert (stats["q1"], stats["q3"]) == (4.0, 4.0)
    stats = ratio_spread([100.0, 300.0, 200.0, 400.0], [100.0, 100.0, 100.0, 100.0])
    assert stats["median"] == 2.5 and (stats["min"], stats["max"]) == (1.0, 4.0)
    assert stats["q1"] == pytest.approx(1.75) and stats["q3"] == pytest.approx(3.25)
    assert ratio_spread([30.0], [10.0])["median"] == pytest.approx(3.0)
    with pytest.raises(ValueError):
        ratio_spread([1.0, 2.0], [1.0])


def test_rounds_interleave_our_sampler_with_the_peer_and_report_the_median_ratio(tmp_path):
    """End to end at the official size, batch 1, two rounds; the peer is a stand-in script speaking DART's JSON."""
    import sys

    log = tmp_path / "peer_calls.txt"
    peer = tmp_path / "peer.py"
    peer.write_text(
        "import json, sys\n"
        f"open({str(log)!r}, 'a').write(' '.join(sys.argv[1:]) + '\\n')\n"
        "print('not json')\n"
        "print(json.dumps({'results': [{'batch': 1, 'ms_per_batch_median': 5000.0}]}))\n")
    out = tmp_path / "rollout.json"
    req = RolloutBenchRequest(batches=[1], models=["official"], device=["cpu"], repeats=1, rounds=2,
                              dart_src=str(tmp_path), dart_python=sys.executable, dart_bench=str(peer), json=str(out))
    assert bench_rollout(req) == 0
    data = json.loads(out.read_text())
    assert data["order"] == ["ours 0", "peer 0", "ours 1", "peer 1"] and data["rounds"] == 2
    calls = log.read_text().splitlines()
    assert len(calls) == 2 and "--reps 1" in calls[0]
    assert "--matmul-n" not in calls[0] and "--matmul-n 256" in calls[1]
    row = data["models"]["official"]["results"][0]
    assert len(row["ms_per_batch_rounds"]) == 2
    spread = data["speedup_vs_dart_official_cpu_spread"]["1"]
    assert spread["rounds"] == [5000.0 / ms for ms in row["ms_per_batch_rounds"]]
    assert spread["min"] <= data["speedup_vs_dart_official_cpu"]["1"] == spread["median"] <= spread["max"]
    assert data["dart_peer"]["ms_per_batch_rounds"] == {"1": [5000.0, 5000.0]}


def test_compiled_rows_keep_their_graph_across_rounds(tmp_path, monkeypatch):
    """Each compiled variant compiles once, in the first round; later rounds replay it (no recompilation)."""
    import sys

    graphs = []

    def counting_backend(gm, example_inputs):
        graphs.append(gm)
        return gm.forward

    real = torch.compile
    monkeypatch.setattr(torch, "compile", lambda fn, **kw: real(fn, **{**kw, "backend": counting_backend,
                                                                        "mode": None}))
    peer = tmp_path / "peer.py"
    peer.write_text("import json\nprint(json.dumps({'results': [{'batch': 2, 'ms_per_batch_median': 50.0}]}))\n")
    out = tmp_path / "rollout.json"
    req = RolloutBenchRequest(batches=[2], models=["default"], device=["cpu"], repeats=1, rounds=3, compile=True,
                              packed=True, dart_src=str(tmp_path), dart_python=sys.executable, dart_bench=str(peer),
                              json=str(out))
    assert bench_rollout(req) == 0
    data = json.loads(out.read_text())
    rows = data["models"]["default"]["results"]
    assert data["rounds"] == 3 and all(len(r["ms_per_batch_rounds"]) == 3 for r in rows)
    assert len(graphs) == 2  # compiled and compiled + packed, each once
    assert rows[1]["max_abs_diff_vs_eager"] < 1e-4 and rows[3]["max_abs_diff_vs_eager"] < 1e-4
    assert rows[2]["speedup_vs_eager"] > 0
