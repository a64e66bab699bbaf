"""Routes among objects: the shortest walk to a goal that keeps clear of every object, and where to head next.

Why: a policy that sees the scene through its rays steers around each object as it meets it; the obstacle reach
policy walks twice the straight line where a route 0.25 m clear of every object is 4.5 % longer (docs/scenes.md,
"Where the reach time goes"). A grid planner sees the whole scene at once. :class:`RouteMap` holds, for one
goal in one scene, the length of the shortest route from every grid cell to within ``reach`` of the goal
(Dijkstra from the goal, 16-connected); :meth:`RouteMap.carrot` turns it into a heading for a walker anywhere on
the grid: the farthest point of its route in clear sight, and the length left. Cells closer to an object than
``clearance`` cost more the closer they are (``band_cost``; infinite: not walkable, but for a start inside the band,
which may keep its own distance), so a body that strays near an object is led out again rather than stranded;
cells inside an object are never walkable.

The scene is probed at the heights :data:`PROBE_Z` (the xy footprint of every object up to 1.2 m, so a table
blocks the route as a pillar does); stairs and seats count as objects to walk around.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from latentrl.errors import ConfigError
from latentrl.scenes.scene import SceneBatch

PROBE_Z = (0.1, 0.4, 0.8, 1.2)
"""Heights (m above the floor) at which the scene is probed for the route's grid."""

_STEPS = tuple((di, dj, math.hypot(di, dj)) for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj)
_KNIGHT = tuple((di, dj, math.hypot(di, dj)) for di, dj in ((1, 2), (2, 1), (-1, 2), (-2, 1), (1, -2), (2, -1),
                                                            (-1, -2), (-2, -1)))
"""16-connected moves: a route between grid points is at most 2.7 % longer than the straight line (8-connected:
8.2 %). A knight's move crosses the two cells beside its line, which must be walkable too."""


@dataclass(frozen=True)
class RouteSettings:
    """How routes are planned (``latentrl eval --route``, ``play``; docs/scenes.md)."""

    clearance: float = 0.4
    """Metres the pelvis's route keeps from every object (cells nearer cost more, see ``band_cost``)."""
    cell: float = 0.1
    """Grid spacing, metres."""
    margin: float = 3.0
    """Metres of grid beyond the start and the goal on every side (a walker outside it heads straight)."""
    band_cost: float = 10.0
    """A metre in the clearance band costs up to 1 + this many metres (at the object's surface); inf: not walkable."""
    reach: float = 0.3
    """The route ends within this of the goal (the tasks' success radius)."""
    lookahead: float = 1.0
    """The point a walker heads for lies at most this far from it (metres; inf: the farthest in clear sight):
    a near point keeps a policy that walks in curves on the route rather than across its corners."""

    def check(self) -> None:
        """One-line :class:`ConfigError` naming the field out of range."""
        bounds = {"clearance": (0.0, 2.0), "cell": (0.02, 1.0), "margin": (0.5, 20.0), "reach": (0.0, 2.0)}
        for name, (lo, hi) in bounds.items():
            value = getattr(self, name)
            if not lo <= value <= hi:
                raise ConfigError(f"route {name}: expected metres in [{lo}, {hi}], got {value}")
        if not self.lookahead >= 0.3:
            raise ConfigError(f"route lookahead: expected metres >= 0.3 (inf: no limit), got {self.lookahead}")
        if not self.band_cost >= 0:
            raise ConfigError(f"route band_cost: expected a weight >= 0 (inf: the band is not walkable), "
                              f"got {self.band_cost}")


class RouteMap:
    """For one goal in one scene: the route length from every cell of a grid around ``start`` and ``goal``.

    ``scene`` is a one-row :class:`SceneBatch`; ``start`` and ``goal`` are xy (metres). The start's cell is
    always walkable (a body may begin inside the clearance band). :attr:`cost` (nx, ny) holds each cell's route
    length in metres, inf where no route leads.
    """

    def __init__(self, scene: SceneBatch, start, goal, settings: RouteSettings | None = None):
        settings = settings or RouteSettings()
        settings.check()
        self.settings = settings
        start, goal = np.asarray(start, np.float64)[:2], np.asarray(goal, np.float64)[:2]
        self.goal = goal
        cell = settings.cell
        self.lo = np.minimum(start, goal) - settings.margin
        hi = np.maximum(start, goal) + settings.margin
        self.shape = tuple((np.ceil((hi - self.lo) / cell).astype(int) + 1).tolist())
        xs, ys = self.lo[0] + cell * np.arange(self.shape[0]), self.lo[1] + cell * np.arange(self.shape[1])
        gx, gy = np.meshgrid(xs, ys, indexing="ij")
        self.centers = np.stack((gx, gy), -1)
        self.sdf = clearance_grid(scene, gx, gy)
        si, sj = self.index(start)
        walkable = self.sdf > 0
        if not math.isfinite(settings.band_cost):  # a start inside the band may keep its distance, not come nearer
            walkable &= self.sdf >= min(settings.clearance, float(self.sdf[si, sj])) - 1e-9
        walkable[si, sj] = True
        self.walkable = walkable
        depth = np.clip((settings.clearance - self.sdf) / max(settings.clearance, 1e-9), 0.0, 1.0)
        band = 0.0 if not math.isfinite(settings.band_cost) else settings.band_cost
        self.weight = 1.0 + band * depth
        self.cost = self._dijkstra(np.hypot(gx - goal[0], gy - goal[1]) <= max(settings.reach, cell / 2))

    def index(self, xy) -> tuple[int, int]:
        """The grid cell nearest ``xy`` (clamped into the grid)."""
        ij = np.round((np.asarray(xy, np.float64)[:2] - self.lo) / self.settings.cell).astype(int)
        return int(np.clip(ij[0], 0, self.shape[0] - 1)), int(np.clip(ij[1], 0, self.shape[1] - 1))

    def inside(self, xy) -> bool:
        """``xy`` lies on the grid."""
        ij = (np.asarray(xy, np.float64)[:2] - self.lo) / self.settings.cell
        return bool(np.all(ij >= -0.5) and np.all(ij <= np.array(self.shape) - 0.5))

    def _dijkstra(self, seeds: np.ndarray) -> np.ndarray:
        """Route length (m) from every cell to the nearest seed cell, through walkable cells (scipy's Dijkstra)."""
        nx, ny = self.shape
        walk = self.walkable
        cell_id = np.arange(nx * ny).reshape(nx, ny)
        rows, cols, costs = [], [], []
        for di, dj, length in (*_STEPS, *_KNIGHT):
            a0, a1, b0, b1 = max(0, -di), nx - max(0, di), max(0, -dj), ny - max(0, dj)
            ok = walk[a0:a1, b0:b1] & walk[a0 + di:a1 + di, b0 + dj:b1 + dj]
            if abs(di) == 2 or abs(dj) == 2:  # a knight's move: the two cells beside its line walkable too
                hi, hj = (di // 2, 0) if abs(di) == 2 else (0, dj // 2)
                ci, cj = di - hi, dj - hj
                ok &= walk[a0 + hi:a1 + hi, b0 + hj:b1 + hj] & walk[a0 + ci:a1 + ci, b0 + cj:b1 + cj]
            w = 0.5 * (self.weight[a0:a1, b0:b1] + self.weight[a0 + di:a1 + di, b0 + dj:b1 + dj])
            rows.append(cell_id[a0:a1, b0:b1][ok])
            cols.append(cell_id[a0 + di:a1 + di, b0 + dj:b1 + dj][ok])
            costs.append(self.settings.cell * length * w[ok])
        graph = csr_matrix((np.concatenate(costs), (np.concatenate(rows), np.concatenate(cols))),
                           shape=(nx * ny, nx * ny))
        sources = np.flatnonzero(seeds.ravel() & walk.ravel())
        if len(sources) == 0:
            return np.full(self.shape, math.inf)
        return dijkstra(graph, directed=True, indices=sources, min_only=True).reshape(nx, ny)

    def length(self, xy) -> float:
        """Route length (m) from ``xy`` to within ``reach`` of the goal (inf: none, or off the grid)."""
        if not self.inside(xy):
            return math.inf
        i, j = self.index(xy)
        return float(self.cost[i, j] + np.hypot(*(self.centers[i, j] - np.asarray(xy, np.float64)[:2])))

    def trace(self, xy) -> list[np.ndarray]:
        """The route's cell centres from ``xy``'s cell downhill to the goal's reach, then the goal ([] if none)."""
        i, j = self.index(xy)
        if not (self.inside(xy) and math.isfinite(self.cost[i, j])):
            return []
        nx, ny = self.shape
        points = [self.centers[i, j]]
        while self.cost[i, j] > 0:
            best, nxt = self.cost[i, j], None
            for di, dj, _ in _STEPS:
                a, b = i + di, j + dj
                if 0 <= a < nx and 0 <= b < ny and self.cost[a, b] < best:
                    best, nxt = self.cost[a, b], (a, b)
            if nxt is None:
                break
            i, j = nxt
            points.append(self.centers[i, j])
        return points + [self.goal]

    def in_sight(self, p, q, floor: float | None = None) -> bool:
        """The segment p-q stays ``clearance`` from every object (or at least ``floor`` metres, if less)."""
        p, q = np.asarray(p, np.float64)[:2], np.asarray(q, np.float64)[:2]
        need = self.settings.clearance if floor is None else min(self.settings.clearance, floor)
        n = max(2, int(np.ceil(np.hypot(*(q - p)) / (self.settings.cell / 2))) + 1)
        ts = np.linspace(0.0, 1.0, n)[:, None]
        ij = np.round((p + (q - p) * ts - self.lo) / self.settings.cell).astype(int)
        ij = np.clip(ij, 0, np.array(self.shape) - 1)
        return bool((self.sdf[ij[:, 0], ij[:, 1]] >= need - 1e-9).all())

    def corners(self, xy) -> list[np.ndarray]:
        """The route from ``xy`` pulled taut: each kept point the farthest later one in clear sight, the goal last."""
        points = self.trace(xy)
        if not points:
            return []
        kept, k = [], 0
        while k < len(points) - 1:
            far = next(m for m in range(len(points) - 1, k, -1) if m == k + 1 or self.in_sight(points[k], points[m]))
            kept.append(points[far])
            k = far
        return kept

    def carrot(self, xy) -> tuple[np.ndarray, float]:
        """Where a walker at ``xy`` should head, and the route length left (m).

        The goal itself, at the straight distance, when the walker sees it clear of the objects (the segment
        keeps ``clearance``, or the walker's own distance where it stands nearer than that) or when there is no
        route (off the grid, or walled in); else the farthest point of its route in clear sight, at most
        ``lookahead`` away.
        """
        xy = np.asarray(xy, np.float64)[:2]
        points = self.trace(xy)
        straight = self.goal.copy(), float(np.hypot(*(self.goal - xy)))
        if not points:
            return straight
        i, j = self.index(xy)
        floor = float(self.sdf[i, j])
        if self.in_sight(xy, self.goal, floor):
            return straight
        best = points[1] if len(points) > 1 else points[0]
        for p in points[1:]:
            if np.hypot(*(p - xy)) > self.settings.lookahead or not self.in_sight(xy, p, floor):
                break
            best = p
        if best is self.goal:
            return straight
        return np.array(best), float(np.hypot(*(best - xy)) + self.cost[self.index(best)])


def footprint_distance(batch: SceneBatch, xy: torch.Tensor, floor: float) -> torch.Tensor:
    """(N, ...) distance from (N, ..., 2) floor points to the nearest object, the least over :data:`PROBE_Z`."""
    z = torch.tensor(PROBE_Z, dtype=xy.dtype, device=xy.device) + float(floor)
    points = torch.cat((xy[..., None, :].expand(*xy.shape[:-1], len(PROBE_Z), 2),
                        z.expand(*xy.shape[:-1], -1)[..., None]), dim=-1)
    return batch.sdf(points).amin(dim=-1)


def clearance_grid(scene: SceneBatch, gx: np.ndarray, gy: np.ndarray) -> np.ndarray:
    """(nx, ny) xy distance from each grid point to the nearest object, the least over :data:`PROBE_Z`, metres."""
    floor = float(scene.floor_height[0])
    out = np.full(gx.shape, np.inf)
    for z in PROBE_Z:
        pts = torch.tensor(np.stack((gx, gy, np.full_like(gx, floor + z)), -1).reshape(1, -1, 3),
                           dtype=scene.box_center.dtype, device=scene.box_center.device)
        out = np.minimum(out, scene.sdf(pts).reshape(gx.shape).cpu().double().numpy())
    return out
