"""``latentrl bench optimize``: noise optimization's quality and cost on the shipped constraint suites.

Rows: per suite, the mean goal error, history error, skate, floor, jerk against plain rollouts of the same
starts and prompts, the share of problems within 1 cm and the wall time to 1 cm (cold start; and warm, from
a policy's noises, with ``--warm``); then the cost of 100 steps over 64 frames (8 primitives) on the embedded
default model and on DART's released architecture (random weights), per device, beside DART's figure (74 s for
100 steps over 60 frames on an RTX 4090, its App. F); then problems per minute of the solver itself at each
``--batches`` size (problems solved together), with each size's same-run ratio to batch 1.
"""

from __future__ import annotations

import dataclasses
import io
import statistics
import time
from dataclasses import dataclass, field

import torch

from latentrl.app.bench.common import default_devices, official_size_model, write_json
from latentrl.motion.checkpoint import load_motion_model
from latentrl.optim import OptimizeSettings, load_suite, optimize
from latentrl.optim.report import summary
from latentrl.optim.solver import add_unconstrained_jerk, rollout, solve_batch
from latentrl.optim.warm import policy_warm_start
from latentrl.resources import task_file
from latentrl.safe_io import atomic_write_bytes
from latentrl.timing import hardware, median_time

DART_SECONDS_PER_100_STEPS_60_FRAMES = 74.0
"""DART App. F: "60 frames and 100 optimization steps costs around 74 seconds" (RTX 4090)."""


@dataclass
class OptimizeBenchRequest:
    """``latentrl bench optimize`` flags."""

    suites: list[str] = field(default_factory=lambda: ["inbetween", "inbetween_mid", "joint_targets"])
    steps: int = 100
    batch: int = 16
    lr: float = 0.05
    warm: str | None = None
    """A reach/path policy whose noises warm-start a second run of every suite."""
    cost_steps: int = 5
    """Timed steps of the cost rows (the figure is scaled to 100 steps)."""
    models: list[str] = field(default_factory=lambda: ["default", "official"])
    batches: list[int] = field(default_factory=lambda: [1, 8, 64])
    """Problems solved together in the rate rows (problems per minute at 100 steps, default model)."""
    device: list[str] | None = None
    threads: int | None = None
    skip_suites: bool = False
    json: str | None = None
    plot: str | None = None
    """PNG: mean goal error against wall time per suite, cold and warm (one line each)."""


def _suite_rows(req: OptimizeBenchRequest, device: str, warm_fn, curves: dict) -> list[dict]:
    model = load_motion_model("default", device=device)
    rows = []
    for name in req.suites:
        problems = load_suite(task_file(name, "constraints") or name)
        starts = [("cold", None)] + ([("warm", warm_fn)] if warm_fn is not None else [])
        for label, fn in starts:
            settings = OptimizeSettings(steps=req.steps, lr=req.lr, batch=req.batch)
            t0 = time.perf_counter()
            results = optimize(model, problems, settings, warm_start=fn)
            wall = time.perf_counter() - t0
            add_unconstrained_jerk(model, results, settings.guidance)
            s = summary(results)
            to_1cm = [r.metrics["seconds_to_1cm"] / r.metrics["batch"] for r in results
                      if r.metrics["seconds_to_1cm"] is not None]
            row = {"suite": name, "start": label, "device": device, "problems": len(results), "wall_s": wall,
                   "seconds_per_problem": wall / len(results),
                   "amortized_seconds_to_1cm_mean": sum(to_1cm) / len(to_1cm) if to_1cm else None, **s}
            rows.append(row)
            curves[f"{name} {label} ({device})"] = mean_curve(results)
            print(f"{name:>14} {label:>4} {device}: goal {s['goal_error_cm']:.3f} cm, within 1 cm "
                  f"{s['share_within_1cm']:.0%}, history {s['history_error_cm']:.3f} cm, skate "
                  f"{s['skate_cm_s']:.2f} cm/s, floor {s['floor_cm']:.2f} cm, jerk {s['jerk']:.0f} (plain rollouts "
                  f"{s['jerk_unconstrained']:.0f}), {wall / len(results):.2f} s per problem "
                  f"({len(results)} problems, batch {req.batch}, {wall:.1f} s)")
    return rows


def mean_curve(results) -> tuple[list[float], list[float]]:
    """(seconds per problem, mean goal error cm) at each step, over the problems of a suite (per batch time / size)."""
    steps = min(len(r.trace) for r in results)
    t = [sum(r.trace[k][0] / r.metrics["batch"] for r in results) / len(results) for k in range(steps)]
    e = [sum(r.trace[k][1] for r in results) / len(results) for k in range(steps)]
    return t, e


def plot_curves(curves: dict, path: str) -> None:
    """Write the error-against-time plot (log scale) of every suite and start."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4), dpi=100)
    for label, (t, e) in curves.items():
        ax.plot(t, e, lw=1.2, ls="--" if " warm " in label else "-", label=label)
    ax.axhline(1.0, color="gray", lw=0.8, ls=":")
    ax.set_yscale("log")
    ax.set_xlabel("wall time per problem (s)")
    ax.set_ylabel("mean goal error (cm)")
    ax.legend(fontsize=7)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    atomic_write_bytes(path, buf.getvalue())
    print(f"wrote {path}")


def _cost_row(name: str, device: str, steps: int) -> dict:
    """Seconds per optimizer step (forward + backward) at batch 1 over 8 primitives, scaled to 100 steps."""
    if name == "official":
        model = official_size_model().to(device)
        default = load_motion_model("default", device=device)
        model.pelvis_delta = default.pelvis_delta
        model.seed_history = default.seed_history
        text = torch.zeros(1, model.text_dim, device=device)
    else:
        model = load_motion_model(name, device=device)
        text = model.encode_text(["walk"])
    start = model.initial_state(1, seed_index=torch.tensor([0]))
    z = torch.zeros(8, 1, *model.latent_shape, device=device, requires_grad=True)
    def one_step():
        joints, _ = rollout(model, start, [text] * 8, z, 5.0)
        joints[:, -1].square().sum().backward()

    per_step = median_time(one_step, repeats=steps, warmup=1, device=device)
    per_100 = per_step * 100
    row = {"model": name, "device": device, "seconds_per_step": per_step, "seconds_per_100_steps_64_frames": per_100,
           "seconds_per_100_steps_60_frames": per_100 * 60 / 64,
           "dart_ratio": DART_SECONDS_PER_100_STEPS_60_FRAMES / (per_100 * 60 / 64)}
    print(f"cost {name:>8} {device}: {per_step * 1000:.0f} ms per step, {per_100:.1f} s per 100 steps x 64 frames "
          f"({per_100 * 60 / 64:.1f} s scaled to 60 frames; DART: 74 s on an RTX 4090, x{row['dart_ratio']:.1f})")
    return row


RATE_SUITE = "inbetween"
"""The rate rows solve copies of this suite's first 64-frame problem."""


def _rate_problem():
    """The first 8-primitive (64-frame) problem of :data:`RATE_SUITE`."""
    return next(p for p in load_suite(task_file(RATE_SUITE, "constraints")) if p.primitives == 8)


def rate_from_trace(step_ends: list[float], wall: float, batch: int, steps: int = 100) -> dict:
    """Problems per minute at ``steps`` steps from one timed batch: the median step and the fixed cost.

    ``step_ends``: seconds since the batch's first step began, at the end of each step (a result's trace);
    the first step is a warm-up, left out of the median. ``wall``: the whole call (set-up and the final
    rollout included); what it holds beyond the steps is counted once per batch.
    """
    if len(step_ends) < 2:
        raise ValueError(f"need at least 2 timed steps (the first is a warm-up), got {len(step_ends)}")
    per_step = statistics.median(b - a for a, b in zip(step_ends, step_ends[1:]))
    fixed = max(wall - step_ends[-1], 0.0)
    seconds = fixed + steps * per_step
    return {"batch": batch, "seconds_per_step": per_step, "fixed_seconds": fixed,
            f"seconds_per_batch_{steps}_steps": seconds, f"seconds_per_problem_{steps}_steps": seconds / batch,
            "problems_per_minute": 60.0 * batch / seconds}


def _rate_row(model, device: str, batch: int, timed_steps: int) -> dict:
    """Solve ``batch`` copies of one 64-frame problem together for ``timed_steps`` + 1 steps; the rate at 100."""
    problem = _rate_problem()
    problems = [dataclasses.replace(problem, name=f"{problem.name}#{k}") for k in range(batch)]
    settings = OptimizeSettings(steps=timed_steps + 1, batch=batch)
    t0 = time.perf_counter()
    results = solve_batch(model, problems, settings)
    wall = time.perf_counter() - t0
    row = {"model": "default", "device": device, "frames": problem.num_frames, "timed_steps": timed_steps,
           **rate_from_trace([t for t, _, _ in results[0].trace], wall, batch)}
    row["seconds_per_problem_100_steps_60_frames"] = row["seconds_per_problem_100_steps"] * 60 / problem.num_frames
    row["dart_ratio"] = DART_SECONDS_PER_100_STEPS_60_FRAMES / row["seconds_per_problem_100_steps_60_frames"]
    return row


def _rate_rows(req: OptimizeBenchRequest, device: str) -> list[dict]:
    """One rate row per ``--batches`` size, each with its ratio to batch 1 of the same run (when timed)."""
    model = load_motion_model("default", device=device)
    rows = [_rate_row(model, device, b, req.cost_steps) for b in req.batches]
    one = next((r for r in rows if r["batch"] == 1), None)
    for r in rows:
        if one is not None:
            r["vs_batch_1"] = r["problems_per_minute"] / one["problems_per_minute"]
        versus = f", {r['vs_batch_1']:.2f}x batch 1 (same run)" if one is not None and r is not one else ""
        print(f"rate default {device} batch {r['batch']:>3}: {r['seconds_per_step'] * 1000:.0f} ms per step, "
              f"{r['seconds_per_batch_100_steps']:.1f} s per 100 steps for {r['batch']} problems of 64 frames, "
              f"{r['problems_per_minute']:.2f} problems/min{versus}; x{r['dart_ratio']:.1f} DART's 74 s per problem "
              f"(100 steps x 60 frames, RTX 4090, published)")
    return rows


def bench_optimize(req: OptimizeBenchRequest) -> int:
    """Run the rows and print them; all figures go to ``--json`` with the hardware label."""
    if req.threads:
        torch.set_num_threads(req.threads)
    devices = default_devices(req.device)
    hw = hardware()
    print(f"hardware: {hw}")
    warm_fn = None
    if req.warm:
        warm_fn = policy_warm_start(req.warm)
    out = {"hardware": hw, "steps": req.steps, "batch": req.batch, "suites": [], "cost": [], "rate": [],
           "curves": {}}
    for device in devices:
        if not req.skip_suites:
            out["suites"] += _suite_rows(req, device, warm_fn, out["curves"])
        for name in req.models:
            out["cost"].append(_cost_row(name, device, req.cost_steps))
        if req.batches:
            out["rate"] += _rate_rows(req, device)
    if req.plot and out["curves"]:
        plot_curves(out["curves"], req.plot)
    write_json(req.json, out)
    return 0
