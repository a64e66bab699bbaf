"""Scenes: the objects of one world (:class:`Scene`) and a batch of worlds on a device (:class:`SceneBatch`).

World frame: metres, z up, the floor at ``floor_height``. Objects stand on the floor unless ``base`` says
where their bottom is. Four object types, each compiled to the two primitives of :mod:`latentrl.scenes.sdf`:

- :class:`Box`: an obstacle, table or platform, turned by ``yaw_deg`` about +z;
- :class:`Cylinder`: a vertical pillar;
- :class:`Seat`: a box one sits on, its top at ``seat_height`` above its base, facing ``yaw_deg``;
- :class:`Stairs`: ``count`` steps climbing along ``direction_deg``, each ``riser`` higher and ``tread`` deep,
  ``width`` wide; step k is a box from the base up to ``(k + 1) * riser``.

The signed distance of a scene is the minimum over its primitives: exact outside and on every surface; inside
overlapping primitives (a stair's steps) it is the depth inside the deepest one, never more than the true
depth. The floor is not an object: :meth:`SceneBatch.height` is the terrain under a point (the floor, or the
top of the highest object whose footprint holds it), which contact and foot placement read.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import torch

from latentrl.scenes.sdf import (
    box_footprint_contains,
    box_sdf,
    cylinder_footprint_contains,
    cylinder_sdf,
    ray_box_2d,
    ray_circle_2d,
)

FAR_M = 1e3
"""Distance reported where a batch row has no object at all (and by padding rows)."""


@dataclass(frozen=True)
class Box:
    """An upright box: footprint centre (x, y), size (x, y, z) before turning, turned ``yaw_deg`` about +z."""

    center: tuple[float, float]
    size: tuple[float, float, float]
    yaw_deg: float = 0.0
    base: float | None = None
    """z of its bottom face; None: on the floor."""


@dataclass(frozen=True)
class Cylinder:
    """A vertical cylinder standing at (x, y)."""

    center: tuple[float, float]
    radius: float
    height: float
    base: float | None = None


@dataclass(frozen=True)
class Seat:
    """A box to sit on: footprint ``size`` (x, y before turning), its top ``seat_height`` above the base.

    A sitter faces ``yaw_deg`` (0 = +x, 90 = +y), back to the seat.
    """

    center: tuple[float, float]
    size: tuple[float, float]
    seat_height: float
    yaw_deg: float = 0.0
    base: float | None = None


@dataclass(frozen=True)
class Stairs:
    """``count`` steps climbing from ``start`` (the bottom edge's midpoint) along ``direction_deg``."""

    start: tuple[float, float]
    direction_deg: float
    width: float
    riser: float
    tread: float
    count: int
    base: float | None = None

    @property
    def top(self) -> float:
        """Height of the last tread above the base."""
        return self.riser * self.count


SceneObject = Box | Cylinder | Seat | Stairs


@dataclass(frozen=True)
class Scene:
    """One world: its objects and the floor height (build one from JSON with :func:`latentrl.scenes.load_scene`)."""

    objects: tuple[SceneObject, ...] = ()
    floor_height: float = 0.0

    def primitives(self) -> tuple[list[tuple], list[tuple]]:
        """(boxes, cylinders): ``(cx, cy, cz, hx, hy, hz, yaw_rad)`` and ``(cx, cy, cz, radius, half_height)``."""
        boxes, cylinders = [], []
        for obj in self.objects:
            base = self.floor_height if obj.base is None else obj.base
            if isinstance(obj, Box):
                sx, sy, sz = obj.size
                boxes.append((*obj.center, base + sz / 2, sx / 2, sy / 2, sz / 2, math.radians(obj.yaw_deg)))
            elif isinstance(obj, Seat):
                sx, sy = obj.size
                h = obj.seat_height
                boxes.append((*obj.center, base + h / 2, sx / 2, sy / 2, h / 2, math.radians(obj.yaw_deg)))
            elif isinstance(obj, Stairs):
                a = math.radians(obj.direction_deg)
                ux, uy = math.cos(a), math.sin(a)
                for k in range(obj.count):
                    along = (k + 0.5) * obj.tread
                    h = (k + 1) * obj.riser
                    boxes.append((obj.start[0] + ux * along, obj.start[1] + uy * along, base + h / 2,
                                  obj.tread / 2, obj.width / 2, h / 2, a))
            else:
                cylinders.append((*obj.center, base + obj.height / 2, obj.radius, obj.height / 2))
        return boxes, cylinders


class SceneBatch:
    """N scenes as padded tensors on one device: boxes and cylinders, each with a validity mask.

    Every query takes points batched like the scenes, (N, ..., 3) or (N, ..., 2); a batch of one scene
    answers a point batch of any N. Padding rows never count.
    """

    def __init__(self, box_center: torch.Tensor, box_half: torch.Tensor, box_yaw: torch.Tensor,
                 box_mask: torch.Tensor, cyl_center: torch.Tensor, cyl_radius: torch.Tensor,
                 cyl_half_height: torch.Tensor, cyl_mask: torch.Tensor, floor_height: torch.Tensor):
        self.box_center, self.box_half, self.box_yaw, self.box_mask = box_center, box_half, box_yaw, box_mask
        """(N, B, 3) centres, (N, B, 3) half sizes, (N, B) yaw in radians, (N, B) bool real boxes."""
        self.cyl_center, self.cyl_radius, self.cyl_half_height, self.cyl_mask = (
            cyl_center, cyl_radius, cyl_half_height, cyl_mask)
        """(N, C, 3) centres, (N, C) radii, (N, C) half heights, (N, C) bool real cylinders."""
        self.floor_height = floor_height
        """(N,) floor z per scene."""

    # ------------------------------------------------------------------ construction
    @classmethod
    def empty(cls, n: int, boxes: int = 0, cylinders: int = 0, device: str | torch.device = "cpu",
              dtype: torch.dtype = torch.float32) -> SceneBatch:
        """N scenes with room for ``boxes`` and ``cylinders`` each and nothing in them (unit-sized padding)."""
        kw = dict(device=device, dtype=dtype)
        return cls(torch.zeros(n, boxes, 3, **kw), torch.ones(n, boxes, 3, **kw), torch.zeros(n, boxes, **kw),
                   torch.zeros(n, boxes, dtype=torch.bool, device=device), torch.zeros(n, cylinders, 3, **kw),
                   torch.ones(n, cylinders, **kw), torch.ones(n, cylinders, **kw),
                   torch.zeros(n, cylinders, dtype=torch.bool, device=device), torch.zeros(n, **kw))

    @classmethod
    def from_scenes(cls, scenes: Sequence[Scene], device: str | torch.device = "cpu",
                    dtype: torch.dtype = torch.float32, boxes: int = 0, cylinders: int = 0) -> SceneBatch:
        """One row per scene, padded to the most primitives of any (at least ``boxes`` / ``cylinders``)."""
        prims = [s.primitives() for s in scenes]
        nb = max([boxes, *(len(b) for b, _ in prims)])
        nc = max([cylinders, *(len(c) for _, c in prims)])
        out = cls.empty(len(scenes), nb, nc, "cpu", torch.float64)
        for i, ((bx, cy), scene) in enumerate(zip(prims, scenes)):
            out.floor_height[i] = scene.floor_height
            if bx:
                t = torch.tensor(bx, dtype=torch.float64)
                out.box_center[i, : len(bx)], out.box_half[i, : len(bx)] = t[:, :3], t[:, 3:6]
                out.box_yaw[i, : len(bx)], out.box_mask[i, : len(bx)] = t[:, 6], True
            if cy:
                t = torch.tensor(cy, dtype=torch.float64)
                out.cyl_center[i, : len(cy)], out.cyl_radius[i, : len(cy)] = t[:, :3], t[:, 3]
                out.cyl_half_height[i, : len(cy)], out.cyl_mask[i, : len(cy)] = t[:, 4], True
        return out.to(device, dtype)

    def _tensors(self) -> tuple[torch.Tensor, ...]:
        return (self.box_center, self.box_half, self.box_yaw, self.box_mask, self.cyl_center, self.cyl_radius,
                self.cyl_half_height, self.cyl_mask, self.floor_height)

    def to(self, device: str | torch.device | None = None, dtype: torch.dtype | None = None) -> SceneBatch:
        """A copy on ``device`` with floating tensors in ``dtype`` (masks stay bool)."""
        return SceneBatch(*(t.to(device) if t.dtype == torch.bool else t.to(device, dtype) for t in self._tensors()))

    def index(self, idx: torch.Tensor | slice) -> SceneBatch:
        """The scenes ``idx`` (rows of every tensor)."""
        return SceneBatch(*(t[idx] for t in self._tensors()))

    def repeat(self, n: int) -> SceneBatch:
        """A batch of ``n`` copies of this one-scene batch."""
        return SceneBatch(*(t.expand(n, *t.shape[1:]).clone() for t in self._tensors()))

    def set_rows(self, idx: torch.Tensor, rows: SceneBatch) -> None:
        """Replace scenes ``idx`` in place by ``rows`` (same padded sizes)."""
        for mine, theirs in zip(self._tensors(), rows._tensors()):
            mine[idx] = theirs.to(mine.dtype)

    @property
    def num_scenes(self) -> int:
        """N."""
        return self.floor_height.shape[0]

    def object_counts(self) -> torch.Tensor:
        """(N,) long: real primitives per scene (a staircase counts one per step)."""
        return self.box_mask.sum(1) + self.cyl_mask.sum(1)

    # ------------------------------------------------------------------ queries
    def _flat(self, points: torch.Tensor) -> tuple[torch.Tensor, SceneBatch, tuple[int, ...]]:
        n = points.shape[0]
        scenes = self
        if self.num_scenes != n:
            if self.num_scenes != 1:
                raise ValueError(f"points batch {n} does not match the {self.num_scenes} scenes")
            scenes = SceneBatch(*(t.expand(n, *t.shape[1:]) for t in self._tensors()))
        return points.reshape(n, -1, points.shape[-1]), scenes, points.shape[:-1]

    def sdf(self, points: torch.Tensor) -> torch.Tensor:
        """(N, ...) signed distance of (N, ..., 3) points to the nearest object (``FAR_M`` with none), metres."""
        flat, s, shape = self._flat(points)
        far = torch.full(flat.shape[:2], FAR_M, dtype=flat.dtype, device=flat.device)
        best = far
        if s.box_mask.shape[1]:
            d = box_sdf(flat, s.box_center, s.box_half, s.box_yaw)
            best = torch.minimum(best, torch.where(s.box_mask[:, None, :], d, FAR_M).amin(dim=-1))
        if s.cyl_mask.shape[1]:
            d = cylinder_sdf(flat, s.cyl_center, s.cyl_radius, s.cyl_half_height)
            best = torch.minimum(best, torch.where(s.cyl_mask[:, None, :], d, FAR_M).amin(dim=-1))
        return best.reshape(shape)

    def height(self, xy: torch.Tensor) -> torch.Tensor:
        """(N, ...) terrain z under (N, ..., 2) points: the floor, or the top of the highest object over it."""
        flat, s, shape = self._flat(xy[..., :2])
        best = s.floor_height[:, None].to(flat.dtype).expand(flat.shape[:2])
        low = -FAR_M
        if s.box_mask.shape[1]:
            inside = box_footprint_contains(flat, s.box_center, s.box_half, s.box_yaw) & s.box_mask[:, None, :]
            top = (s.box_center[..., 2] + s.box_half[..., 2])[:, None, :]
            best = torch.maximum(best, torch.where(inside, top, low).amax(dim=-1))
        if s.cyl_mask.shape[1]:
            inside = cylinder_footprint_contains(flat, s.cyl_center, s.cyl_radius) & s.cyl_mask[:, None, :]
            top = (s.cyl_center[..., 2] + s.cyl_half_height)[:, None, :]
            best = torch.maximum(best, torch.where(inside, top, low).amax(dim=-1))
        return best.reshape(shape)

    def rays(self, origin: torch.Tensor, directions: torch.Tensor, max_range: float) -> torch.Tensor:
        """(N, R) distance along horizontal rays to the first object footprint, clipped at ``max_range``.

        ``origin`` (N, 2 or 3) (z ignored), ``directions`` (N, R, 2) unit vectors. Objects count at every
        height (a 0.1 m step blocks a ray as a wall does): the view from above, what a walker must go around
        or step onto.
        """
        origin = origin[:, :2]
        _, s, _ = self._flat(origin[:, None, :])
        best = torch.full(directions.shape[:2], float(max_range), dtype=origin.dtype, device=origin.device)
        if s.box_mask.shape[1]:
            t = ray_box_2d(origin, directions, s.box_center, s.box_half, s.box_yaw)
            best = torch.minimum(best, torch.where(s.box_mask[:, None, :], t, float("inf")).amin(dim=-1))
        if s.cyl_mask.shape[1]:
            t = ray_circle_2d(origin, directions, s.cyl_center, s.cyl_radius)
            best = torch.minimum(best, torch.where(s.cyl_mask[:, None, :], t, float("inf")).amin(dim=-1))
        return best
