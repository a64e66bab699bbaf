"""What the Joystick and TimedPath evaluations share: the batch rollout, the results and the report.

Both run each entry of a suite file (a command timeline, a timed path) as one batch of
``settings.episodes`` envs without autoreset, as the path runner does for FollowPath, and score
every episode with a flat dict of metrics. The report aggregates them per entry, per suite and over
everything as ``{"mean", "ci95"}`` (:func:`~latentrl.evaluation.metrics.mean_ci95`), and is written as
``report.json`` (format :data:`FORMAT`) and ``report.md``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from latentrl.envs.scene import resolve_scene
from latentrl.errors import ConfigError
from latentrl.evaluation.metrics import mean_ci95
from latentrl.evaluation.video import recorder_for, takes_sink
from latentrl.scenes.contact import scene_metrics
from latentrl.scenes.courses import CoursePool
from latentrl.scenes.spec import scene_to_json

FORMAT = "latentrl.eval.task/1"
"""``report.json`` format of the Joystick and TimedPath evaluations."""


@dataclass
class TaskEpisode:
    """One episode of one suite entry: how it ended and its metrics (None where undefined)."""

    suite: str
    index: int
    episode: int
    end: str
    """'complete' (the timeline ran out or every waypoint was passed), 'timeout', 'diverged' or 'lost'."""
    steps: int
    metrics: dict[str, float | None]
    detail: dict[str, Any] = field(default_factory=dict)
    """Per-command or per-waypoint values (settle times, arrival errors) for report.json."""
    motion_file: str | None = None


@dataclass
class TaskResult:
    """Every episode of one entry (a timeline or a timed path) of a suite file."""

    suite: str
    index: int
    label: str
    episodes: list[TaskEpisode]
    wall_s: float


def run_each(
    files: Sequence[str | Path], load: Callable[[Path], list], run_one: Callable[..., TaskResult], seed: int,
    progress: Callable[[TaskResult], None] | None = None,
) -> list[tuple[str, str, list[TaskResult]]]:
    """Every item (timeline, timed path) of every file, all files parsed first: ``[(suite, file, results)]``.

    ``run_one(item, suite=, index=, seed=)`` evaluates one item; each gets its own seed from the suite
    name and index (:func:`~latentrl.evaluation.runner.path_seed`), as the path evaluation does.
    """
    from latentrl.evaluation.runner import path_seed

    loaded = [(Path(f), load(Path(f))) for f in files]
    out = []
    for file, items in loaded:
        results = []
        for index, item in enumerate(items):
            results.append(run_one(item, suite=file.stem, index=index, seed=path_seed(seed, file.stem, index)))
            if progress is not None:
                progress(results[-1])
        out.append((file.stem, str(file), results))
    return out


def episode_clip(env, i: int, steps: int):
    """Env i's recorded episode cut at its end (envs keep stepping until the whole batch is done).

    With a scene the clip carries env i's scene (its JSON), so that ``latentrl view`` and the importers show it.
    """
    clip = env.export_clip(i, episode=0).cut(steps)
    clip.meta.pop("from_reset", None)
    if env.scene is not None:
        clip.scene = scene_to_json(env.scene.scene_of(i))
    return clip


def goal_scene(settings: Any, entries: str):
    """``settings.scene`` resolved for an evaluation of ``entries`` ("timed paths"): a scene, random obstacles or None.

    Course pools (random mazes, random stairs) come with their own routes, which these entries cannot follow:
    refused in one line.
    """
    scene = resolve_scene(settings.scene) if settings.scene is not None else None
    if isinstance(scene, CoursePool):
        raise ConfigError(f"scene: {scene.kind} brings its own routes (path suites); {entries} take a scene file "
                          "or random_obstacles")
    return scene


def scene_row(env, i: int):
    """Env i's scene as a one-row batch (the terrain of its floor metrics), None on the flat floor."""
    return env.scene.row(i) if env.scene is not None else None


def with_scene_metrics(metrics: dict[str, float | None], joints, row) -> dict[str, float | None]:
    """``metrics`` plus the scene metrics of ``joints`` (T, 22, 3) in scene ``row`` (:data:`SCENE_UNITS`)."""
    if row is not None:
        metrics.update(scene_metrics(np.asarray(joints, dtype=np.float32), row))
    return metrics


# --------------------------------------------------------------------------- report
def aggregate(episodes: Sequence[TaskEpisode]) -> dict[str, dict[str, float]]:
    """Metric -> ``{"mean", "ci95", "n"}`` over the episodes that define it (None values left out)."""
    names = dict.fromkeys(k for ep in episodes for k in ep.metrics)
    out = {}
    for name in names:
        values = [ep.metrics[name] for ep in episodes if ep.metrics.get(name) is not None]
        values = [float(v) for v in values if math.isfinite(float(v))]
        out[name] = {**mean_ci95(values), "n": len(values)}
    return out


SCENE_UNITS = {"collision": "share", "scene_penetration_cm": "cm", "scene_penetration_max_cm": "cm"}
"""Units of the scene metrics (:func:`latentrl.scenes.contact.scene_metrics`), reported when episodes carry them."""


def build_task_report(task: str, suites: Sequence[tuple[str, str, list[TaskResult]]], settings: Any,
                      metric_units: dict[str, str], definitions: str, **extra: Any) -> dict[str, Any]:
    """``report.json`` content: per entry, per suite and overall aggregates, and every episode.

    The units are ``metric_units``, and :data:`SCENE_UNITS` when the episodes ran in a scene.
    """
    everything = [ep for _, _, results in suites for r in results for ep in r.episodes]
    scene = {k: u for k, u in SCENE_UNITS.items() if any(k in ep.metrics for ep in everything)}
    return {
        "format": FORMAT,
        "task": task,
        "settings": asdict(settings),
        "units": {**metric_units, **scene},
        "definitions": definitions,
        "overall": aggregate(everything),
        "suites": [
            {"name": name, "file": file, "overall": aggregate([ep for r in results for ep in r.episodes]),
             "entries": [{"index": r.index, "label": r.label, "wall_s": r.wall_s, "metrics": aggregate(r.episodes),
                          "episodes": [_episode_entry(ep) for ep in r.episodes]} for r in results]}
            for name, file, results in suites
        ],
        **extra,
    }


def _episode_entry(ep: TaskEpisode) -> dict[str, Any]:
    return {"episode": ep.episode, "end": ep.end, "steps": ep.steps, "metrics": ep.metrics, "detail": ep.detail,
            "motion_file": ep.motion_file}


def _finite(obj: Any) -> Any:
    """NaN and inf become None so that report.json is strict JSON."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, (np.floating, np.integer)):
        return _finite(obj.item())
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    return obj


def _fmt(m: dict[str, float] | None) -> str:
    if not m or m.get("mean") is None or not math.isfinite(m["mean"]):
        return "-"
    ci = m.get("ci95")
    return f"{m['mean']:.2f} ± {ci:.2f}" if ci is not None and math.isfinite(ci) else f"{m['mean']:.2f}"


def results_table(report: dict[str, Any]) -> list[str]:
    """The markdown table of report.md: one row per entry, then per suite, then overall."""
    units = report["units"]
    keys = list(units)
    lines = ["| suite | entry | " + " | ".join(f"{k} ({u})" for k, u in units.items()) + " |",
             "|---|---|" + "---|" * len(keys)]
    for suite in report["suites"]:
        for entry in suite["entries"]:
            cells = [_fmt(entry["metrics"].get(k)) for k in keys]
            lines.append(f"| {suite['name']} | {entry['index']}: {entry['label']} | " + " | ".join(cells) + " |")
        lines.append(f"| **{suite['name']}** | all | " + " | ".join(_fmt(suite["overall"].get(k)) for k in keys) + " |")
    lines.append("| **all** | | " + " | ".join(_fmt(report["overall"].get(k)) for k in keys) + " |")
    return lines


def write_task_report(out_dir: str | Path, report: dict[str, Any]) -> tuple[Path, Path]:
    """Write ``report.json`` and ``report.md`` into ``out_dir``."""
    import json

    from latentrl.safe_io import atomic_write_text

    out_dir = Path(out_dir)
    js = atomic_write_text(out_dir / "report.json", json.dumps(_finite(report), indent=1) + "\n")
    md = [f"# {report['task']} evaluation", "", *results_table(report), "", "Mean ± 95% CI over episodes "
          "(1.96 std / sqrt(n)).", "", report["definitions"]]
    return js, atomic_write_text(out_dir / "report.md", "\n".join(md) + "\n")


def training_hook(run: Callable[[Callable, Any], list], env_cfg: Any, eval_cfg: Any, device: str,
                  success: str | None = None):
    """``policy -> EvalReport`` from a suite runner ``run(act, settings)``: the overall finite means.

    Settings come from ``eval_cfg`` (episodes, max_steps, deterministic) and ``env_cfg`` (guidance,
    action bound); the run stops once the mean of ``success`` reaches ``eval_cfg.success_target``.
    """
    from latentrl.evaluation.config import EvalSettings

    settings = EvalSettings(episodes=eval_cfg.episodes, max_steps=eval_cfg.max_steps,
                            deterministic=eval_cfg.deterministic, device=str(device))
    settings.take_training_env(env_cfg)
    settings.take_eval_config(eval_cfg)
    settings.validate()
    target = getattr(eval_cfg, "success_target", None)
    recorder = recorder_for(eval_cfg) if takes_sink(run) else None

    def evaluate(policy: torch.nn.Module):
        from latentrl.evaluation.episodes import collect_returns
        from latentrl.evaluation.runner import policy_fn
        from latentrl.monitor import EvalReport

        with collect_returns() as returns:
            act = policy_fn(policy, settings.deterministic)
            due = recorder is not None and recorder.start()
            suites = run(act, settings, sink=recorder.sink) if due else run(act, settings)
        pooled = aggregate([ep for _, _, results in suites for r in results for ep in r.episodes])
        metrics = {k: v["mean"] for k, v in pooled.items() if math.isfinite(v["mean"])}
        if returns:
            metrics["mean_reward"] = sum(returns) / len(returns)
        stop = target is not None and success is not None and metrics.get(success, 0.0) >= target
        return EvalReport(metrics, {}, stop, recorder.videos() if recorder is not None else {})

    return evaluate
