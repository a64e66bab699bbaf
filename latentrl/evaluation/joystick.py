"""Joystick evaluation: run a policy along command timelines and measure how well it tracks them.

Each timeline of a file (:func:`latentrl.envs.load_timelines`, suites in ``tasks/joystick/``) runs
``settings.episodes`` envs in one batch until its duration. Velocities are measured per step: the
pelvis displacement (xy) from the last frame before the step to its last new frame, over the step's
0.267 s, which averages out the sway of the gait. The command of a step is the one in force at
its start (what the policy observed).

Metrics of an episode:

- ``heading_err_deg``, ``speed_err_m_s``: mean absolute error of the step's direction of motion
  (degrees, wrapped to [0, 180]) and of its speed (m/s), over the steps that start at least
  ``settle_window_s`` after the latest command change (or the episode start): tracking once settled;
- ``settle_s``: mean over command changes of the time from the change to the end of the first step
  whose heading and speed errors are both within tolerance (``heading_tolerance_deg``,
  ``speed_tolerance_m_s``); ``unsettled``: the share of changes that never settle before the next;
- ``skate_cm_s``, ``floor_cm``: DART's metrics (:func:`~latentrl.evaluation.metrics.episode_metrics`; with a
  scene, over the terrain under each foot);
- with a scene (``latentrl eval --scene``, a scene file or name): ``collision``, ``scene_penetration_cm``,
  ``scene_penetration_max_cm`` (:func:`~latentrl.scenes.contact.scene_metrics`).
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

from latentrl.envs.joystick import STEP_SECONDS, CommandTimeline, JoystickEnv, load_timelines, world_angle
from latentrl.envs.scene import resolve_scene
from latentrl.errors import ConfigError
from latentrl.evaluation import metrics as M
from latentrl.evaluation.config import EvalSettings
from latentrl.evaluation.episodes import end_of, rollout
from latentrl.evaluation.task_eval import TaskEpisode, TaskResult, episode_clip, run_each, scene_row, with_scene_metrics
from latentrl.motion.representation import FUTURE_LENGTH, HISTORY_LENGTH
from latentrl.motion.skeleton import FPS, PELVIS
from latentrl.scenes.scene import Scene

UNITS = {"heading_err_deg": "deg", "speed_err_m_s": "m/s", "settle_s": "s", "unsettled": "share",
         "skate_cm_s": "cm/s", "floor_cm": "cm",
         "pj_seam": "m/frame^3"}
"""Metric -> unit, in report order."""


@dataclass
class TrackingCriteria:
    """What "settled" means (report.json records it)."""

    settle_window_s: float = 2.0
    """Tracking errors count from this long after each command change."""
    heading_tolerance_deg: float = 20.0
    """A step is on heading within this many degrees."""
    speed_tolerance_m_s: float = 0.3
    """A step is on speed within this many m/s."""


DEFINITIONS = """\
- heading_err_deg / speed_err_m_s: mean |error| of each step's direction of motion and speed (pelvis over the
  step's 0.267 s), counted from `settle_window_s` after each command change.
- settle_s: mean time from a command change to the end of the first step within both tolerances;
  unsettled: share of changes that never got there before the next change (they are left out of settle_s).
- skate_cm_s, floor_cm: DART's foot skate and floor distance over the whole episode.
- pj_seam: DART's peak jerk at the primitive boundaries (m/frame^3; episodes of 4 primitives or more)."""


# --------------------------------------------------------------------------- kernels
def step_velocity(joints, steps: int, fps: float = FPS) -> torch.Tensor:
    """(T, 22, 3) joints of an episode in the primitive layout -> (steps, 2) pelvis velocity per step, m/s."""
    j = torch.as_tensor(np.asarray(joints), dtype=torch.float32)
    frames = HISTORY_LENGTH - 1 + FUTURE_LENGTH * torch.arange(steps + 1)
    p = j[frames, PELVIS, :2]
    return (p[1:] - p[:-1]) * (fps / FUTURE_LENGTH)


def tracking_errors(velocity: torch.Tensor, heading_rad: torch.Tensor, speed: torch.Tensor
                    ) -> tuple[torch.Tensor, torch.Tensor]:
    """(S, 2) velocities, (S,) commanded world angles (from +x), speeds -> (S,) |heading error| deg, |speed error|."""
    moved = torch.atan2(velocity[:, 1], velocity[:, 0])
    diff = torch.remainder(moved - heading_rad + math.pi, 2 * math.pi) - math.pi
    return diff.abs().rad2deg(), (velocity.norm(dim=-1) - speed).abs()


def settle_times(ok: torch.Tensor, starts: Sequence[int], step_s: float = STEP_SECONDS) -> list[float | None]:
    """Per command starting at step ``starts[c]``: seconds to the end of its first ``ok`` step, None if none.

    A command runs until the next one starts (the last until the end of ``ok``).
    """
    out = []
    bounds = [*starts, len(ok)]
    for c in range(len(starts)):
        hits = ok[bounds[c]: bounds[c + 1]].nonzero()
        out.append(None if len(hits) == 0 else (int(hits[0, 0]) + 1) * step_s)
    return out


def command_schedule(timeline: CommandTimeline, steps: int) -> tuple[torch.Tensor, torch.Tensor, list[int]]:
    """(steps,) world angle and speed in force at each step's start, and the step at which each command starts."""
    at = [timeline.at(k * STEP_SECONDS) for k in range(steps)]
    angle = torch.tensor([world_angle(c[1]) for c in at], dtype=torch.float32)
    speed = torch.tensor([c[2] for c in at], dtype=torch.float32)
    starts = sorted({math.ceil(t / STEP_SECONDS - 1e-6) for t, _, _ in timeline.commands})
    return angle, speed, [s for s in starts if s < steps]


def joystick_metrics(joints, timeline: CommandTimeline, steps: int, criteria: TrackingCriteria,
                     floor: float = 0.0, terrain: Any = None) -> tuple[dict[str, float | None], dict[str, Any]]:
    """Every metric of one episode (module docstring) and its per-change settle times.

    ``terrain``: the episode's one-row scene (None: the flat floor), which adds the scene metrics.
    """
    velocity = step_velocity(joints, steps)
    angle, speed, starts = command_schedule(timeline, steps)
    head_err, speed_err = tracking_errors(velocity, angle, speed)
    since = torch.zeros(steps)
    for s in starts:
        since[s:] = torch.arange(steps - s, dtype=torch.float32) * STEP_SECONDS
    settled = since >= criteria.settle_window_s - 1e-6
    ok = (head_err <= criteria.heading_tolerance_deg) & (speed_err <= criteria.speed_tolerance_m_s)
    changes = settle_times(ok, starts)[1:]  # the first command starts the episode: it is not a change
    reached = [t for t in changes if t is not None]
    quality = M.episode_metrics(joints, FPS, floor, terrain)
    metrics = {
        "heading_err_deg": float(head_err[settled].mean()) if bool(settled.any()) else None,
        "speed_err_m_s": float(speed_err[settled].mean()) if bool(settled.any()) else None,
        "settle_s": float(np.mean(reached)) if reached else None,
        "unsettled": (len(changes) - len(reached)) / len(changes) if changes else None,
        "skate_cm_s": quality["skate_cm_s"],
        "floor_cm": quality["floor_cm"],
        "pj_seam": quality.get("pj_seam"),  # None for an episode under 4 primitives
    }
    return with_scene_metrics(metrics, joints, terrain), {"settle_s": changes}


# --------------------------------------------------------------------------- running
def make_env(motion, timeline: CommandTimeline, num_envs: int, settings: EvalSettings,
             record_history: bool = False) -> JoystickEnv:
    """The evaluation env: every env follows ``timeline``, no autoreset, the policy's guidance and bound.

    ``settings.scene`` (``latentrl eval --scene``) must be a fixed scene: random obstacles are cleared around the
    goal, and a joystick's goal is a point the command sweeps ahead of the body.
    """
    scene = resolve_scene(settings.scene) if settings.scene is not None else None
    if scene is not None and not isinstance(scene, Scene):
        raise ConfigError("scene: a joystick timeline takes a scene file or name (random obstacles and mazes are "
                          "drawn around goals, and the command's goal sweeps ahead of the body)")
    return JoystickEnv(num_envs, motion=motion, commands=[timeline], command_assignment="by_env",
                       texts=(timeline.text,), device=settings.device, max_episode_steps=timeline_steps(timeline),
                       autoreset_mode="Disabled", record_history=record_history, **settings.motion_kwargs(),
                       **settings.scene_kwargs(scene))


def timeline_steps(timeline: CommandTimeline) -> int:
    """Steps that cover the timeline's duration."""
    return max(1, math.ceil(timeline.duration / STEP_SECONDS - 1e-6))


def timeline_label(timeline: CommandTimeline) -> str:
    """How reports name a timeline: its text, command count and duration."""
    return f"{timeline.text}, {len(timeline.commands)} commands, {timeline.duration:g} s"


def run_timeline(act: Callable, motion, timeline: CommandTimeline, settings: EvalSettings, *, suite: str = "joystick",
                 index: int = 0, criteria: TrackingCriteria | None = None, seed: int = 0,
                 sink: Callable[[TaskEpisode, Any], str | None] | None = None,
                 wrap: Callable[[Any, Callable], Callable] | None = None) -> TaskResult:
    """``settings.episodes`` episodes of one timeline in one batch (``wrap``: as ``runner.run_path``'s)."""
    criteria = criteria or TrackingCriteria()
    t0 = time.perf_counter()
    env = make_env(motion, timeline, settings.episodes, settings, record_history=True)
    outcome = rollout(env, act if wrap is None else wrap(env, act), timeline_steps(timeline), seed)
    episodes = []
    for i in range(settings.episodes):
        steps = int(outcome["steps"][i])
        clip = episode_clip(env, i, steps)
        metrics, detail = joystick_metrics(clip.joints, timeline, steps, criteria, env.floor_height,
                                           scene_row(env, i))
        ep = TaskEpisode(suite, index, i, end_of(outcome, i), steps, metrics, detail)
        if sink is not None:
            ep.motion_file = sink(ep, clip)
        episodes.append(ep)
    env.close()
    return TaskResult(suite, index, timeline_label(timeline), episodes, time.perf_counter() - t0)


def run_suites(act: Callable, motion, files: Sequence[str | Path], settings: EvalSettings, *,
               criteria: TrackingCriteria | None = None, sink=None,
               progress: Callable[[TaskResult], None] | None = None,
               wrap: Callable[[Any, Callable], Callable] | None = None) -> list[tuple[str, str, list[TaskResult]]]:
    """Every timeline of every file (all files are parsed first); ``[(suite name, file, results)]``."""
    settings.validate()
    return run_each(files, load_timelines, lambda timeline, **where: run_timeline(
        act, motion, timeline, settings, criteria=criteria, sink=sink, wrap=wrap, **where), settings.seed, progress)


def training_eval_hook(files: Sequence[str | Path], motion, env_cfg: Any, eval_cfg: Any, device: str = "cpu"):
    """The trainer's periodic evaluation of a Joystick policy on ``files``: ``policy -> EvalReport``.

    Reports the overall means of :data:`UNITS` (``heading_err_deg``, ``speed_err_m_s``, ...); files are
    parsed now, not at the first evaluation.
    """
    from latentrl.evaluation.task_eval import training_hook

    for file in files:
        load_timelines(file)
    return training_hook(lambda act, settings, sink=None: run_suites(act, motion, files, settings, sink=sink),
                         env_cfg, eval_cfg, device)
