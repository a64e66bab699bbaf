"""TimedPath: waypoints with arrival times; arrive at each on time, not only at all.

Timed path files are DART's path files with one more field, ``goal_time``: the arrival time of each
waypoint in seconds from the episode start (the start of its first step), strictly increasing::

    [{"goal_location": [[0, 3, 0], [3, 3, 0]], "goal_text": ["walk", "walk"], "goal_time": [3.0, 6.0]}]

A waypoint's arrival time is that of the first new frame whose pelvis lies within
``success_threshold`` (xy) of it: frame j (0-based) of step k is at ``(8 k + j + 1) / 30`` s.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from latentrl.config import is_finite_number, require
from latentrl.envs.joystick import STEP_SECONDS
from latentrl.envs.path import MAX_FILE_BYTES, FollowPathEnv, WaypointPath, parse_paths
from latentrl.errors import DataError, closest
from latentrl.motion.representation import FUTURE_LENGTH
from latentrl.motion.skeleton import FPS, PELVIS
from latentrl.rewards.compose import COMMON_TERMS
from latentrl.safe_io import read_json_file

_FIELDS = ("goal_location", "goal_text", "goal_time")
MAX_TIME_S = 3600.0
"""Arrival times beyond this many seconds are refused."""


@dataclass(frozen=True)
class TimedPath(WaypointPath):
    """A :class:`~latentrl.envs.path.WaypointPath` with an arrival time per waypoint (seconds, increasing)."""

    times: tuple[float, ...] = ()


def load_timed_paths(file: str | Path) -> list[TimedPath]:
    """Read a timed path file; errors name the file, path index, waypoint index and field (0-based)."""
    data = read_json_file(file, "timed path file", MAX_FILE_BYTES, DataError)
    return parse_timed_paths(data, str(file))


def parse_timed_paths(data: Any, source: str = "timed paths") -> list[TimedPath]:
    """Validate parsed JSON: DART's path fields (:func:`~latentrl.envs.path.parse_paths`) plus ``goal_time``."""
    if not isinstance(data, list):
        raise DataError(f'{source}: expected a list of paths like [{{"goal_location": [[x, y, z], ...], '
                        f'"goal_text": [...], "goal_time": [seconds, ...]}}], got {type(data).__name__}')
    times = []
    for i, item in enumerate(data):
        where = f"{source}: path {i}"
        if not isinstance(item, dict):
            raise DataError(f"{where}: expected an object with fields {list(_FIELDS)}, got {type(item).__name__}")
        for key in item:
            if key not in _FIELDS:
                raise DataError(f"{where}: unknown field '{key}'{closest(str(key), _FIELDS)}; expected {list(_FIELDS)}")
        if "goal_time" not in item:
            raise DataError(f"{where}: missing field 'goal_time' (arrival seconds per waypoint)")
        times.append(item["goal_time"])
    paths = parse_paths([{k: v for k, v in item.items() if k != "goal_time"} for item in data], source)
    return [TimedPath(p.waypoints, p.texts, _parse_times(t, len(p.waypoints), f"{source}: path {i}"))
            for i, (p, t) in enumerate(zip(paths, times))]


def _parse_times(times: Any, count: int, where: str) -> tuple[float, ...]:
    if not isinstance(times, list):
        raise DataError(f"{where}: field 'goal_time' must be a list of seconds, got {type(times).__name__}")
    if len(times) != count:
        raise DataError(f"{where}: field 'goal_time' has {len(times)} entries for {count} waypoints")
    last = 0.0
    for j, t in enumerate(times):
        if not is_finite_number(t) or not last < t <= MAX_TIME_S:
            raise DataError(f"{where}, waypoint {j}: field 'goal_time' must be seconds after the previous "
                            f"arrival ({last:g}) and at most {MAX_TIME_S:g}, got {t!r:.80}")
        last = float(t)
    return tuple(float(t) for t in times)


def timed_observation(current: torch.Tensor, time_left: torch.Tensor, clip: float,
                      following: torch.Tensor | None = None) -> torch.Tensor:
    """(N, 5 or 9) ``[goal features | time_left clipped to +-clip | next goal features]``, pure for the ONNX export.

    ``current`` and ``following`` (None: not observed) are (N, 4) goal features, ``time_left`` (N,) seconds.
    """
    obs = torch.cat((current, time_left.clamp(-clip, clip)[:, None]), dim=1)
    return obs if following is None else torch.cat((obs, following), dim=1)


class TimedPathEnv(FollowPathEnv):
    """Follow waypoints and reach each at its arrival time.

    ## Description

    :class:`~latentrl.envs.path.FollowPathEnv` whose waypoints carry arrival times (seconds from the
    episode start). Reaching a waypoint (pelvis within ``success_threshold``) advances to the next
    one whatever the time; the arrival error (arrival - goal time; early < 0) is reported in
    ``infos["arrival_error_s"]`` and rewarded by ``timing``. Training paths are random smooth paths
    (FollowPath's generator) whose segments are timed at a speed drawn per segment from ``speed_range``.

    ## Observation Space

    FollowPath's goal fields, then ``time_left`` (seconds until the current waypoint's arrival time,
    negative when late, clipped to +-``time_left_clip``), then ``next_goal_*`` with ``observe_next``;
    then text, motion and scene.

    ## Rewards

    DART's terms toward the current waypoint (``dist``, ``success``, ``foot_floor``, ``skate``,
    ``orient``, ``rotation``, ``jerk``), ``pace`` (-|speed toward the waypoint - distance left / time
    left|, the target clipped to ``speed_range[1]``; ``speed_range[1]`` once the time is up) and
    ``timing`` (on arrival, 1 - |arrival error| / ``rewards.timing_tolerance``, at least 0).

    ## Arguments

    ``paths`` (``None`` = random, a timed path file, or a list of :class:`TimedPath`), ``speed_range``
    ((0.7, 1.4) m/s: walking), ``time_left_clip`` (10 s) and FollowPath's other arguments.
    """

    goal_fields = (("goal_dir", 3), ("goal_dist", 1), ("time_left", 1))
    reward_terms = ("dist", "success", "foot_floor", "skate", "orient", "rotation", "jerk", "pace", "timing",
                    *COMMON_TERMS)
    walks_courses = False  # a maze route has no arrival times

    def __init__(
        self,
        num_envs: int = 1,
        *,
        paths: str | Path | Sequence[TimedPath] | None = None,
        speed_range: Sequence[float] = (0.7, 1.4),
        time_left_clip: float = 10.0,
        **kwargs,
    ):
        lo, hi = (float(v) for v in speed_range)
        require(0 < lo <= hi, "speed_range", f"must be (min, max) m/s with 0 < min <= max, got {tuple(speed_range)}")
        require(time_left_clip > 0, "time_left_clip", f"must be > 0 seconds, got {time_left_clip}")
        if isinstance(paths, (str, Path)):
            paths = load_timed_paths(paths)
        for i, p in enumerate(paths or ()):
            require(isinstance(p, TimedPath) and len(p.times) == len(p.waypoints), "paths",
                    f"path {i} has no arrival time per waypoint; give TimedPath objects or a timed path file")
        self.speed_range = (lo, hi)
        self.time_left_clip = float(time_left_clip)
        super().__init__(num_envs, paths=paths, **kwargs)
        n, dev = self.num_envs, self.device
        self._wp_time = torch.zeros(n, self._wp.shape[1], device=dev)
        self._arrival_error = torch.zeros(n, device=dev)
        if self.paths is not None:
            self._path_times = torch.zeros(len(self.paths), self._wp.shape[1], device=dev)
            for i, p in enumerate(self.paths):
                self._path_times[i, : len(p.times)] = torch.tensor(p.times, device=dev)

    def _reset_task(self, idx: torch.Tensor) -> None:
        super()._reset_task(idx)
        if self.paths is None:
            start = self.history_world(idx)[:, -1, PELVIS, :2]
            points = torch.cat((start[:, None], self._wp[idx, :, :2]), dim=1)
            segments = (points[:, 1:] - points[:, :-1]).norm(dim=-1)  # (M, W)
            speed = self._uniform(segments.numel(), *self.speed_range).view_as(segments)
            self._wp_time[idx] = (segments / speed).cumsum(dim=1)
        else:
            self._wp_time[idx] = self._path_times[self._path_id[idx]]

    def _choose_paths(self, idx: torch.Tensor) -> torch.Tensor:
        pid = super()._choose_paths(idx)
        self._path_id[idx] = pid
        return pid

    def _setup_paths(self) -> None:
        super()._setup_paths()
        self._path_id = torch.zeros(self.num_envs, dtype=torch.long, device=self.device)

    # ------------------------------------------------------------------ timing
    def _goal_time(self) -> torch.Tensor:
        """(N,) arrival time of the current waypoint, seconds."""
        k = torch.minimum(self._wp_index, self._wp_len - 1)
        return self._wp_time[self._rows, k]

    def _time_left(self) -> torch.Tensor:
        """(N,) seconds from now (the end of the last step) to the current waypoint's arrival time."""
        return self._goal_time() - self._ep_len.float() * STEP_SECONDS

    def _goal_observation(self, history_world: torch.Tensor) -> torch.Tensor:
        following = self._goal_features(history_world, self._waypoint(1)) if self.observe_next else None
        return timed_observation(self._goal_features(history_world, self._waypoint()), self._time_left(),
                                 self.time_left_clip, following)

    def _reward_inputs(self, before, future, goal, reached) -> dict[str, torch.Tensor]:
        """The on-time speed toward the waypoint, and the arrival error of a waypoint reached in this step."""
        left = self._time_left()
        dist = (goal[:, :2] - before[:, -1, PELVIS, :2]).norm(dim=-1)
        hi = self.speed_range[1]
        target = torch.where(left > STEP_SECONDS / 2, dist / left.clamp(min=STEP_SECONDS / 2), hi).clamp(0.0, hi)
        near = (future[:, :, PELVIS, :2] - goal[:, None, :2]).norm(dim=-1) < self.success_threshold  # (N, 8)
        first = near.float().argmax(dim=1)  # the first frame within the radius (0 where none)
        arrival = (self._ep_len.float() * FUTURE_LENGTH + first + 1) / FPS
        self._arrival_error = torch.where(reached, arrival - self._goal_time(), 0.0)
        return {"target_speed": target, "arrival_error": self._arrival_error}

    def _task_infos(self, infos: dict[str, Any], reached: torch.Tensor) -> None:
        super()._task_infos(infos, reached)
        infos["arrival_error_s"] = self._arrival_error.clone()
        infos["time_left_s"] = self._time_left()
        infos["_arrival_error_s"] = infos["_time_left_s"] = self._all
