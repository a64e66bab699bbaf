"""Our own waypoint path suites, generated deterministically and shipped as DART-format JSON.

DART's suites (``tasks/paths/dart_*.json``) test long straight and gently curved paths with one
skill each. These four add what they leave out:

- ``random_smooth``: five random smooth paths (seeded), 6 waypoints, segments of 2-4 m turning by up
  to 45 degrees, one skill per path (walk, run, hop, walk, run).
- ``sharp_turns``: right angles, a hairpin, a start whose first waypoint lies straight behind the
  body (DART's goal observation clips it to "straight ahead"), a 120-degree zigzag and a
  pentagram (144-degree turns); all walking.
- ``mixed_text``: the skill changes along the way (walk -> run -> hop...), on a straight line, a
  square, a curve, a back-and-forth and a seeded random path with a random skill per waypoint.
- ``mixed_skills``: walk, run and hop alternate with segment lengths that suit each skill (run 6-10 m,
  hop 2-4 m, walk 3-5 m), so each segment is long enough for the per-segment skill check
  (:mod:`~latentrl.evaluation.skills`): a line, a gentle left curve, a run-first line, right-angle turns
  and a seeded random path.

``goal_text[k]`` is the prompt in force while heading to waypoint ``k`` (``FollowPathEnv``
switches text when a waypoint is reached). Coordinates are world metres, z up, the episode starts
with the pelvis at the origin facing +y, rounded to the millimetre.

The generators run once; :func:`write_suites` writes ``tasks/paths/<name>.json`` and a test checks
that the shipped files equal the generators' output. Regenerate with
``python -m latentrl.evaluation.suites [FOLDER]``.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from latentrl.envs.path import WaypointPath

WALK, RUN, HOP = "walk", "run", "hop on left leg"
SKILLS = (WALK, RUN, HOP)
"""DART's three evaluation prompts; every suite uses only these."""


def _path(points: Sequence[Sequence[float]], texts: Sequence[str] | str) -> WaypointPath:
    """Waypoints given as (x, y) metres, rounded to mm, z = 0; one text or one per waypoint."""
    if isinstance(texts, str):
        texts = [texts] * len(points)
    wps = tuple((round(float(x), 3) + 0.0, round(float(y), 3) + 0.0, 0.0) for x, y in points)
    return WaypointPath(wps, tuple(texts))


def _polyline(headings_deg: Sequence[float], lengths: Sequence[float]) -> list[tuple[float, float]]:
    """Cumulative (x, y) of segments with absolute headings (degrees from +x, counter-clockwise)."""
    x = y = 0.0
    out = []
    for h, length in zip(headings_deg, lengths):
        x += length * math.cos(math.radians(h))
        y += length * math.sin(math.radians(h))
        out.append((x, y))
    return out


def _random_smooth(rng: np.random.Generator, waypoints: int, max_turn_deg: float) -> list[tuple[float, float]]:
    """A smooth random polyline from the origin: heading starts at +y (90 deg) and turns gently."""
    turns = rng.uniform(-max_turn_deg, max_turn_deg, waypoints)
    turns[0] *= 30.0 / max_turn_deg  # the first segment stays within 30 deg of the body's forward axis
    return _polyline(90.0 + np.cumsum(turns), rng.uniform(2.0, 4.0, waypoints))


def random_smooth() -> list[WaypointPath]:
    """Five seeded random smooth paths, 6 waypoints (2-4 m segments, turns up to 45 deg), one skill each."""
    rng = np.random.default_rng(20250601)
    texts = (WALK, RUN, HOP, WALK, RUN)
    return [_path(_random_smooth(rng, 6, 45.0), text) for text in texts]


def sharp_turns() -> list[WaypointPath]:
    """Right angles, a hairpin, a goal straight behind, a 120-degree zigzag and a pentagram; walking."""
    zigzag = _polyline([90.0 + (-120.0 if k % 2 else 0.0) for k in range(5)], [2.5] * 5)
    star = _polyline([90.0 - 144.0 * k for k in range(5)], [3.0] * 5)
    return [
        _path([(0, 3), (3, 3), (3, 6), (0, 6)], WALK),
        _path([(0, 4), (1, 4), (1, 0)], WALK),
        _path([(0, -3), (0, -6)], WALK),
        _path(zigzag, WALK),
        _path(star, WALK),
    ]


def mixed_text() -> list[WaypointPath]:
    """The skill changes along the path: line, square, curve, back-and-forth, seeded random."""
    rng = np.random.default_rng(20250602)
    random_points = _random_smooth(rng, 6, 45.0)
    random_texts = [SKILLS[i] for i in rng.integers(0, len(SKILLS), len(random_points))]
    return [
        _path([(0, 3 * (k + 1)) for k in range(6)], [WALK, RUN, RUN, HOP, HOP, WALK]),
        _path([(0, 4), (4, 4), (4, 0), (0, 0)], [WALK, RUN, HOP, WALK]),
        _path([(0, 2), (1, 4), (3, 6), (6, 8), (10, 10)], [WALK, RUN, WALK, RUN, WALK]),
        _path([(0, 3), (0, -3), (0, 3), (0, -3)], [RUN, WALK, HOP, RUN]),
        _path(random_points, random_texts),
    ]


SKILL_SEGMENT_M: dict[str, tuple[float, float]] = {WALK: (3.0, 5.0), RUN: (6.0, 10.0), HOP: (2.0, 4.0)}
"""Segment lengths (min, max metres) of ``mixed_skills`` per skill: long enough for each to settle after the
switch (a run needs room to speed up, a hop tires quickly), so the per-segment skill check has frames to judge."""


def _skill_path(headings_deg: Sequence[float], texts: Sequence[str], fractions: Sequence[float]) -> WaypointPath:
    """A polyline whose segment k has the length of its skill's range at ``fractions[k]`` (0 = min, 1 = max)."""
    lengths = [lo + f * (hi - lo) for f, (lo, hi) in zip(fractions, (SKILL_SEGMENT_M[t] for t in texts))]
    return _path(_polyline(headings_deg, lengths), texts)


def mixed_skills() -> list[WaypointPath]:
    """Walk, run and hop alternate along each path, with per-skill segment lengths (:data:`SKILL_SEGMENT_M`)."""
    rng = np.random.default_rng(20250603)
    cycle = [WALK, RUN, HOP] * 2
    curve = [90.0 + 15.0 * k for k in range(6)]
    rng_texts = [WALK, RUN, HOP, RUN, WALK, HOP]
    rng_headings = 90.0 + np.cumsum(rng.uniform(-45.0, 45.0, 6) * [30.0 / 45.0, 1, 1, 1, 1, 1])
    return [
        _skill_path([90.0] * 6, cycle, [0.5] * 6),
        _skill_path(curve, cycle, [0.0, 0.0, 0.0, 1.0, 1.0, 1.0]),
        _skill_path([90.0] * 5, [RUN, WALK, HOP, RUN, WALK], [0.5, 0.5, 0.5, 1.0, 0.5]),
        _skill_path([90.0, 0.0, -90.0, 180.0], [WALK, RUN, HOP, WALK], [0.5, 0.5, 0.5, 0.5]),
        _skill_path(rng_headings, rng_texts, rng.uniform(0.0, 1.0, 6)),
    ]


def reach_obstacles() -> list[WaypointPath]:
    """Five seeded single goals 3-5 m ahead, within 45 degrees of the body's forward axis, walking.

    The reach task among random obstacles: they come from the evaluated policy's training scene (docs/scenes.md).
    """
    rng = np.random.default_rng(20261127)
    headings = 90.0 + rng.uniform(-45.0, 45.0, 5)
    lengths = rng.uniform(3.0, 5.0, 5)
    return [_path(_polyline([h], [d]), WALK) for h, d in zip(headings, lengths)]


SUITES: dict[str, Callable[[], list[WaypointPath]]] = {
    "random_smooth": random_smooth,
    "sharp_turns": sharp_turns,
    "mixed_text": mixed_text,
    "mixed_skills": mixed_skills,
    "reach_obstacles": reach_obstacles,
}
"""Suite name (= file stem in ``tasks/paths/``) -> generator."""


def suite_json(paths: Sequence[WaypointPath]) -> str:
    """DART's path-file JSON, one waypoint per line (stable text, so the shipped files can be compared)."""
    blocks = []
    for p in paths:
        points = ",\n".join(f"      [{_num(x)}, {_num(y)}, {_num(z)}]" for x, y, z in p.waypoints)
        texts = ", ".join(f'"{t}"' for t in p.texts)
        blocks.append(f'  {{\n    "goal_location": [\n{points}\n    ],\n    "goal_text": [{texts}]\n  }}')
    return "[\n" + ",\n".join(blocks) + "\n]\n"


def _num(v: float) -> str:
    return repr(round(float(v), 3) + 0.0)


def default_folder() -> Path:
    """``latentrl/tasks/paths``, the shipped suites (package data)."""
    from latentrl.resources import suites_folder

    return suites_folder()


def write_suites(folder: str | Path | None = None) -> list[Path]:
    """Write every suite in :data:`SUITES` as ``<folder>/<name>.json`` (default ``tasks/paths``)."""
    from latentrl.safe_io import atomic_write_text

    folder = Path(folder) if folder is not None else default_folder()
    return [atomic_write_text(folder / f"{name}.json", suite_json(make())) for name, make in SUITES.items()]


if __name__ == "__main__":
    for written in write_suites(sys.argv[1] if len(sys.argv) > 1 else None):
        print(f"wrote {written}")
