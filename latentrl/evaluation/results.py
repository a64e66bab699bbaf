"""What an evaluation produces: its settings and the per-episode, per-path and per-suite results.

Plain data shared by :mod:`~latentrl.evaluation.runner` (which fills it), :mod:`~latentrl.evaluation.report`
and :mod:`~latentrl.evaluation.plots` (which read it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from latentrl.envs.path import WaypointPath
from latentrl.motion.representation import FUTURE_LENGTH, HISTORY_LENGTH

__all__ = ["EpisodeResult", "PathResult", "SuiteResult", "frames_after"]


def frames_after(steps: int) -> int:
    """Frames of an episode after ``steps`` primitives: the 2 seed frames + 8 per primitive (DART counts both)."""
    return HISTORY_LENGTH + FUTURE_LENGTH * int(steps)


@dataclass
class EpisodeResult:
    """One episode of one path. Times in seconds (frames / 30, seed frames included)."""

    suite: str
    path_index: int
    episode: int
    success: bool
    end: str
    """'success', 'timeout' (budget spent), 'diverged' (motion blew up) or 'lost' (beyond terminate_distance)."""
    steps: int
    """Primitives until the episode ended (the budget for timeouts)."""
    reach_time_s: float
    """Time to the final waypoint; the budget time for failures (censored, so failures are not hidden)."""
    waypoint_times_s: list[float | None]
    """Time each waypoint was reached; None where it was not."""
    final_dist_m: float
    """DART's ``dist``: min over the last 8 frames of the pelvis xy distance to the final waypoint."""
    metrics: dict[str, float]
    """:func:`latentrl.evaluation.metrics.episode_metrics` of the whole episode."""
    pelvis_xy: np.ndarray = field(repr=False)
    """(T, 2) pelvis track, world metres (for plots; not written to JSON)."""
    motion_file: str | None = None
    segments: list[dict] = field(default_factory=list)
    """Per waypoint segment, whether the motion matched its text (:func:`latentrl.evaluation.skills.judge_clip`)."""
    scene: str | None = None
    """The episode's scene as ``latentrl.scene/1`` JSON text (None: the flat floor); ``paths.png`` draws it."""


@dataclass
class PathResult:
    """Every episode of one path of a suite, and the wall time they took."""

    suite: str
    index: int
    path: WaypointPath
    episodes: list[EpisodeResult]
    wall_s: float


@dataclass
class SuiteResult:
    """Every path of one suite file, in file order."""

    name: str
    """File stem, e.g. ``dart_walk_long``."""
    file: str
    paths: list[PathResult]


def prompts_label(texts) -> str:
    """A path's prompts in order of first use, e.g. ``walk, run`` (what report.md, paths.png and the summary show)."""
    return ", ".join(dict.fromkeys(str(t) for t in texts))
