"""ReachJoint evaluation: run a policy on joint-goal files and measure each joint's error at its goal time.

Each entry of a file (:func:`latentrl.envs.reach_joint.load_joint_goals`, suites in ``tasks/joint_goals/``,
format in docs/joint_goals.md) runs ``settings.episodes`` envs in one batch until its last goal is due. A
goal's error is the joint's distance to its target at the goal frame (xy for 2-D targets), as the env
measures it; a goal is *near* when it is due at most one step (8 frames, 0.267 s) after the previous goal
(or the episode start), *far* otherwise.

A foot goal is a footstep: its touchdown is the contact onset of that foot (a frame in contact, foot joint
below ``contact_height_m``, after one that is not) nearest to the goal frame, between the previous goal's
frame and the next goal's (the episode's end for the last); the footstep error is the foot's xy distance to
the target at that frame. A footstep without a touchdown there is missed.

Metrics of an episode:

- ``success``: every goal reached: within ``radius_m`` at its time, footsteps at their touchdown;
- ``err_near_cm`` / ``err_far_cm``: mean error at the goal time of the near / far goals (cm);
- ``footstep_err_cm``: mean touchdown error of the footsteps reached or not (the goal-time error where missed);
- ``steps_reached``: share of footsteps touched down within ``radius_m``; ``reached``: share of all goals;
- ``skate_cm_s``, ``floor_cm``: DART's metrics (:func:`~latentrl.evaluation.metrics.episode_metrics`; with a
  scene, over the terrain under each foot);
- with a scene (``latentrl eval --scene``): ``collision``, ``scene_penetration_cm``, ``scene_penetration_max_cm``
  (:func:`~latentrl.scenes.contact.scene_metrics`). A footstep's touchdown is judged against the ground under the
  foot (a stone on a box top touches down on the box).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from latentrl.constants import CONTACT_HEIGHT_M
from latentrl.envs.reach_joint import FEET, JOINTS, JointGoalEntry, ReachJointConfig, ReachJointEnv, load_joint_goals
from latentrl.evaluation import metrics as M
from latentrl.evaluation.config import EvalSettings
from latentrl.evaluation.episodes import end_of, rollout
from latentrl.evaluation.task_eval import (
    TaskEpisode,
    TaskResult,
    episode_clip,
    goal_scene,
    run_each,
    scene_row,
    with_scene_metrics,
)
from latentrl.motion.representation import FUTURE_LENGTH, HISTORY_LENGTH
from latentrl.motion.skeleton import FPS, PELVIS
from latentrl.render import GOAL_JOINT_COLOURS

UNITS = {"success": "share", "err_near_cm": "cm", "err_far_cm": "cm", "footstep_err_cm": "cm",
         "steps_reached": "share", "reached": "share", "skate_cm_s": "cm/s", "floor_cm": "cm",
         "pj_seam": "m/frame^3"}
"""Metric -> unit, in report order."""


@dataclass
class JointGoalCriteria:
    """What "reached" means (report.json records it)."""

    radius_m: float = 0.1
    """A goal is reached within this many metres of its target at its time (a footstep at its touchdown)."""
    contact_height_m: float = CONTACT_HEIGHT_M
    """A foot touches the floor below this height (DART's 3 cm)."""
    late_limit_s: float = 2.0
    """Episodes stop this long after the last goal time (asap goals: after it is due)."""


DEFINITIONS = """\
- err_near_cm / err_far_cm: the joint's distance to its target at the goal time (xy for 2-D targets), for goals due
  within one step (0.267 s) of the previous goal or the start / later.
- footstep_err_cm: the foot's xy distance to its target at touchdown (the contact onset nearest the goal time);
  steps_reached: share of footsteps touched down within the radius; reached: share of all goals within it.
- success: every goal reached. skate_cm_s, floor_cm: DART's foot skate and floor distance over the episode.
- pj_seam: DART's peak jerk at the primitive boundaries (m/frame^3; episodes of 4 primitives or more)."""


@dataclass
class JointGoalResult(TaskResult):
    """A :class:`~latentrl.evaluation.task_eval.TaskResult` with its entry and each episode's pelvis track (plot)."""

    entry: JointGoalEntry | None = None
    tracks: list[np.ndarray] = field(default_factory=list)
    scenes: list[str | None] = field(default_factory=list)
    """Each episode's scene JSON (None: the flat floor), drawn in paths.png."""


# --------------------------------------------------------------------------- kernels
def clip_frame(goal_frame: int) -> int:
    """Index in an episode's clip (seed history first) of frame ``goal_frame`` (1-based from the start)."""
    return HISTORY_LENGTH - 1 + int(goal_frame)


def touchdown(heights: np.ndarray, frame: int, low: int, high: int, contact_height: float) -> int | None:
    """The contact onset of one foot nearest to clip frame ``frame`` within ``(low, high]``, or None.

    ``heights``: (T,) the foot joint's height above the floor per clip frame.
    """
    down = heights < contact_height
    onsets = [t for t in range(max(low + 1, 1), min(high, len(heights) - 1) + 1) if down[t] and not down[t - 1]]
    return min(onsets, key=lambda t: (abs(t - frame), t)) if onsets else None


def goal_metrics(joints: np.ndarray, entry: JointGoalEntry, frames: Sequence[int], criteria: JointGoalCriteria,
                 floor: float = 0.0, terrain: Any = None) -> tuple[dict[str, float | None], dict[str, Any]]:
    """The metrics of one episode (module docstring) from its clip joints and each goal's frame (-1: never due).

    ``joints``: (T, 22, 3) world joints of the clip, seed history first; ``terrain``: the episode's one-row scene
    (None: the flat floor), which adds the scene metrics.
    """
    j = np.asarray(joints, dtype=np.float64)
    ground = (np.full(j.shape[:2], floor) if terrain is None else
              M.terrain_floor(torch.as_tensor(j, dtype=torch.float32), terrain, floor).double().numpy())
    last = len(j) - 1
    errors, steps, near = [], [], []
    previous = 0
    for k, (goal, frame) in enumerate(zip(entry.goals, frames)):
        if frame < 0 or clip_frame(frame) > last:
            errors.append(None)
            near.append(False)
            if goal.joint in FEET:
                steps.append(None)
            continue
        t = clip_frame(frame)
        target = np.asarray(goal.target, dtype=np.float64)
        at = j[t, JOINTS[goal.joint], : len(target)]
        errors.append(float(np.linalg.norm(at - target)))
        near.append(frame - previous <= FUTURE_LENGTH)
        if goal.joint in FEET:
            following = [f for f in frames[k + 1:] if f >= 0]
            high = clip_frame(following[0]) if following else last
            foot = j[:, JOINTS[goal.joint]]
            onset = touchdown(foot[:, 2] - ground[:, JOINTS[goal.joint]], t, clip_frame(previous), high,
                              criteria.contact_height_m)
            steps.append(None if onset is None else float(np.linalg.norm(foot[onset, :2] - target)))
        previous = frame
    feet = [g.joint in FEET for g in entry.goals]
    hit = []
    step_iter = iter(steps)
    for is_foot, err in zip(feet, errors):
        value = next(step_iter) if is_foot else err
        hit.append(value is not None and value <= criteria.radius_m)
    foot_err = [s if s is not None else e for s, e in zip(steps, [e for e, f in zip(errors, feet) if f])]
    foot_err = [e for e in foot_err if e is not None]
    near_err = [e * 100 for e, n in zip(errors, near) if e is not None and n]
    far_err = [e * 100 for e, n in zip(errors, near) if e is not None and not n]
    quality = M.episode_metrics(joints, FPS, floor, terrain)
    metrics = {
        "success": float(all(hit)),
        "err_near_cm": float(np.mean(near_err)) if near_err else None,
        "err_far_cm": float(np.mean(far_err)) if far_err else None,
        "footstep_err_cm": float(np.mean(foot_err)) * 100 if foot_err else None,
        "steps_reached": float(np.mean([s is not None and s <= criteria.radius_m for s in steps])) if steps else None,
        "reached": float(np.mean(hit)),
        "skate_cm_s": quality["skate_cm_s"],
        "floor_cm": quality["floor_cm"],
        "pj_seam": quality.get("pj_seam"),  # None for an episode under 4 primitives
    }
    with_scene_metrics(metrics, joints, terrain)
    detail = {"error_cm": [None if e is None else e * 100 for e in errors],
              "touchdown_err_cm": [None if s is None else s * 100 for s in steps], "frame": list(map(int, frames))}
    return metrics, detail


# --------------------------------------------------------------------------- running
def make_env(motion, entry: JointGoalEntry, num_envs: int, settings: EvalSettings, record_history: bool = False,
             max_steps: int | None = None) -> ReachJointEnv:
    """The evaluation env: every env runs ``entry``, no autoreset, the policy's guidance and bound.

    ``settings.scene`` (``latentrl eval --scene``: a scene file or name, or random obstacles, drawn clear of the
    start and the first goal) puts objects around the goals; the policy observes them only when it was trained with
    a scene (``settings.observe_scene``).
    """
    scene = goal_scene(settings, "joint goals")
    return ReachJointEnv(num_envs, motion=motion, goals=[entry], texts=(entry.text,), device=settings.device,
                         max_episode_steps=max_steps or settings.max_steps, autoreset_mode="Disabled",
                         record_history=record_history, **settings.motion_kwargs(), **settings.scene_kwargs(scene))


def budget(entry: JointGoalEntry, settings: EvalSettings, criteria: JointGoalCriteria, max_speed: float) -> int:
    """Steps until ``late_limit_s`` after the last goal could be due, at most ``settings.max_steps``.

    Asap goals are counted at ``max_speed`` over the straight lines between consecutive targets (and from the
    start), which bounds when the env makes them due.
    """
    t, at = 0.0, np.zeros(2)
    for goal in entry.goals:
        xy = np.asarray(goal.target[:2])
        t = goal.time if goal.time is not None else t + float(np.linalg.norm(xy - at)) / max_speed + 2 / FPS
        at = xy
    return min(settings.max_steps, math.ceil((t + criteria.late_limit_s) * FPS / FUTURE_LENGTH))


def entry_label(entry: JointGoalEntry) -> str:
    """How reports name an entry: its text, goal count, joints and last time."""
    joints = ", ".join(dict.fromkeys(g.joint for g in entry.goals))
    timed = [g.time for g in entry.goals if g.time is not None]
    when = f", last at {timed[-1]:g} s" if len(timed) == len(entry.goals) else ", asap goals"
    return f"{entry.text}, {len(entry.goals)} goals ({joints}){when}"


def run_entry(act: Callable, motion, entry: JointGoalEntry, settings: EvalSettings, *, suite: str = "joint_goals",
              index: int = 0, criteria: JointGoalCriteria | None = None, seed: int = 0,
              sink: Callable[[TaskEpisode, Any], str | None] | None = None,
              wrap: Callable[[Any, Callable], Callable] | None = None) -> JointGoalResult:
    """``settings.episodes`` episodes of one entry in one batch.

    ``wrap(env, act) -> act``: a policy function that also reads the env (``latentrl.optim.refine``).
    """
    criteria = criteria or JointGoalCriteria()
    t0 = time.perf_counter()
    steps_max = budget(entry, settings, criteria, ReachJointConfig.max_speed)
    env = make_env(motion, entry, settings.episodes, settings, record_history=True, max_steps=steps_max)
    outcome = rollout(env, act if wrap is None else wrap(env, act), steps_max, seed)
    _, frames = env.goal_record()
    episodes, tracks, scenes = [], [], []
    for i in range(settings.episodes):
        steps = int(outcome["steps"][i])
        clip = episode_clip(env, i, steps)
        metrics, detail = goal_metrics(clip.joints, entry, frames[i].tolist(), criteria, env.floor_height,
                                       scene_row(env, i))
        ep = TaskEpisode(suite, index, i, end_of(outcome, i), steps, metrics, detail)
        if sink is not None:
            clip.waypoints = np.asarray([(*g.target[:2], g.target[2] if not g.planar else env.floor_height)
                                         for g in entry.goals], np.float32)
            clip.meta["waypoint_joints"] = np.asarray([JOINTS[g.joint] for g in entry.goals], np.int32)  # SMPL
            ep.motion_file = sink(ep, clip)
        episodes.append(ep)
        tracks.append(np.asarray(clip.joints)[:, PELVIS, :2].copy())
        scenes.append(clip.scene)
    env.close()
    return JointGoalResult(suite, index, entry_label(entry), episodes, time.perf_counter() - t0, entry, tracks,
                           scenes)


def run_suites(act: Callable, motion, files: Sequence[str | Path], settings: EvalSettings, *,
               criteria: JointGoalCriteria | None = None, sink=None,
               progress: Callable[[TaskResult], None] | None = None,
               wrap: Callable[[Any, Callable], Callable] | None = None) -> list[tuple[str, str, list[TaskResult]]]:
    """Every entry of every file (all files are parsed first); ``[(suite name, file, results)]``."""
    settings.validate()
    return run_each(files, load_joint_goals, lambda entry, **where: run_entry(
        act, motion, entry, settings, criteria=criteria, sink=sink, wrap=wrap, **where), settings.seed, progress)


def training_eval_hook(files: Sequence[str | Path], motion, env_cfg: Any, eval_cfg: Any, device: str = "cpu"):
    """The trainer's periodic evaluation of a ReachJoint policy on ``files``: ``policy -> EvalReport``.

    Reports the overall means of :data:`UNITS` and stops the run at ``eval_cfg.success_target``.
    """
    from latentrl.evaluation.task_eval import training_hook

    for file in files:
        load_joint_goals(file)
    return training_hook(lambda act, settings, sink=None: run_suites(act, motion, files, settings, sink=sink),
                         env_cfg, eval_cfg, device, success="success")


# --------------------------------------------------------------------------- figure
JOINT_COLORS = {name: tuple(c / 255 for c in rgb) for name, rgb in GOAL_JOINT_COLOURS.items()}
"""matplotlib colours (0-1) of :data:`latentrl.render.GOAL_JOINT_COLOURS`."""


def goals_figure(suites: Sequence[tuple[str, str, list]], columns: int = 4):
    """A matplotlib figure with one panel per entry: pelvis tracks and goal targets, from above.

    Tracks are green for a success, red otherwise; each goal's target is a marker coloured by its joint, numbered.
    Scene objects are grey footprints, as in the path evaluation's paths.png.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    from latentrl.evaluation.plots import draw_scenes

    results = [r for _, _, rs in suites for r in rs if getattr(r, "entry", None) is not None]
    cols = max(1, min(columns, len(results)))
    rows = max(1, math.ceil(len(results) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 3.2 * rows), squeeze=False)
    for ax, r in zip(axes.flat, results):
        draw_scenes(ax, r.scenes)
        for ep, track in zip(r.episodes, r.tracks):
            ax.plot(track[:, 0], track[:, 1], color="tab:green" if ep.metrics["success"] else "tab:red", lw=0.8,
                    alpha=0.45)
        for k, g in enumerate(r.entry.goals):
            marker = "x" if g.joint in FEET else "o"
            ax.plot(g.target[0], g.target[1], marker, color=JOINT_COLORS[g.joint], ms=6, mfc="none", zorder=3)
            if len(r.entry.goals) <= 30:
                ax.annotate(str(k), g.target[:2], xytext=(3, 3), textcoords="offset points", fontsize=6, zorder=4)
        wins = sum(ep.metrics["success"] for ep in r.episodes)
        ax.set_title(f"{r.suite} / {r.index}: {wins:g}/{len(r.episodes)} succeeded", fontsize=8)
        ax.set_aspect("equal", adjustable="datalim")
        ax.tick_params(labelsize=6)
        ax.grid(alpha=0.3)
    for ax in list(axes.flat)[len(results):]:
        ax.axis("off")
    used = dict.fromkeys(g.joint for r in results for g in r.entry.goals)
    handles = [Line2D([], [], ls="none", marker="x" if j in FEET else "o", mfc="none", color=JOINT_COLORS[j], label=j)
               for j in used]
    fig.legend(handles=handles, loc="upper center", ncol=max(1, len(handles)), fontsize=8, frameon=False)
    fig.supxlabel("x (m)", fontsize=8)
    fig.supylabel("y (m)", fontsize=8)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.25 / (3.2 * rows)))
    return fig


def save_png(path: str | Path, suites: Sequence[tuple[str, str, list]], columns: int = 4, dpi: int = 110) -> Path:
    """Write :func:`goals_figure` as paths.png (through a fresh temporary file, then renamed)."""
    import matplotlib.pyplot as plt

    from latentrl.safe_io import atomic_write_with

    fig = goals_figure(suites, columns)
    try:
        return atomic_write_with(path, lambda tmp: fig.savefig(tmp, dpi=dpi, format="png"))
    finally:
        plt.close(fig)
