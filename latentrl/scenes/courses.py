"""Generated courses: mazes and staircases, each a scene and the waypoints of a walk through it.

The shipped maze and stairs suites (``latentrl/tasks/paths/maze.json``, ``stairs.json``, ``stairs_skills.json``)
and their scenes (``latentrl/tasks/scenes/maze_*.json``, ``stairs_*.json``) are written from :data:`COURSES` by
``python -m latentrl.scenes.courses`` (a test checks the files equal this module's output). World frame as every
scene's: metres, z up, the episode's start pelvis at the xy origin facing +y.

**Mazes** (:func:`maze`): a grid of ``cols`` x ``rows`` square cells ``cell`` metres wide, carved into a perfect
maze (one way between any two cells) by a depth-first search with a seeded ``random.Random``. Walls are boxes
``wall`` thick and ``height`` high on the cell borders; collinear wall pieces are merged into one box, extended by
half the wall's thickness at each end so corners close. The start cell is the middle cell of the first row, its
centre at the origin; the goal is the cell of the last row farthest from the start along the maze. The path
visits every cell centre on the way, so each waypoint and each segment between two stays ``(cell - wall) / 2``
from the walls (the corridor is ``cell - wall`` wide).

**Stairs** (:func:`stairs_up_down`): a flight of ``count`` steps up along +y, a landing, and a flight down, either
straight on (+y) or turned to +x; waypoints on each flight, on the landing and on the floor beyond.

**Pools for training** (:class:`CoursePool`, :data:`POOLS`): :class:`RandomMazes` and :class:`RandomStairs` make
seeded pools of such courses with random sizes; the path task walks one per episode (``env.scene: {random_mazes:
...}`` or ``{random_stairs: ...}``).
"""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import ClassVar

from latentrl.scenes.scene import Box, Scene, Stairs
from latentrl.scenes.settings import check_number, check_range, settings_of

WALL_HEIGHT_M = 1.2
"""Height of maze walls: above the pelvis, below the head (the scene rays see every wall at any height)."""


@dataclass(frozen=True)
class Course:
    """A scene and a walk through it: waypoints (x, y) in order, each with its text."""

    scene: Scene
    waypoints: tuple[tuple[float, float], ...]
    texts: tuple[str, ...]


def _carve(cols: int, rows: int, start: tuple[int, int], rng: random.Random) -> set[frozenset]:
    """The open passages of a perfect maze: a set of ``{cell, cell}`` pairs (iterative depth-first search)."""
    seen, stack, open_ = {start}, [start], set()
    while stack:
        i, j = stack[-1]
        nxt = [(i + di, j + dj) for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1))
               if 0 <= i + di < cols and 0 <= j + dj < rows and (i + di, j + dj) not in seen]
        if not nxt:
            stack.pop()
            continue
        cell = rng.choice(nxt)
        open_.add(frozenset(((i, j), cell)))
        seen.add(cell)
        stack.append(cell)
    return open_


def _route(cols: int, rows: int, start: tuple[int, int], open_: set[frozenset]) -> list[tuple[int, int]]:
    """The cells from ``start`` to the last-row cell farthest from it along the maze (breadth-first search)."""
    parent: dict[tuple[int, int], tuple[int, int] | None] = {start: None}
    order = [start]
    for i, j in order:
        for cell in ((i + 1, j), (i - 1, j), (i, j + 1), (i, j - 1)):
            if cell not in parent and frozenset(((i, j), cell)) in open_:
                parent[cell] = (i, j)
                order.append(cell)
    depth = {start: 0}
    for cell in order[1:]:
        depth[cell] = depth[parent[cell]] + 1
    goal = max((c for c in order if c[1] == rows - 1), key=lambda c: (depth[c], -c[0]))
    route = [goal]
    while parent[route[-1]] is not None:
        route.append(parent[route[-1]])
    return route[::-1]


def _merge(pieces: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """Unit wall pieces ``(line, k)`` (piece k on grid line ``line``) as runs ``(line, first, last)``."""
    runs: list[list[int]] = []
    for line, k in sorted(pieces):
        if runs and runs[-1][0] == line and runs[-1][2] == k - 1:
            runs[-1][2] = k
        else:
            runs.append([line, k, k])
    return [tuple(r) for r in runs]


def maze(cols: int, rows: int, seed: int, cell: float = 2.0, wall: float = 0.2,
         height: float = WALL_HEIGHT_M, text: str = "walk") -> Course:
    """A seeded perfect maze and the walk from its start cell to its goal (module docstring)."""
    if cols < 1 or rows < 2 or not 0 < wall < cell:
        raise ValueError(f"maze: need cols >= 1, rows >= 2 and 0 < wall < cell, got {cols}, {rows}, {wall}, {cell}")
    start = (cols // 2, 0)
    open_ = _carve(cols, rows, start, random.Random(seed))

    def x_of(i: float) -> float:
        return (i - start[0]) * cell

    def y_of(j: float) -> float:
        return j * cell

    # horizontal lines y = j - 0.5 (j = 0..rows) hold pieces between (i, j-1) and (i, j); vertical alike
    horizontal = [(j, i) for j in range(rows + 1) for i in range(cols)
                  if j in (0, rows) or frozenset(((i, j - 1), (i, j))) not in open_]
    vertical = [(i, j) for i in range(cols + 1) for j in range(rows)
                if i in (0, cols) or frozenset(((i - 1, j), (i, j))) not in open_]
    boxes = []
    for j, first, last in _merge(horizontal):
        length = round((last - first + 1) * cell + wall, 6)
        boxes.append(Box((round(x_of((first + last) / 2), 6), round(y_of(j - 0.5), 6)), (length, wall, height)))
    for i, first, last in _merge(vertical):
        length = round((last - first + 1) * cell + wall, 6)
        boxes.append(Box((round(x_of(i - 0.5), 6), round(y_of((first + last) / 2), 6)), (wall, length, height)))
    route = _route(cols, rows, start, open_)
    waypoints = tuple((round(x_of(i), 6), round(y_of(j), 6)) for i, j in route[1:])
    return Course(Scene(tuple(boxes)), waypoints, (text,) * len(waypoints))


def stairs_up_down(riser: float, count: int = 5, tread: float = 0.3, width: float = 1.4, landing: float = 1.2,
                   turn: bool = False, up: str = "walk", down: str = "walk") -> Course:
    """Up ``count`` steps along +y from y = 1 m, a ``landing`` deep, then down along +y (or +x with ``turn``).

    The flights are ``width`` wide and centred on x = 0 (the down flight of a turned course on y at the landing's
    middle). ``up`` and ``down`` are the texts of the waypoints on each flight and after it.
    """
    start_y = 1.0
    top = riser * count
    run = tread * count
    land_y0 = start_y + run
    objects: list = [Stairs((0.0, start_y), 90.0, width, riser, tread, count)]
    if not turn:
        objects.append(Box((0.0, round(land_y0 + landing / 2, 6)), (width, landing, round(top, 6))))
        end = land_y0 + landing + run
        objects.append(Stairs((0.0, round(end, 6)), -90.0, width, riser, tread, count))
        points = [(0.0, start_y + run / 2), (0.0, land_y0 + landing / 2), (0.0, land_y0 + landing + run / 2),
                  (0.0, end + 1.5)]
    else:  # a square landing, the way down leaves it along +x
        side = max(landing, width)
        mid_y = land_y0 + side / 2
        objects.append(Box((0.0, round(mid_y, 6)), (side, side, round(top, 6))))
        end = side / 2 + run
        objects.append(Stairs((round(end, 6), round(mid_y, 6)), 180.0, width, riser, tread, count))
        points = [(0.0, start_y + run / 2), (0.0, mid_y), (side / 2 + run / 2, mid_y), (end + 1.5, mid_y)]
    texts = (up, up, down, down)
    return Course(Scene(tuple(objects)), tuple((round(x, 6), round(y, 6)) for x, y in points), texts)


class CoursePool:
    """A seeded pool of generated courses for training (``env.scene: {KIND: {...}}``).

    The path task draws a course per episode and walks its route (docs/scenes.md); the pool is made once, when
    the env is built. Subclasses name their ``env.scene`` key (:attr:`kind`), the shipped suite of their kind that
    ``latentrl eval`` runs by default for a policy trained on them (:attr:`suite`), and make the pool
    (:meth:`courses`).
    """

    kind: ClassVar[str] = ""
    suite: ClassVar[str] = ""

    def validate(self) -> None:  # pragma: no cover - every pool checks its own fields
        """Sizes in range; one-line :class:`ConfigError` naming the field."""
        raise NotImplementedError

    @classmethod
    def of(cls, raw: dict) -> CoursePool:
        """A checked spec from its YAML/JSON mapping (unknown keys are one-line errors)."""
        return settings_of(cls, raw, cls.kind)

    def courses(self) -> list[Course]:  # pragma: no cover - every pool makes its own
        """The pool, in order (the same for the same settings)."""
        raise NotImplementedError


MAX_RANDOM_MAZES = 4096
MAX_MAZE_CELLS = 12
"""Largest side of a random maze, cells."""
MIN_CORRIDOR_M = 1.2
"""Narrowest corridor (cell minus wall) of a random maze, metres."""


@dataclass
class RandomMazes(CoursePool):
    """A pool of ``count`` seeded mazes of random size for training (``env.scene: {random_mazes: {...}}``).

    Maze k has ``cols`` x ``rows`` cells (each drawn uniformly from its [min, max]) of side ``cell`` metres
    (uniform in [min, max]; corridors ``cell - wall`` >= 1.2 m) with walls ``wall`` thick, carved with seed
    ``seed * 1,000,003 + 1,000 + k``, so the shipped ``maze`` suite (seeds 1-3) stays out of the pool. A path env
    draws one per episode and walks its route (docs/scenes.md); the pool is made once, when the env is built.
    """

    kind: ClassVar[str] = "random_mazes"
    suite: ClassVar[str] = "maze"
    count: int = 256
    cols: list[int] = field(default_factory=lambda: [3, 5])
    rows: list[int] = field(default_factory=lambda: [3, 5])
    cell: list[float] = field(default_factory=lambda: [1.4, 2.2])
    wall: float = 0.2
    seed: int = 0

    def validate(self) -> None:
        """Sizes in range; one-line :class:`ConfigError` naming the field."""
        check_number("random_mazes.count", self.count, 1, MAX_RANDOM_MAZES, integer=True)
        check_range("random_mazes.cols", self.cols, 1, MAX_MAZE_CELLS, integer=True)
        check_range("random_mazes.rows", self.rows, 2, MAX_MAZE_CELLS, integer=True)
        check_number("random_mazes.wall", self.wall, 0.01, 1.0)
        check_range("random_mazes.cell", self.cell, round(self.wall + MIN_CORRIDOR_M, 6), 10.0)
        check_number("random_mazes.seed", self.seed, 0, 2**31 - 1, integer=True)

    def courses(self) -> list[Course]:
        """The pool, in order (the same for the same settings)."""
        out = []
        for k in range(self.count):
            seed = self.seed * 1_000_003 + 1_000 + k
            rng = random.Random(seed)
            cols, rows = rng.randint(*self.cols), rng.randint(*self.rows)
            cell = round(rng.uniform(*self.cell), 3)
            out.append(maze(cols, rows, seed=seed, cell=cell, wall=self.wall))
        return out


MAX_RANDOM_STAIRS = 4096
MAX_STAIR_STEPS = 12


@dataclass
class RandomStairs(CoursePool):
    """A pool of ``count`` seeded staircases for training (``env.scene: {random_stairs: {...}}``).

    Course k is :func:`stairs_up_down` with its riser, number of steps, tread, width and landing each drawn
    uniformly from their [min, max] (metres; steps an integer), and turned (the way down leaves the landing along
    +x) with probability ``turn``, all from ``random.Random(seed * 1,000,003 + 2,000 + k)``. The shipped
    ``stairs`` suite's four courses (five steps of 0.10 / 0.15 / 0.20 m, 0.3 m treads, a 1.4 m flight) are fixed
    sizes a pool draws only by chance.
    """

    kind: ClassVar[str] = "random_stairs"
    suite: ClassVar[str] = "stairs"
    count: int = 256
    riser: list[float] = field(default_factory=lambda: [0.10, 0.20])
    steps: list[int] = field(default_factory=lambda: [3, 6])
    tread: list[float] = field(default_factory=lambda: [0.26, 0.36])
    width: list[float] = field(default_factory=lambda: [1.2, 1.8])
    landing: list[float] = field(default_factory=lambda: [1.0, 1.8])
    turn: float = 0.25
    seed: int = 0

    def validate(self) -> None:
        """Sizes in range; one-line :class:`ConfigError` naming the field."""
        check_number("random_stairs.count", self.count, 1, MAX_RANDOM_STAIRS, integer=True)
        check_range("random_stairs.riser", self.riser, 0.02, 0.4)
        check_range("random_stairs.steps", self.steps, 1, MAX_STAIR_STEPS, integer=True)
        check_range("random_stairs.tread", self.tread, 0.15, 1.0)
        check_range("random_stairs.width", self.width, 0.6, 4.0)
        check_range("random_stairs.landing", self.landing, 0.6, 4.0)
        check_number("random_stairs.turn", self.turn, 0.0, 1.0)
        check_number("random_stairs.seed", self.seed, 0, 2**31 - 1, integer=True)

    def courses(self) -> list[Course]:
        """The pool, in order (the same for the same settings)."""
        out = []
        for k in range(self.count):
            rng = random.Random(self.seed * 1_000_003 + 2_000 + k)
            riser, count = round(rng.uniform(*self.riser), 3), rng.randint(*self.steps)
            tread, width = round(rng.uniform(*self.tread), 3), round(rng.uniform(*self.width), 3)
            landing, turn = round(rng.uniform(*self.landing), 3), rng.random() < self.turn
            out.append(stairs_up_down(riser, count, tread, width, landing, turn=turn))
        return out


POOLS: dict[str, type[CoursePool]] = {pool.kind: pool for pool in (RandomMazes, RandomStairs)}
"""The course pools by their ``env.scene`` key."""

COURSES: dict[str, Callable[[], Course]] = {
    "maze_a": lambda: maze(4, 4, seed=1, cell=2.0),
    "maze_b": lambda: maze(5, 4, seed=2, cell=1.7),
    "maze_c": lambda: maze(4, 5, seed=3, cell=1.4),
    "stairs_10": lambda: stairs_up_down(0.10),
    "stairs_15": lambda: stairs_up_down(0.15),
    "stairs_20": lambda: stairs_up_down(0.20),
    "stairs_turn": lambda: stairs_up_down(0.15, turn=True),
}
"""Scene name (file stem in ``tasks/scenes``) -> its course."""

SUITES: dict[str, tuple[tuple[str, tuple[str, str] | None], ...]] = {
    "maze": (("maze_a", None), ("maze_b", None), ("maze_c", None)),
    "stairs": (("stairs_10", None), ("stairs_15", None), ("stairs_20", None), ("stairs_turn", None)),
    "stairs_skills": (("stairs_10", ("walk up stairs", "walk down stairs")),
                      ("stairs_15", ("walk up stairs", "walk down stairs")),
                      ("stairs_20", ("walk up stairs", "walk down stairs"))),
}
"""Suite name (file stem in ``tasks/paths``) -> its paths: a course and the (up, down) texts replacing the
course's own (None: keep them). ``stairs_skills`` asks for the stairs prompts of models trained with them."""

DESCRIPTIONS: dict[str, str] = {
    "maze_a": "A 4 x 4 maze of 2.0 m cells (1.8 m corridors), seed 1; start at the origin facing +y.",
    "maze_b": "A 5 x 4 maze of 1.7 m cells (1.5 m corridors), seed 2; start at the origin facing +y.",
    "maze_c": "A 4 x 5 maze of 1.4 m cells (1.2 m corridors), seed 3; start at the origin facing +y.",
    "stairs_10": "Five 0.10 m steps up along +y from y = 1, a 1.2 m landing, five steps down.",
    "stairs_15": "Five 0.15 m steps up along +y from y = 1, a 1.2 m landing, five steps down.",
    "stairs_20": "Five 0.20 m steps up along +y from y = 1, a 1.2 m landing, five steps down.",
    "stairs_turn": "Five 0.15 m steps up along +y, a square landing, five steps down along +x.",
}


def suite_paths(name: str) -> list[dict]:
    """The path-file entries of suite ``name``: waypoints (z = 0), texts and the scene by name."""
    out = []
    for scene_name, texts in SUITES[name]:
        course = COURSES[scene_name]()
        if texts is None:
            labels = course.texts
        else:  # the first half of a stairs course climbs, the rest goes down
            half = len(course.waypoints) // 2
            labels = tuple(texts[0] if k < half else texts[1] for k in range(len(course.waypoints)))
        out.append({"goal_location": [[x, y, 0.0] for x, y in course.waypoints], "goal_text": list(labels),
                    "scene": scene_name})
    return out


def scene_file_text(name: str) -> str:
    """The ``latentrl.scene/1`` file of course ``name``, one object per line."""
    import json

    from latentrl.scenes.spec import scene_to_dict

    data = scene_to_dict(COURSES[name]().scene)
    objects = ",\n".join(f"  {json.dumps(o)}" for o in data["objects"])
    return (f'{{"format": "{data["format"]}",\n "description": {json.dumps(DESCRIPTIONS[name])},\n'
            f' "floor_height": {data["floor_height"]},\n "objects": [\n{objects}\n ]}}\n')


def suite_file_text(name: str) -> str:
    """The path file of suite ``name``, one path per line."""
    import json

    return "[\n" + ",\n".join(f"  {json.dumps(p)}" for p in suite_paths(name)) + "\n]\n"


def write_courses(root=None) -> list:
    """Write every scene of :data:`COURSES` to ``<root>/scenes`` and every suite to ``<root>/paths``."""
    from pathlib import Path

    from latentrl.resources import packaged
    from latentrl.safe_io import atomic_write_text

    base = Path(root) if root is not None else packaged("tasks")
    written = [atomic_write_text(base / "scenes" / f"{n}.json", scene_file_text(n)) for n in COURSES]
    written += [atomic_write_text(base / "paths" / f"{n}.json", suite_file_text(n)) for n in SUITES]
    return written


if __name__ == "__main__":
    import sys

    for file in write_courses(sys.argv[1] if len(sys.argv) > 1 else None):
        print(f"wrote {file}")
