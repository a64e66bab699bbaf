"""What ``latentrl optimize`` writes: ``report.json``/``report.md``, a motion ``.npz`` per problem and a plot.

``report.json`` carries each problem's constraints as point targets (frame counted from the first generated
frame, joint name, world target, axes) so the viewer can draw them beside the result, and the metrics of
the returned motion (post-processing: none; docs/optimize.md defines every metric).
"""

from __future__ import annotations

import io
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

from latentrl.errors import DataError
from latentrl.motion.representation import HISTORY_LENGTH
from latentrl.motion.skeleton import JOINT_NAMES
from latentrl.optim.solver import OptimizeSettings, Result
from latentrl.safe_io import atomic_write_bytes, atomic_write_text

REPORT_FORMAT = "latentrl.optimize-report/1"
METRICS = ("goal_error_cm", "history_error_cm", "skate_cm_s", "floor_cm", "jerk", "jerk_unconstrained",
           "seconds", "seconds_to_1cm", "steps")


def _mean(values: list) -> float | None:
    vals = [v for v in values if v is not None and math.isfinite(v)]
    return float(np.mean(vals)) if vals else None


def summary(results: list[Result]) -> dict:
    """Means over problems of every metric, and the share of problems at or under 1 cm."""
    out = {k: _mean([r.metrics.get(k) for r in results]) for k in METRICS}
    out["problems"] = len(results)
    out["share_within_1cm"] = float(np.mean([r.metrics["goal_error_cm"] <= 1.0 for r in results]))
    # each problem's share of its own batch's wall time (batches of one suite may differ in size)
    out["seconds_per_problem"] = _mean([r.metrics["seconds"] / r.metrics["batch"] for r in results]) or 0.0
    return out


def check_report(report: Any, path: str | Path) -> None:
    """The one check of a read ``report.json`` of this format (what ``latentrl view`` relies on).

    ``problems`` a non-empty list; each with ``name`` and ``motion`` strings (the motion a relative file name
    inside the report's folder), ``metrics`` numbers (NaN allowed) or null, ``targets`` a list of ``motion_frame`` (an
    integer in [0, MAX_FRAMES]) and ``position`` (three finite numbers); ``overall`` numbers or null;
    ``suite`` a string. One :class:`DataError` line naming the file and field.
    """
    from latentrl.motion.clip import MAX_FRAMES

    def need(ok: bool, field: str, expected: str, got: Any) -> None:
        if not ok:
            shown = type(got).__name__ if isinstance(got, (dict, list)) else repr(got)[:60]
            raise DataError(f"{path}: field '{field}' must be {expected}, got {shown}")

    def number(v: Any) -> bool:
        return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

    def numbers(block: Any, field: str) -> None:  # NaN and inf stay allowed: a metric may be undefined
        need(isinstance(block, dict), field, "an object", block)
        for key, v in block.items():
            need(v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)), f"{field}.{key}",
                 "a number or null", v)

    need(isinstance(report, dict), "report", "an object", report)
    need(isinstance(report.get("suite", ""), str), "suite", "a string", report.get("suite"))
    numbers(report.get("overall", {}), "overall")
    problems = report.get("problems")
    need(isinstance(problems, list) and len(problems) > 0, "problems", "a non-empty list", problems)
    for i, e in enumerate(problems):
        field = f"problems.{i}"
        need(isinstance(e, dict), field, "an object", e)
        need(isinstance(e.get("name"), str), f"{field}.name", "a string", e.get("name"))
        motion = e.get("motion")
        need(isinstance(motion, str), f"{field}.motion", "a file name inside the report's folder", motion)
        if Path(motion).is_absolute() or ".." in Path(motion).parts:
            raise DataError(f"{path}: field '{field}.motion' {motion[:80]!r} points outside the report's folder")
        numbers(e.get("metrics", {}), f"{field}.metrics")
        targets = e.get("targets", [])
        need(isinstance(targets, list), f"{field}.targets", "a list", targets)
        for j, t in enumerate(targets):
            need(isinstance(t, dict), f"{field}.targets.{j}", "an object", t)
            frame, pos = t.get("motion_frame"), t.get("position")
            need(isinstance(frame, int) and not isinstance(frame, bool) and 0 <= frame <= MAX_FRAMES,
                 f"{field}.targets.{j}.motion_frame", f"an integer in [0, {MAX_FRAMES}]", frame)
            need(isinstance(pos, list) and len(pos) == 3 and all(number(v) for v in pos),
                 f"{field}.targets.{j}.position", "[x, y, z] finite numbers", pos)


def problem_entry(r: Result, motion_file: str) -> dict:
    """One problem of ``report.json``: its metrics, motion file and targets (frames in the motion file's count)."""
    p = r.problem
    targets = [{"frame": int(f), "motion_frame": int(f) + HISTORY_LENGTH, "joint": JOINT_NAMES[int(j)],
                "position": [round(float(x), 5) for x in t], "axes": "".join(a for a, m in zip("xyz", mk) if m)}
               for f, j, t, mk in zip(p.frames, p.joints, p.targets, p.masks)]
    return {"name": p.name, "text": p.texts, "primitives": p.primitives, "motion": motion_file,
            "metrics": r.metrics, "targets": targets}


def write_outputs(results: list[Result], out_dir: str | Path, settings: OptimizeSettings, header: dict,
                  plot: bool = True) -> Path:
    """Write motions, ``report.json``, ``report.md`` and ``optimize.png`` into ``out_dir``; returns report.json."""
    out = Path(out_dir)
    (out / "motions").mkdir(parents=True, exist_ok=True)
    entries = []
    for r in results:
        name = f"motions/{r.problem.name}.npz"
        r.clip().save(out / name)
        entries.append(problem_entry(r, name))
    report = {"format": REPORT_FORMAT, **header, "post_processing": "none",
              "settings": {k: v for k, v in vars(settings).items()}, "overall": summary(results),
              "problems": entries}
    atomic_write_text(out / "report.md", markdown(report))
    if plot:
        atomic_write_bytes(out / "optimize.png", plot_traces(results))
    return atomic_write_text(out / "report.json", json.dumps(report, indent=1))


def hardware_label(hw: dict) -> str:
    """One line naming the CPU (cores, torch threads), the GPU if any, and torch."""
    gpu = f", {hw['gpu']}" if hw.get("gpu") else ""
    return (f"{hw.get('cpu', 'unknown CPU')} ({hw.get('cpu_count', '?')} cores, {hw.get('torch_threads', '?')} torch "
            f"threads){gpu}, torch {hw.get('torch', '?')}")


def _fmt(v) -> str:
    if v is None:
        return "–"
    if isinstance(v, float):
        return f"{v:.3g}" if abs(v) < 100 else f"{v:.0f}"
    return str(v)


def markdown(report: dict) -> str:
    """The report as a markdown table (one row per problem, then the means)."""
    cols = ("goal_error_cm", "history_error_cm", "skate_cm_s", "floor_cm", "jerk", "jerk_unconstrained",
            "seconds", "seconds_to_1cm")
    lines = [f"# Noise optimization: {report.get('suite', '')}", "",
             f"Motion model `{report.get('motion_model', '')}`, {report['settings']['steps']} steps, lr "
             f"{report['settings']['lr']}, init `{report['settings']['init']}`, post-processing: none. "
             f"Hardware: {hardware_label(report.get('hardware', {}))}.", "",
             "| problem | " + " | ".join(cols) + " |", "|---" * (len(cols) + 1) + "|"]
    for e in report["problems"]:
        lines.append(f"| {e['name']} | " + " | ".join(_fmt(e["metrics"].get(c)) for c in cols) + " |")
    o = report["overall"]
    lines.append("| **mean** | " + " | ".join(_fmt(o.get(c)) for c in cols) + " |")
    lines += ["", f"{o['share_within_1cm']:.0%} of {o['problems']} problems within 1 cm. `seconds` is the wall time of "
              "the problem's batch; seconds per problem (batch wall time / batch size): "
              f"{_fmt(o['seconds_per_problem'])}.", ""]
    return "\n".join(lines)


def plot_traces(results: list[Result]) -> bytes:
    """PNG: goal error (cm, log scale) against wall time, one line per problem."""
    import matplotlib  # loaded only when a plot is drawn

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4), dpi=100)
    for r in results:
        if r.trace:
            t, e, _ = zip(*r.trace)
            ax.plot(t, np.maximum(e, 1e-3), lw=1, label=r.problem.name)
    ax.axhline(1.0, color="gray", ls="--", lw=0.8)
    ax.set_yscale("log")
    ax.set_xlabel("wall time (s)")
    ax.set_ylabel("goal error (cm)")
    if len(results) <= 10:
        ax.legend(fontsize=7)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    plt.close(fig)
    return buf.getvalue()
