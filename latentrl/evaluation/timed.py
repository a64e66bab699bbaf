"""TimedPath evaluation: run a policy along timed paths and measure how punctually it arrives.

Each path of a file (:func:`latentrl.envs.load_timed_paths`, suites in ``tasks/timed/``) runs
``settings.episodes`` envs in one batch until every env passed its last waypoint, or until
``late_limit_s`` after the last arrival time (capped by ``settings.max_steps``). The arrival time
of a waypoint is that of the first frame within 0.3 m of it (the env's ``arrival_error_s``).

Metrics of an episode:

- ``success``: every waypoint reached (pelvis within ``settings.success_threshold``, 0.3 m) and
  every arrival within ``time_tolerance_s`` (1 s) of its time;
- ``arrival_err_s``: mean |arrival error| over the waypoints reached; ``late_s``: mean signed
  error (late > 0, early < 0); ``reached``: share of waypoints reached;
- ``skate_cm_s``, ``floor_cm``: DART's metrics (:func:`~latentrl.evaluation.metrics.episode_metrics`; with a
  scene, over the terrain under each foot);
- with a scene (``latentrl eval --scene``): ``collision``, ``scene_penetration_cm``, ``scene_penetration_max_cm``
  (:func:`~latentrl.scenes.contact.scene_metrics`).

report.json also keeps each waypoint's arrival error per episode (``detail.arrival_err_s``, None
where not reached).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from latentrl.envs.joystick import STEP_SECONDS
from latentrl.envs.timed import TimedPath, TimedPathEnv, load_timed_paths
from latentrl.evaluation import metrics as M
from latentrl.evaluation.config import EvalSettings
from latentrl.evaluation.episodes import end_of, rollout
from latentrl.evaluation.results import prompts_label
from latentrl.evaluation.task_eval import (
    TaskEpisode,
    TaskResult,
    episode_clip,
    goal_scene,
    run_each,
    scene_row,
    with_scene_metrics,
)
from latentrl.motion.skeleton import FPS

UNITS = {"success": "share", "arrival_err_s": "s", "late_s": "s", "reached": "share", "skate_cm_s": "cm/s",
         "floor_cm": "cm", "pj_seam": "m/frame^3"}
"""Metric -> unit, in report order."""


@dataclass
class TimingCriteria:
    """What "on time" means (report.json records it)."""

    time_tolerance_s: float = 1.0
    """A waypoint counts as on time within this many seconds of its arrival time."""
    late_limit_s: float = 10.0
    """Episodes stop this long after the last arrival time (or at ``settings.max_steps``)."""


DEFINITIONS = """\
- success: every waypoint reached (pelvis within 0.3 m) and each arrival within `time_tolerance_s` of its time.
- arrival_err_s: mean |arrival time - goal time| over the waypoints reached; late_s: the same, signed (late > 0).
- reached: share of waypoints reached; skate_cm_s, floor_cm: DART's metrics over the whole episode.
- pj_seam: DART's peak jerk at the primitive boundaries (m/frame^3; episodes of 4 primitives or more)."""


def timed_metrics(errors: Sequence[float | None], tolerance_s: float, joints,
                  floor: float = 0.0, terrain: Any = None) -> dict[str, float | None]:
    """The metrics of one episode from its per-waypoint arrival errors (None = not reached) and its joints.

    ``terrain``: the episode's one-row scene (None: the flat floor), which adds the scene metrics.
    """
    hit = [e for e in errors if e is not None]
    quality = M.episode_metrics(joints, FPS, floor, terrain)
    return with_scene_metrics({
        "success": float(len(hit) == len(errors) and all(abs(e) <= tolerance_s for e in hit)),
        "arrival_err_s": sum(abs(e) for e in hit) / len(hit) if hit else None,
        "late_s": sum(hit) / len(hit) if hit else None,
        "reached": len(hit) / len(errors),
        "skate_cm_s": quality["skate_cm_s"],
        "floor_cm": quality["floor_cm"],
        "pj_seam": quality.get("pj_seam"),  # None for an episode under 4 primitives
    }, joints, terrain)


def make_env(motion, path: TimedPath, num_envs: int, settings: EvalSettings, observe_next: bool = False,
             record_history: bool = False, max_steps: int | None = None) -> TimedPathEnv:
    """The evaluation env: every env follows ``path``, no autoreset, the policy's guidance and bound.

    ``settings.scene`` (``latentrl eval --scene``: a scene file or name, or random obstacles, drawn clear of the
    start and the first waypoint, then of each waypoint as it becomes the goal) puts objects along the path.
    """
    scene = goal_scene(settings, "timed paths")
    return TimedPathEnv(num_envs, motion=motion, paths=[path], path_assignment="by_env", observe_next=observe_next,
                        next_at_last=settings.next_at_last, texts=(path.texts[0],), device=settings.device,
                        max_episode_steps=max_steps or settings.max_steps, autoreset_mode="Disabled",
                        success_threshold=settings.success_threshold, record_history=record_history,
                        **settings.motion_kwargs(), **settings.scene_kwargs(scene))


def budget(path: TimedPath, settings: EvalSettings, criteria: TimingCriteria) -> int:
    """Steps until ``late_limit_s`` after the last arrival time, at most ``settings.max_steps``."""
    return min(settings.max_steps, math.ceil((path.times[-1] + criteria.late_limit_s) / STEP_SECONDS))


def run_path(act: Callable, motion, path: TimedPath, settings: EvalSettings, *, suite: str = "timed",
             index: int = 0, observe_next: bool = False, criteria: TimingCriteria | None = None, seed: int = 0,
             sink: Callable[[TaskEpisode, Any], str | None] | None = None,
             wrap: Callable[[Any, Callable], Callable] | None = None) -> TaskResult:
    """``settings.episodes`` episodes of one timed path in one batch (``wrap``: as ``runner.run_path``'s)."""
    criteria = criteria or TimingCriteria()
    t0 = time.perf_counter()
    steps_max = budget(path, settings, criteria)
    env = make_env(motion, path, settings.episodes, settings, observe_next, record_history=True, max_steps=steps_max)
    n, width = settings.episodes, len(path.waypoints)
    errors = torch.full((n, width), math.nan)

    def on_step(k: int, infos: dict, live: torch.Tensor) -> None:
        reached = (infos["waypoint_reached"] & live).cpu()
        wp = (infos["waypoint_index"].cpu() - 1).clamp(min=0)  # the index after advancing, minus the one reached
        rows = torch.arange(n)[reached]
        errors[rows, wp[reached]] = infos["arrival_error_s"].cpu()[reached]

    outcome = rollout(env, act if wrap is None else wrap(env, act), steps_max, seed, on_step)
    episodes = []
    for i in range(n):
        steps = int(outcome["steps"][i])
        clip = episode_clip(env, i, steps)
        errs = [None if math.isnan(e) else float(e) for e in errors[i].tolist()]
        metrics = timed_metrics(errs, criteria.time_tolerance_s, clip.joints, env.floor_height, scene_row(env, i))
        ep = TaskEpisode(suite, index, i, end_of(outcome, i), steps, metrics, {"arrival_err_s": errs})
        if sink is not None:
            clip.waypoints = np.asarray(path.waypoints, np.float32)
            ep.motion_file = sink(ep, clip)
        episodes.append(ep)
    env.close()
    label = f"{prompts_label(path.texts)}, {width} waypoints, {path.times[-1]:g} s"
    return TaskResult(suite, index, label, episodes, time.perf_counter() - t0)


def run_suites(act: Callable, motion, files: Sequence[str | Path], settings: EvalSettings, *,
               observe_next: bool = False, criteria: TimingCriteria | None = None, sink=None,
               progress: Callable[[TaskResult], None] | None = None,
               wrap: Callable[[Any, Callable], Callable] | None = None) -> list[tuple[str, str, list[TaskResult]]]:
    """Every path of every file (all files are parsed first); ``[(suite name, file, results)]``."""
    settings.validate()
    return run_each(files, load_timed_paths, lambda path, **where: run_path(
        act, motion, path, settings, observe_next=observe_next, criteria=criteria, sink=sink, wrap=wrap, **where),
        settings.seed, progress)


def training_eval_hook(files: Sequence[str | Path], motion, env_cfg: Any, eval_cfg: Any, device: str = "cpu"):
    """The trainer's periodic evaluation of a TimedPath policy on ``files``: ``policy -> EvalReport``.

    Reports the overall means of :data:`UNITS` and stops the run at ``eval_cfg.success_target``.
    """
    from latentrl.evaluation.task_eval import training_hook

    for file in files:
        load_timed_paths(file)
    observe_next = bool(getattr(env_cfg, "observe_next", False))
    return training_hook(lambda act, settings, sink=None: run_suites(act, motion, files, settings,
                                                                    observe_next=observe_next, sink=sink),
                         env_cfg, eval_cfg, device, success="success")
