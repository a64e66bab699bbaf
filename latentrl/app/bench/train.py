"""``latentrl bench train``: time to eval success on the quick config; native vs SB3 iteration time.

With ``--nproc 1 2 ...`` it instead times the same config on 1, 2, ... ranks of this machine
(``latentrl train --nproc N`` in a fresh process each; ``env.num_envs`` per rank).
"""

from __future__ import annotations

import re
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import torch

from latentrl.app.bench.common import write_json
from latentrl.timing import hardware


@dataclass
class TrainBenchRequest:
    """``latentrl bench train`` flags."""

    config: str | None = None
    overrides: list[str] = field(default_factory=list)
    target: float = 0.9
    eval_every: int = 10
    max_steps: int | None = None
    iterations: int = 5
    skip_success: bool = False
    threads: int | None = None
    run_dir: str | None = None
    progress: bool = True
    json: str | None = None
    side_by_side: bool = True
    """Also time the native and SB3 trainers side by side (``--no-side-by-side``: only the success run)."""
    nproc: list[int] | None = None
    """Rank counts to compare (``--nproc 1 2``); replaces the other two measurements."""


_LOG_LINE = re.compile(r"iter (\d+) \| steps (\d+) \| fps \S+ \| collect_s (\S+) \| update_s (\S+)")


def _ranks_run(req: TrainBenchRequest, base: Path, work: Path, nproc: int) -> dict:
    """Train ``req.iterations`` iterations on ``nproc`` ranks in a fresh process; rank 0's ``train.log`` timings."""
    from latentrl.app.train import load_train_config

    cfg = load_train_config(base, req.overrides)
    plan = cfg.ppo.plan(cfg.env.num_envs)
    run_dir = work / f"ranks_{nproc}"
    sets = [*req.overrides, f"ppo.total_steps={plan.batch_size * nproc * req.iterations}", "ppo.eval_every=0",
            f"ppo.checkpoint_every={10**6}"] + ([f"threads={req.threads}"] if req.threads else [])
    cmd = [sys.executable, "-m", "latentrl", "train", str(base), "--run-dir", str(run_dir), "--no-progress",
           "--nproc", str(nproc)] + [x for item in sets for x in ("--set", item)]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True)
    wall = time.perf_counter() - t0
    rows = [m.groups() for m in map(_LOG_LINE.search, (run_dir / "train.log").read_text().splitlines()) if m]
    times = [_Time(float(c), float(u)) for _, _, c, u in rows]
    summary = _iteration_summary(times)
    step = plan.batch_size * nproc
    return {"ranks": nproc, "envs_per_rank": cfg.env.num_envs, "steps_per_iteration": step, "wall_s": wall,
            **summary, "env_steps_per_s": step / summary["iteration_s"]}


class _Time:
    def __init__(self, collection_s: float, update_s: float):
        self.collection_s, self.update_s = collection_s, update_s


def bench_ranks(req: TrainBenchRequest, base: Path, work: Path) -> dict:
    """Env steps/s and seconds per iteration on each rank count of ``req.nproc``, and the ratio to the first."""
    runs = [_ranks_run(req, base, work, n) for n in req.nproc]
    first = runs[0]
    for run in runs:
        run["throughput_ratio"] = run["env_steps_per_s"] / first["env_steps_per_s"]
        print(f"{run['ranks']} rank(s) x {run['envs_per_rank']} envs: {run['env_steps_per_s']:.0f} env steps/s, "
              f"{run['iteration_s']:.2f} s/iteration (collect {run['collection_s']:.2f}, update "
              f"{run['update_s']:.2f}); throughput x{run['throughput_ratio']:.2f} of {first['ranks']} rank(s)")
    return {"runs": runs}


def _iteration_summary(times) -> dict:
    """Median per-iteration collection/update seconds, skipping the first (warm-up) iteration."""
    rows = list(times)[1:] or list(times)
    coll = statistics.median(t.collection_s for t in rows)
    upd = statistics.median(t.update_s for t in rows)
    return {"iterations_timed": len(rows), "collection_s": coll, "update_s": upd, "iteration_s": coll + upd,
            "update_share": upd / (coll + upd)}


def bench_train(req: TrainBenchRequest) -> int:
    """Time to eval success on the quick config, and native vs SB3 iteration time side by side."""
    import tempfile

    from latentrl.app.train import QUICK_CONFIG, load_train_config, run_training
    from latentrl.resources import config_file

    if req.threads:
        torch.set_num_threads(req.threads)
    base = config_file(req.config or QUICK_CONFIG)
    out = {"benchmark": "train", "hardware": hardware(), "config": str(base)}
    gpu = f"; {out['hardware']['gpu']}" if "gpu" in out["hardware"] else ""
    print(f"hardware: {out['hardware']['cpu']} ({out['hardware']['torch_threads']} threads){gpu}")
    work = Path(req.run_dir) if req.run_dir else Path(tempfile.mkdtemp(prefix="latentrl-bench-train-"))
    if req.nproc:
        out["ranks"] = bench_ranks(req, base, work)
        write_json(req.json, out)
        return 0
    if not req.skip_success:
        cfg = load_train_config(base, req.overrides)
        cfg.eval.success_target = req.target
        cfg.ppo.eval_every = req.eval_every
        if req.max_steps:
            cfg.ppo.total_steps = req.max_steps
        print(f"training {base.name} until eval success >= {req.target} (at most {cfg.ppo.total_steps} env steps)")
        t0 = time.perf_counter()
        res = run_training(cfg, work / "to_success", progress=req.progress)
        wall = time.perf_counter() - t0
        metrics = res.eval.metrics if res.eval is not None else {}
        out["to_success"] = {"target": req.target, "reached": bool(res.stopped_early), "wall_s": wall,
                             "train_s": res.elapsed_s, "env_steps": res.env_steps, "iterations": res.iterations,
                             "last_eval": metrics, **_iteration_summary(res.times)}
        print(f"{'reached' if res.stopped_early else 'did NOT reach'} eval success {req.target} after "
              f"{res.env_steps} env steps, {wall:.0f} s wall (last eval: {metrics})")
    if not req.side_by_side:
        write_json(req.json, out)
        return 0
    side = {}
    for trainer in ("native", "sb3"):
        cfg = load_train_config(base, req.overrides)
        cfg.ppo.eval_every = 0
        cfg.ppo.checkpoint_every = 10**6
        plan = cfg.ppo.plan(cfg.env.num_envs)
        cfg.ppo.total_steps = plan.batch_size * req.iterations
        res = run_training(cfg, work / f"side_by_side_{trainer}", trainer=trainer, progress=False)
        side[trainer] = _iteration_summary(res.times)
        s = side[trainer]
        print(f"{trainer:>6}: {s['iteration_s']:.2f} s/iteration (collection {s['collection_s']:.2f} s, "
              f"update {s['update_s']:.2f} s, update share {s['update_share']:.0%})")
    side["native_over_sb3"] = side["native"]["iteration_s"] / side["sb3"]["iteration_s"]
    out["native_vs_sb3"] = side
    print(f"native / SB3 per-iteration time: {side['native_over_sb3']:.2f} (target <= 0.6)")
    write_json(req.json, out)
    return 0
