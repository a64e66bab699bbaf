"""What an evaluation produces: its settings and the per-episode, per-path and per-suite results.

Plain data shared by :mod:`~latentrl.evaluation.runner` (which fills it), :mod:`~latentrl.evaluation.report`
and :mod:`~latentrl.evaluation.plots` (which read it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from latentrl.config import require
from latentrl.envs.path import WaypointPath
from latentrl.motion.representation import FUTURE_LENGTH, HISTORY_LENGTH
from latentrl.motion.skeleton import FPS


@dataclass
class EvalSettings:
    """How an evaluation runs; stored in ``report.json`` under ``settings``."""

    episodes: int = 32
    """Episodes per path, run in parallel as one batch (DART: 32 envs)."""
    max_steps: int = 256
    """Step budget per episode in primitives of 8 frames (DART's ``num_steps`` 256 = 68.3 s, enough for
    its longest walking path, 36 m, at half of DART's walking speed). Episodes still running are failures."""
    deterministic: bool = False
    """Use the policy's mean action instead of sampling (DART samples)."""
    seed: int = 0
    """Base seed; each path gets its own seed derived from it, the file stem and the path index."""
    device: str = "cpu"
    guidance_scale: float = 5.0
    """Classifier-free guidance of the motion model (DART's ``guidance_param``)."""
    success_threshold: float = 0.3
    """Waypoint radius, metres (xy, pelvis); DART 0.3."""

    def validate(self) -> None:
        require(self.episodes >= 1, "episodes", f"must be >= 1, got {self.episodes}")
        require(self.max_steps >= 1, "max_steps", f"must be >= 1, got {self.max_steps}")
        require(self.success_threshold > 0, "success_threshold", f"must be > 0, got {self.success_threshold}")

    @property
    def budget_s(self) -> float:
        """The reach time a failed episode gets: the frames of a full budget (seed frames included) / 30."""
        return frames_after(self.max_steps) / FPS


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


@dataclass
class PathResult:
    suite: str
    index: int
    path: WaypointPath
    episodes: list[EpisodeResult]
    wall_s: float


@dataclass
class SuiteResult:
    name: str
    """File stem, e.g. ``dart_walk_long``."""
    file: str
    paths: list[PathResult]
