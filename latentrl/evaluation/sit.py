"""Sit / get-up evaluation: each seat of a seat file (``latentrl/tasks/sit/``) gets ``settings.episodes`` episodes.

An episode is a :class:`~latentrl.envs.sit.SitEnv` episode with that seat and the default success definitions
(:class:`SitCriteria`, CLoSD's protocol made kinematic), run until the get-up or the step budget. Metrics of an
episode:

- ``sit_success``: 1 when the pelvis held the seated pose (within ``sit_radius`` of the seat centre and
  ``height_tolerance`` of the seated height) for ``hold_frames`` frames, else 0;
- ``getup_success``: 1 when it then stood up and walked ``leave_distance`` from the seat, else 0;
- ``getup_after_sit``: the same, over the episodes that sat (None without a sit): CLoSD's get-up task starts
  seated, so its get-up rate compares with this one;
- ``sit_time_s``: seconds from the start to the sit success (None without one);
- ``scene_penetration_max_cm``: the deepest joint inside its skin radius of the seat (a seated pelvis sits
  0.09 m above the seat top, 1 cm inside its 0.10 m skin);
- ``skate_cm_s``, ``floor_cm``: DART's metrics against the ground under each joint.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from latentrl.envs.sit import SeatSpec, SitEnv, load_seats
from latentrl.evaluation import metrics as M
from latentrl.evaluation.config import EvalSettings
from latentrl.evaluation.episodes import end_of, rollout
from latentrl.evaluation.task_eval import TaskEpisode, TaskResult, episode_clip, run_each
from latentrl.motion.skeleton import FPS
from latentrl.scenes.contact import scene_metrics

UNITS = {"sit_success": "share", "getup_success": "share", "getup_after_sit": "share", "sit_time_s": "s",
         "scene_penetration_max_cm": "cm", "skate_cm_s": "cm/s", "floor_cm": "cm"}
"""Metric -> unit, in report order."""

DEFINITIONS = """\
- sit_success: the pelvis held within sit_radius (xy) of the seat centre and height_tolerance of the seated
  height (seat top + 0.09 m) for hold_frames frames in a row.
- getup_success: after sitting, the pelvis back at stand_fraction of its standing height and leave_distance (xy)
  from the seat centre (the episode ends there).
- getup_after_sit: getup_success over the episodes that sat (CLoSD's get-up task starts seated: its rate compares
  with this one).
- sit_time_s: seconds from the start to the sit success; scene_penetration_max_cm: the deepest joint inside its
  skin radius of the seat; skate_cm_s, floor_cm: DART's metrics on the terrain.
- Kinematic: no physics pushes the body out of the seat (CLoSD's numbers are in physics)."""


@dataclass
class SitCriteria:
    """The success definitions an evaluation uses (report.json records them; the env's defaults)."""

    sit_radius: float = 0.3
    height_tolerance: float = 0.05
    hold_frames: int = 15
    leave_distance: float = 0.6
    stand_fraction: float = 0.9


def make_env(motion, seat: SeatSpec, num_envs: int, settings: EvalSettings, record_history: bool = False,
             criteria: SitCriteria | None = None) -> SitEnv:
    """The evaluation env: every env sits on ``seat``, no autoreset, the policy's step settings and height grid."""
    criteria = criteria or SitCriteria()
    grid = {"height_grid": settings.height_grid, "height_grid_spacing": settings.height_grid_spacing} \
        if settings.height_grid else {}
    return SitEnv(num_envs, motion=motion, seats=[seat], device=settings.device, max_episode_steps=settings.max_steps,
                  autoreset_mode="Disabled", record_history=record_history, **dataclasses.asdict(criteria),
                  **settings.motion_kwargs(), **grid)


def seat_label(seat: SeatSpec) -> str:
    """How reports name a seat: its height, distance from the start and facing."""
    dist = (seat.center[0] ** 2 + seat.center[1] ** 2) ** 0.5
    return f"seat {seat.seat_height:.2f} m high, {dist:.1f} m away, facing {seat.facing_deg:g} deg"


def run_seat(act: Callable, motion, seat: SeatSpec, settings: EvalSettings, *, suite: str = "sit", index: int = 0,
             criteria: SitCriteria | None = None, seed: int = 0,
             sink: Callable[[TaskEpisode, Any], str | None] | None = None,
             wrap: Callable[[Any, Callable], Callable] | None = None) -> TaskResult:
    """``settings.episodes`` episodes on one seat in one batch (``wrap``: as ``runner.run_path``'s)."""
    t0 = time.perf_counter()
    env = make_env(motion, seat, settings.episodes, settings, record_history=True, criteria=criteria)
    sat_step = torch.zeros(settings.episodes, dtype=torch.long)

    def note(k: int, infos: dict, live: torch.Tensor) -> None:
        first = infos["sit_success"].cpu() & live.cpu() & (sat_step == 0)
        sat_step[first] = k

    outcome = rollout(env, act if wrap is None else wrap(env, act), settings.max_steps, seed, on_step=note)
    episodes = []
    for i in range(settings.episodes):
        steps = int(outcome["steps"][i])
        clip = episode_clip(env, i, steps)
        joints = torch.as_tensor(clip.joints)
        quality = M.episode_metrics(joints, FPS, env.floor_height, env.scene.row(i))
        sat = int(sat_step[i]) > 0
        got_up = float(bool(outcome["complete"][i]))
        metrics = {"sit_success": float(sat), "getup_success": got_up, "getup_after_sit": got_up if sat else None,
                   "sit_time_s": int(sat_step[i]) * 8 / FPS if sat else None,
                   "scene_penetration_max_cm": scene_metrics(joints, env.scene.row(i))["scene_penetration_max_cm"],
                   "skate_cm_s": quality["skate_cm_s"], "floor_cm": quality["floor_cm"]}
        ep = TaskEpisode(suite, index, i, end_of(outcome, i), steps, metrics)
        if sink is not None:
            from latentrl.scenes.spec import scene_to_json

            clip.scene = scene_to_json(env.scene.scene_of(i))
            ep.motion_file = sink(ep, clip)
        episodes.append(ep)
    env.close()
    return TaskResult(suite, index, seat_label(seat), episodes, time.perf_counter() - t0)


def run_suites(act: Callable, motion, files: Sequence[str | Path], settings: EvalSettings, *,
               criteria: SitCriteria | None = None, sink=None,
               progress: Callable[[TaskResult], None] | None = None,
               wrap: Callable[[Any, Callable], Callable] | None = None) -> list[tuple[str, str, list[TaskResult]]]:
    """Every seat of every file (all files parsed first); ``[(suite name, file, results)]``."""
    settings.validate()
    return run_each(files, load_seats, lambda seat, **where: run_seat(
        act, motion, seat, settings, criteria=criteria, sink=sink, wrap=wrap, **where), settings.seed, progress)


def training_eval_hook(files: Sequence[str | Path], motion, env_cfg: Any, eval_cfg: Any, device: str = "cpu"):
    """The trainer's periodic evaluation of a sit policy on ``files``: ``policy -> EvalReport``.

    Training stops once ``getup_success`` reaches ``eval.success_target``.
    """
    from latentrl.evaluation.task_eval import training_hook

    for file in files:
        load_seats(file)
    return training_hook(lambda act, settings, sink=None: run_suites(act, motion, files, settings, sink=sink),
                         env_cfg, eval_cfg, device, success="getup_success")


def seat_suite(count: int = 12, seed: int = 20261128) -> list[SeatSpec]:
    """The shipped ``sit_seats`` suite: ``count`` seats with heights evenly spread over 0.2-0.6 m.

    Each lies 1.5-3 m from the start within 60 degrees of its forward axis (+y) and faces a seeded random direction.
    """
    import math
    import random

    rng = random.Random(seed)
    seats = []
    for k in range(count):
        height = 0.2 + 0.4 * k / max(count - 1, 1)
        angle, dist = math.radians(90.0 + rng.uniform(-60.0, 60.0)), rng.uniform(1.5, 3.0)
        seats.append(SeatSpec((round(dist * math.cos(angle), 3), round(dist * math.sin(angle), 3)), round(height, 3),
                              round(rng.uniform(-180.0, 180.0), 1)))
    return seats


def seat_file_text(seats: Sequence[SeatSpec]) -> str:
    """A seat file, one seat per line (stable text, so the shipped file can be compared)."""
    import json

    rows = [json.dumps({"center": list(s.center), "seat_height": s.seat_height, "facing_deg": s.facing_deg})
            for s in seats]
    return "[\n" + ",\n".join(f"  {r}" for r in rows) + "\n]\n"


if __name__ == "__main__":
    from latentrl.resources import suites_folder
    from latentrl.safe_io import atomic_write_text

    print(f"wrote {atomic_write_text(suites_folder('sit') / 'sit_seats.json', seat_file_text(seat_suite()))}")
