"""FollowPath: waypoints with a text each, DART's path-file format, random smooth training paths.

Path files are DART's ``data/test_locomotion/*.json``: a JSON list of paths, each
``{"goal_location": [[x, y, z], ...], "goal_text": ["walk", ...]}`` in the world frame (metres,
z up, the episode starts with the pelvis at the origin facing +y; only xy is used). A path may add
``"scene"``: the scene it runs in (a ``latentrl.scene/1`` file beside the path file, in ``tasks/scenes`` by
name, or inline; docs/scenes.md), so a maze or a staircase travels with the paths through it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from latentrl.config import require
from latentrl.envs.base import LatentMotionVectorEnv
from latentrl.envs.goal import body_forward
from latentrl.errors import DataError, closest
from latentrl.motion.skeleton import PELVIS
from latentrl.motion.text import prompt_problem
from latentrl.safe_io import read_json_file

_PATH_FIELDS = ("goal_location", "goal_text")
_OPTIONAL_FIELDS = ("scene",)
MAX_WAYPOINTS = 10_000
"""Most waypoints per path (DART's suites have 2-20); every env keeps a padded (W, 3) copy of its path."""
MAX_FILE_BYTES = 64 << 20
"""Largest path file read (64 MiB, about a million waypoints of JSON)."""
MAX_PATHS = 1_000
"""Most paths per file (DART's suites have 1-5); each path is its own evaluated rollout."""
MAX_COORD_M = 10_000.0
"""Waypoint coordinates beyond +/- this many metres are refused (episodes end 100 m from the goal anyway)."""


@dataclass(frozen=True)
class WaypointPath:
    """One path: waypoints (world metres, start pelvis at the origin facing +y) and a text per waypoint."""

    waypoints: tuple[tuple[float, float, float], ...]
    texts: tuple[str, ...]
    scene: Any = field(default=None, kw_only=True)
    """The :class:`~latentrl.scenes.Scene` the path runs in (its ``"scene"`` field); None: the evaluation's own."""


NEXT_AT_LAST = ("repeat", "extend")
"""What ``next_goal_*`` observes at a path's last waypoint (:class:`FollowPathEnv`'s ``next_at_last``)."""


def next_at_last_problem(value: str) -> str | None:
    """Why ``value`` cannot be ``next_at_last`` (the env's and the configs' one check), or None."""
    return None if value in NEXT_AT_LAST else f"must be 'repeat' or 'extend', got {value!r}"


def load_paths(file: str | Path) -> list[WaypointPath]:
    """Read a DART path file; errors name the file, path index, waypoint index and field (0-based)."""
    data = read_json_file(file, "path file", MAX_FILE_BYTES, DataError)
    return parse_paths(data, str(file), Path(file).parent)


def parse_paths(data: Any, source: str = "paths", base: Path | None = None) -> list[WaypointPath]:
    """Validate DART's path structure (already parsed from JSON) into :class:`WaypointPath` s.

    ``base``: the folder a path's ``scene`` file name is looked up in first (the path file's).
    """
    if not isinstance(data, list):
        raise DataError(
            f"{source}: expected a list of paths like "
            f'[{{"goal_location": [[x, y, z], ...], "goal_text": [...]}}], got {type(data).__name__}'
        )
    if not data:
        raise DataError(f"{source}: holds no paths")
    if len(data) > MAX_PATHS:
        raise DataError(f"{source}: {len(data)} paths, more than the {MAX_PATHS} a path file may hold; "
                        "split it into several files")
    return [_parse_path(item, f"{source}: path {i}", base) for i, item in enumerate(data)]


def _parse_scene(value: Any, where: str, base: Path | None) -> Any:
    """A path's ``scene`` field as a fixed :class:`~latentrl.scenes.Scene` (a file beside the path file, a name)."""
    from latentrl.envs.scene import resolve_scene
    from latentrl.errors import LatentRLError
    from latentrl.scenes.scene import Scene

    if not isinstance(value, (str, dict)):
        raise DataError(f"{where}: field 'scene' must be a scene file name or a latentrl.scene/1 object, "
                        f"got {type(value).__name__}")
    if isinstance(value, str) and base is not None and (base / value).is_file():
        value = str(base / value)
    try:
        scene = resolve_scene(value)
    except LatentRLError as exc:
        raise DataError(f"{where}: field 'scene': {exc}") from None
    if not isinstance(scene, Scene):
        raise DataError(f"{where}: field 'scene' must be a fixed scene (random_obstacles is an env setting)")
    return scene


def _parse_path(item: Any, where: str, base: Path | None = None) -> WaypointPath:
    if not isinstance(item, dict):
        raise DataError(f"{where}: expected an object with fields {list(_PATH_FIELDS)}, got {type(item).__name__}")
    for key in item:
        if key not in _PATH_FIELDS + _OPTIONAL_FIELDS:
            raise DataError(
                f"{where}: unknown field '{key}'{closest(key, _PATH_FIELDS + _OPTIONAL_FIELDS)}; expected "
                f"{list(_PATH_FIELDS)} and optionally {list(_OPTIONAL_FIELDS)}"
            )
    for key in _PATH_FIELDS:
        if key not in item:
            raise DataError(f"{where}: missing field '{key}'")
    points, texts = item["goal_location"], item["goal_text"]
    if not isinstance(points, list) or not points:
        raise DataError(f"{where}: field 'goal_location' must be a non-empty list of [x, y, z], got {points!r:.80}")
    if not isinstance(texts, list):
        raise DataError(f"{where}: field 'goal_text' must be a list of strings, got {type(texts).__name__}")
    if len(texts) != len(points):
        raise DataError(f"{where}: field 'goal_text' has {len(texts)} entries for {len(points)} waypoints")
    if len(points) > MAX_WAYPOINTS:
        raise DataError(f"{where}: {len(points)} waypoints, more than the {MAX_WAYPOINTS} a path may have; "
                        "split it into several paths")
    waypoints = []
    for j, (point, text) in enumerate(zip(points, texts)):
        ok = isinstance(point, list) and len(point) == 3
        ok = ok and all(isinstance(v, (int, float)) and not isinstance(v, bool) and -MAX_COORD_M <= v <= MAX_COORD_M
                        for v in point)  # compares ints exactly (no float overflow) and refuses nan/inf
        if not ok:
            raise DataError(f"{where}, waypoint {j}: field 'goal_location' must be [x, y, z] finite numbers within "
                            f"+/-{MAX_COORD_M:g} m, got {str(point)[:80]}")
        if not isinstance(text, str) or not text.strip():
            raise DataError(f"{where}, waypoint {j}: field 'goal_text' must be a non-empty string, got {text!r:.80}")
        if prompt_problem(text) is not None:
            raise DataError(f"{where}, waypoint {j}: field 'goal_text': {prompt_problem(text)}")
        waypoints.append(tuple(float(v) for v in point))
    scene = _parse_scene(item["scene"], where, base) if item.get("scene") is not None else None
    return WaypointPath(tuple(waypoints), tuple(texts), scene=scene)


class FollowPathEnv(LatentMotionVectorEnv):
    """Follow a sequence of waypoints, switching text at each one.

    ## Description

    The motion model is driven as in :class:`~latentrl.envs.reach.ReachLocationEnv`, but the
    goal is the current waypoint of a path. When the pelvis passes within
    ``success_threshold`` (xy) of it during a step, the next waypoint becomes the goal and its
    text becomes the conditioning text; reaching the last waypoint ends the episode with
    ``is_success``. Paths come from DART's path files (evaluation suites in ``tasks/paths/``)
    or, for training, are random smooth paths generated at reset from the env's generator.

    ## Action Space

    ``Box(-action_bound, action_bound, (D,), float32)``, as for ReachLocation.

    ## Observation Space

    ``Box(-inf, inf, (G + E + 552 + 1,), float32)``; G = 4, or 8 with ``observe_next``:

    =====================  ==============  ====================================================
    slice                  name            meaning
    =====================  ==============  ====================================================
    [0:3]                  goal_dir        direction to the current waypoint (DART's clipped,
                                           canonical-frame direction, as in ReachLocation)
    [3:4]                  goal_dist       xy distance to it, metres, clipped at 5
    [4:7] (observe_next)   next_goal_dir   the same for the following waypoint (at the last
    [7:8] (observe_next)   next_goal_dist  waypoint: itself again, or with ``next_at_last=
                                           "extend"`` a point one last-segment length beyond it)
    [G:G+E]                text            embedding of the current waypoint's text
    [G+E:G+E+552]          motion          2 x 276 unnormalized canonical history features
    [G+E+552:G+E+553]      scene           floor z minus the pelvis z of history frame 0, metres
    =====================  ==============  ====================================================

    ## Rewards

    As ReachLocation, toward the current waypoint; ``success`` is 1 at every waypoint reached.

    ## Starting State

    As ReachLocation; the path is drawn uniformly (``path_assignment="random"``) or env i takes
    path ``i % P`` (``"by_env"``, for evaluation suites). Random paths start at the pelvis and
    turn by up to ``random_turn_deg`` per waypoint, with segments uniform in ``random_segment``.

    ## Episode End

    - Termination: the last waypoint is reached (``is_success``), the pelvis is farther than
      ``terminate_distance`` from the current waypoint, or the motion diverged.
    - Truncation: ``max_episode_steps`` (256, DART's evaluation budget).

    ## Arguments

    ``paths`` (``None`` = random, a path file, or a list of :class:`WaypointPath`),
    ``path_assignment``, ``observe_next``, ``next_at_last`` ("repeat" or "extend": what
    ``next_goal_*`` shows at the last waypoint), ``random_waypoints`` (5), ``random_segment``
    ((1.0, 3.0) m), ``random_turn_deg`` (45), ``text_per_waypoint`` (random paths: a text per
    waypoint instead of per path); the rest are :class:`~latentrl.envs.base.LatentMotionVectorEnv`'s.
    With a course pool as the scene (``{"random_mazes": {...}}``, ``{"random_stairs": {...}}``) each episode draws a
    course of the pool and walks its route (a maze's cell centres, a staircase's flights, from the origin; ``paths``
    must be unset), with a text drawn per episode.

    ## Version History

    - v0: initial version.
    """

    walks_courses = True

    def __init__(
        self,
        num_envs: int = 1,
        *,
        paths: str | Path | Sequence[WaypointPath] | None = None,
        path_assignment: str = "random",
        observe_next: bool = False,
        next_at_last: str = "repeat",
        random_waypoints: int = 5,
        random_segment: Sequence[float] = (1.0, 3.0),
        random_turn_deg: float = 45.0,
        text_per_waypoint: bool = False,
        max_episode_steps: int = 256,
        **kwargs,
    ):
        if isinstance(paths, (str, Path)):
            paths = load_paths(paths)
        self.paths: list[WaypointPath] | None = None if paths is None else list(paths)
        require(self.paths is None or len(self.paths) > 0, "paths", "give at least one path (or None for random)")
        require(
            path_assignment in ("random", "by_env"),
            "path_assignment",
            f"expected 'random' or 'by_env', got {path_assignment!r}",
        )
        problem = next_at_last_problem(next_at_last)
        require(problem is None, "next_at_last", str(problem))
        require(int(random_waypoints) >= 1, "random_waypoints", f"must be >= 1, got {random_waypoints}")
        lo, hi = (float(v) for v in random_segment)
        require(0 < lo <= hi, "random_segment", f"must be (min, max) metres with 0 < min <= max, got {random_segment}")
        require(0 <= random_turn_deg <= 180, "random_turn_deg", f"must be in [0, 180], got {random_turn_deg}")
        self.path_assignment = path_assignment
        self.observe_next = bool(observe_next)
        self.next_at_last = next_at_last
        self.random_waypoints = int(random_waypoints)
        self.random_segment = (lo, hi)
        self.random_turn_deg = float(random_turn_deg)
        self.text_per_waypoint = bool(text_per_waypoint)
        if self.observe_next:
            self.goal_fields = (*type(self).goal_fields, ("next_goal_dir", 3), ("next_goal_dist", 1))
        super().__init__(num_envs, max_episode_steps=max_episode_steps, **kwargs)
        if self._courses:
            require(self.paths is None, "paths",
                    f"{self.scene.spec.kind} brings its own paths (each course's route); leave paths unset")
        self._setup_paths()

    def _all_texts(self, texts: tuple[str, ...]) -> tuple[str, ...]:
        return texts + tuple(t for p in self.paths or () for t in p.texts)

    @property
    def _courses(self) -> list:
        """The course pool of a ``random_mazes`` or ``random_stairs`` scene (empty without one)."""
        return self.scene.courses if self.scene is not None else []

    def _setup_paths(self) -> None:
        """Padded (P, W, 3) waypoints, (P, W) text ids and (P,) lengths; per-env copies (N, W, ...).

        With random mazes the P paths are the pool's routes (z on the floor), walked with a drawn text.
        """
        n, dev = self.num_envs, self.device
        routes = [[(x, y, self.floor_height) for x, y in c.waypoints] for c in self._courses]
        if self.paths is None and not routes:
            width = self.random_waypoints
            self._path_points = None
        else:
            points = routes or [p.waypoints for p in self.paths]
            width = max(len(p) for p in points)
            self._path_points = torch.zeros(len(points), width, 3, device=dev)
            self._path_texts = torch.zeros(len(points), width, dtype=torch.long, device=dev)
            self._path_len = torch.tensor([len(p) for p in points], device=dev)
            for i, p in enumerate(points):
                self._path_points[i, : len(p)] = torch.tensor(p, dtype=torch.float32, device=dev)
            for i, p in enumerate(self.paths or ()):
                self._path_texts[i, : len(p.texts)] = torch.tensor([self.texts.index(t) for t in p.texts], device=dev)
        self._wp = torch.zeros(n, width, 3, device=dev)
        self._wp_text = torch.zeros(n, width, dtype=torch.long, device=dev)
        self._wp_len = torch.ones(n, dtype=torch.long, device=dev)
        self._wp_index = torch.zeros(n, dtype=torch.long, device=dev)
        self._wp_beyond = torch.zeros(n, 3, device=dev)
        self._rows = torch.arange(n, device=dev)

    # ------------------------------------------------------------------ paths
    def _random_paths(self, idx: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(M, W, 3) waypoints, (M, W) text ids, (M,) lengths of smooth random paths from the current body."""
        m, w = len(idx), self.random_waypoints
        forward, pelvis = body_forward(self.history_world(idx)[:, -1])
        turn = math.radians(self.random_turn_deg)
        turns = self._uniform(m * w, -turn, turn).view(m, w)
        heading = torch.atan2(forward[:, 1], forward[:, 0])[:, None] + turns.cumsum(1)
        length = self._uniform(m * w, *self.random_segment).view(m, w, 1)
        xy = pelvis[:, None, :2] + (torch.stack((heading.cos(), heading.sin()), -1) * length).cumsum(1)
        points = torch.cat((xy, torch.full_like(xy[..., :1], self.floor_height)), -1)
        if self.text_per_waypoint:
            texts = self._sample_texts(m * w).view(m, w)
        else:
            texts = self._sample_texts(m)[:, None].expand(m, w)
        return points, texts, torch.full((m,), w, dtype=torch.long, device=self.device)

    def _choose_paths(self, idx: torch.Tensor) -> torch.Tensor:
        """(M,) index into :attr:`paths` for envs ``idx``: ``i % P`` (``by_env``) or drawn uniformly."""
        p = len(self.paths)
        if self.path_assignment == "by_env":
            return idx % p
        return torch.randint(p, (len(idx),), generator=self._generator, device=self.device)

    def _reset_task(self, idx: torch.Tensor) -> None:
        if self._path_points is None:
            points, texts, lengths = self._random_paths(idx)
        elif self._courses:  # a maze per episode, and its route
            pid = self.scene.draw(idx, self._generator)
            points, lengths = self._path_points[pid], self._path_len[pid]
            texts = self._sample_texts(len(idx))[:, None].expand(-1, points.shape[1])
        else:
            pid = self._choose_paths(idx)
            points, texts, lengths = self._path_points[pid], self._path_texts[pid], self._path_len[pid]
        self._wp[idx] = points
        self._wp_text[idx] = texts
        self._wp_len[idx] = lengths
        self._wp_index[idx] = 0
        self._wp_beyond[idx] = self._point_beyond(idx, points, lengths)
        self._text_idx[idx] = texts[:, 0]

    def _point_beyond(self, idx: torch.Tensor, points: torch.Tensor, lengths: torch.Tensor) -> torch.Tensor:
        """(M, 3) what ``next_goal_*`` shows at the last waypoint.

        The last one again (``repeat``) or the last segment continued by its own length (``extend``), so
        that the last goal looks like a straight stretch of path instead of an input met only at the end.
        """
        rows = torch.arange(len(idx), device=self.device)
        last = points[rows, lengths - 1]
        if self.next_at_last == "repeat":
            return last
        start = self.history_world(idx)[:, -1, PELVIS].clone()
        start[:, 2] = last[:, 2]
        before = torch.where((lengths > 1)[:, None], points[rows, (lengths - 2).clamp(min=0)], start)
        return last + (last - before)

    # ------------------------------------------------------------------ task hooks
    def _waypoint(self, offset: int = 0) -> torch.Tensor:
        """(N, 3) the waypoint ``offset`` after the current one; past the last, :meth:`_point_beyond`'s."""
        k = self._wp_index + offset
        point = self._wp[self._rows, torch.minimum(k, self._wp_len - 1)]
        if offset == 0:
            return point
        return torch.where((k >= self._wp_len)[:, None], self._wp_beyond, point)

    @property
    def goal_world(self) -> torch.Tensor:
        """(N, 3) the current waypoint, world metres."""
        return self._waypoint()

    @property
    def waypoint_index(self) -> torch.Tensor:
        """(N,) index of the waypoint each env is heading to (= waypoints reached this episode)."""
        return self._wp_index.clone()

    def _goal_observation(self, history_world: torch.Tensor) -> torch.Tensor:
        obs = self._goal_features(history_world, self._waypoint())
        if self.observe_next:
            obs = torch.cat((obs, self._goal_features(history_world, self._waypoint(1))), dim=1)
        return obs

    def _advance_task(self, reached: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Reached waypoints advance the index and switch the text; the last one ends the episode."""
        was_finished = self._wp_index >= self._wp_len
        self._wp_index = torch.minimum(self._wp_index + reached.long(), self._wp_len)
        finished = self._wp_index >= self._wp_len
        switch = reached & ~finished
        self._text_idx = torch.where(
            switch, self._wp_text[self._rows, self._wp_index.clamp(max=self._wp.shape[1] - 1)], self._text_idx
        )
        return finished, finished & ~was_finished

    def _task_infos(self, infos: dict[str, Any], reached: torch.Tensor) -> None:
        infos["waypoint_reached"] = reached
        infos["waypoint_index"] = self._wp_index.clone()
        infos["_waypoint_reached"] = infos["_waypoint_index"] = self._all
