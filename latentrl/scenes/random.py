"""Random obstacle scenes, drawn on the device per episode: boxes and pillars in front of the body.

Spec (``env.scene: {random_obstacles: {...}}``, docs/scenes.md)::

    random_obstacles: {count: [3, 8], size: [0.3, 1.0], height: [0.5, 1.5], distance: [1.0, 5.0],
                       angle_deg: 90, cylinder_share: 0.5, clearance: 0.5}

Each obstacle is a box (yaw uniform) or a vertical cylinder, its centre ``distance`` metres from the start
pelvis within ``angle_deg`` of the body's forward axis. An obstacle is kept only where its footprint (its
bounding circle) stays ``clearance`` metres from the start pelvis and from the goal; each slot tries
:data:`TRIES` draws and stays empty when none fits (with the defaults, 8 slots and reach goals 0.5-5 m
ahead, none of 32,000 slots stayed empty).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import torch

from latentrl.scenes.scene import SceneBatch
from latentrl.scenes.settings import check_number, check_range, settings_of

TRIES = 8
"""Draws per obstacle slot before it is left empty."""
MAX_RANDOM_OBSTACLES = 64


@dataclass
class RandomObstacles:
    """How many obstacles, how large and where (metres, degrees); see the module docstring."""

    count: list[int] = field(default_factory=lambda: [3, 8])
    size: list[float] = field(default_factory=lambda: [0.3, 1.0])
    """Box side lengths (x and y drawn apart) and cylinder diameters, [min, max] metres."""
    height: list[float] = field(default_factory=lambda: [0.5, 1.5])
    distance: list[float] = field(default_factory=lambda: [1.0, 5.0])
    angle_deg: float = 90.0
    cylinder_share: float = 0.5
    clearance: float = 0.5

    def validate(self) -> None:
        """Ranges ordered and positive; one-line :class:`ConfigError` naming the field."""
        check_range("random_obstacles.count", self.count, 0, MAX_RANDOM_OBSTACLES, integer=True)
        check_range("random_obstacles.size", self.size, 1e-3, 100.0)
        check_range("random_obstacles.height", self.height, 1e-3, 100.0)
        check_range("random_obstacles.distance", self.distance, 0.0, 1000.0)
        for name, low, high in (("angle_deg", 0.0, 180.0), ("cylinder_share", 0.0, 1.0), ("clearance", 0.0, 100.0)):
            check_number(f"random_obstacles.{name}", getattr(self, name), low, high)

    @classmethod
    def of(cls, raw: dict) -> RandomObstacles:
        """A checked spec from its YAML/JSON mapping (unknown keys are one-line errors)."""
        return settings_of(cls, raw, "random_obstacles")

    def empty(self, n: int, device: str | torch.device = "cpu") -> SceneBatch:
        """N empty scenes with a slot per obstacle (each slot is a box or a cylinder)."""
        k = int(self.count[1])
        return SceneBatch.empty(n, k, k, device)

    def sample(self, start: torch.Tensor, forward: torch.Tensor, goal: torch.Tensor,
               generator: torch.Generator, floor_height: float = 0.0) -> SceneBatch:
        """M scenes around (M, >=2) start points facing (M, >=2) unit forward axes, clear of (M, >=2) goals."""
        m, k, device = start.shape[0], int(self.count[1]), start.device

        def uniform(lo: float, hi: float, *shape: int) -> torch.Tensor:
            return lo + (hi - lo) * torch.rand(*shape, generator=generator, device=device)

        shape = (m, k, TRIES)
        count = torch.randint(int(self.count[0]), k + 1, (m, 1), generator=generator, device=device)
        angle = uniform(-math.radians(self.angle_deg), math.radians(self.angle_deg), *shape)
        dist = uniform(*self.distance, *shape)
        fx, fy = forward[:, None, None, 0], forward[:, None, None, 1]
        cx = start[:, None, None, 0] + dist * (torch.cos(angle) * fx - torch.sin(angle) * fy)
        cy = start[:, None, None, 1] + dist * (torch.sin(angle) * fx + torch.cos(angle) * fy)
        sx, sy = uniform(*self.size, *shape), uniform(*self.size, *shape)
        height = uniform(*self.height, *shape)
        yaw = uniform(0.0, math.pi, *shape)
        cylinder = torch.rand(*shape, generator=generator, device=device) < self.cylinder_share
        reach = torch.where(cylinder, sx / 2, torch.sqrt(sx * sx + sy * sy) / 2)  # bounding circle

        def clear_of(p: torch.Tensor) -> torch.Tensor:
            gap = torch.hypot(cx - p[:, None, None, 0], cy - p[:, None, None, 1]) - reach
            return gap >= self.clearance

        ok = clear_of(start) & clear_of(goal)
        first = torch.argmax(ok.to(torch.int8), dim=-1, keepdim=True)  # the first try that fits
        found = ok.gather(-1, first)[..., 0] & (torch.arange(k, device=device)[None, :] < count)

        def pick(t: torch.Tensor) -> torch.Tensor:
            return t.gather(-1, first)[..., 0]

        cx, cy, sx, sy, height, yaw, cylinder = map(pick, (cx, cy, sx, sy, height, yaw, cylinder))
        out = self.empty(m, device)
        out.floor_height[:] = floor_height
        z = floor_height + height / 2
        out.box_center = torch.stack((cx, cy, z), dim=-1)
        out.box_half = torch.stack((sx / 2, sy / 2, height / 2), dim=-1)
        out.box_yaw = yaw
        out.box_mask = found & ~cylinder
        out.cyl_center = out.box_center.clone()
        out.cyl_radius = sx / 2
        out.cyl_half_height = height / 2
        out.cyl_mask = found & cylinder
        return out


def clear_around(scenes: SceneBatch, points: torch.Tensor, clearance: float) -> None:
    """Drop (in place) the objects whose bounding circle comes within ``clearance`` of (N, >=2) ``points``."""
    p = points[:, None, :2]
    box_reach = torch.linalg.vector_norm(scenes.box_half[..., :2], dim=-1)
    box_gap = torch.linalg.vector_norm(scenes.box_center[..., :2] - p, dim=-1) - box_reach
    cyl_gap = torch.linalg.vector_norm(scenes.cyl_center[..., :2] - p, dim=-1) - scenes.cyl_radius
    scenes.box_mask &= box_gap >= clearance
    scenes.cyl_mask &= cyl_gap >= clearance
