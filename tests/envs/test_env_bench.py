"""``latentrl bench env`` body: figures, ratios, skips and notes, on the tiny model."""

import argparse
import json

import torch

from latentrl.app.bench.env import bench_env, bench_model, standing_seed


def bench_args(tmp_path, **kwargs) -> argparse.Namespace:
    base = {
        "models": ["tiny"],
        "num_envs": [1, 2],
        "device": ["cpu"],
        "steps": 1,
        "max_seconds": 60.0,
        "baseline": True,
        "compile": False,
        "amp": None,
        "threads": None,
        "json": str(tmp_path / "env.json"),
    }
    return argparse.Namespace(**{**base, **kwargs})


def test_bench_reports_both_kinds_and_the_ratio(tmp_path):
    assert bench_env(bench_args(tmp_path)) == 0
    out = json.loads((tmp_path / "env.json").read_text())
    rows = out["models"]["tiny"]["results"]
    assert [r["num_envs"] for r in rows] == [1, 2]
    for row in rows:
        assert row["vector"]["frames_per_s"] == 8 * row["vector"]["env_steps_per_s"]
        assert row["speedup"] == row["vector"]["env_steps_per_s"] / row["loop"]["env_steps_per_s"]
        assert row["sampler"]["env_steps_per_s"] > 0  # the bare sampler, beside the env
        assert row["env_share"] == 1.0 - row["vector"]["env_steps_per_s"] / row["sampler"]["env_steps_per_s"]


def test_bare_sampler_timer_steps_the_model_from_its_seed_states():
    from latentrl.app.bench.env import time_bare_sampler

    assert time_bare_sampler(bench_model("tiny"), 3, "cpu", 2) > 0


def test_bench_refuses_a_missing_model_before_timing_anything(tmp_path):
    import pytest

    from latentrl.errors import LatentRLError

    with pytest.raises(LatentRLError, match="missing.pt"):
        bench_env(bench_args(tmp_path, models=["tiny", str(tmp_path / "missing.pt")]))
    assert not (tmp_path / "env.json").exists()


def test_bench_skips_figures_over_budget(tmp_path):
    bench_env(bench_args(tmp_path, max_seconds=0.0, baseline=False))
    rows = json.loads((tmp_path / "env.json").read_text())["models"]["tiny"]["results"]
    assert "env_steps_per_s" in rows[0]["vector"]  # the first N always runs: nothing to estimate from
    assert "skipped" in rows[1]["vector"] and "loop" not in rows[1]


def test_standing_seed_is_canonical_and_on_its_feet():
    seed, pelvis_delta = standing_seed()
    assert seed.shape == (1, 2, 276)
    torch.testing.assert_close(seed[0, :, 144:147], torch.zeros(2, 3))  # pelvis at the canonical origin
    model = bench_model("tiny")
    assert model.seed_history is not None and model.text_encoder is not None
    assert model.pelvis_delta.shape == (3,) and torch.equal(pelvis_delta, model.pelvis_delta)


def test_bench_times_the_compiled_env_beside_the_eager_one(tmp_path, monkeypatch):
    """``--compile`` adds a compiled row and its ratio (traced with the eager backend here: no C++ build)."""
    real = torch.compile
    monkeypatch.setattr(torch, "compile", lambda fn, **kw: real(fn, **{**kw, "backend": "eager"}))
    torch._dynamo.reset()
    assert bench_env(bench_args(tmp_path, num_envs=[2], baseline=False, compile=True)) == 0
    row = json.loads((tmp_path / "env.json").read_text())["models"]["tiny"]["results"][0]
    assert row["compiled"]["env_steps_per_s"] > 0
    assert row["compile_speedup"] == row["compiled"]["env_steps_per_s"] / row["vector"]["env_steps_per_s"]


def test_bench_times_the_bf16_env_beside_the_fp32_one_and_restores_the_model(tmp_path):
    """``--amp bf16`` adds an autocast row and its ratio; the model is left in float32 for the rows after it."""
    assert bench_env(bench_args(tmp_path, num_envs=[2], baseline=False, amp="bf16")) == 0
    row = json.loads((tmp_path / "env.json").read_text())["models"]["tiny"]["results"][0]
    assert row["amp"]["env_steps_per_s"] > 0
    assert row["amp_speedup"] == row["amp"]["env_steps_per_s"] / row["vector"]["env_steps_per_s"]
    model = bench_model("tiny")
    from latentrl.app.bench.env import time_vector_env

    assert time_vector_env(model, 2, "cpu", 1, amp="bf16") > 0 and model.amp_dtype is None


def test_compile_with_amp_also_times_both_together(tmp_path, monkeypatch):
    """``--compile --amp bf16``: a third row, the compiled env under autocast, and its ratio to the fp32 eager env."""
    real = torch.compile
    monkeypatch.setattr(torch, "compile", lambda fn, **kw: real(fn, **{**kw, "backend": "eager"}))
    torch._dynamo.reset()
    assert bench_env(bench_args(tmp_path, num_envs=[2], baseline=False, compile=True, amp="bf16")) == 0
    row = json.loads((tmp_path / "env.json").read_text())["models"]["tiny"]["results"][0]
    assert {"compiled", "amp", "amp_compiled"} <= row.keys()
    assert row["amp_compiled_speedup"] == row["amp_compiled"]["env_steps_per_s"] / row["vector"]["env_steps_per_s"]
