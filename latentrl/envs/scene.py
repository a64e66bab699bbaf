"""An env's scene: a fixed scene for every env, or random obstacles or a course drawn per episode, and its rays.

A course is a maze or a staircase of a pool (:mod:`latentrl.scenes.courses`).

The env (:class:`~latentrl.envs.base.LatentMotionVectorEnv`, argument ``scene``) holds one :class:`EnvScene`
when a scene is set and None otherwise, so a flat-floor env runs exactly the code it ran before scenes existed.
With a scene, :attr:`EnvScene.batch` is also the terrain each step's floor snap places the motion on.
The scene observation (``scene_rays``) is :data:`NUM_RAYS` horizontal distances from the pelvis of the last
history frame over the front half-plane, right (-90 degrees) to left (+90 degrees) of the body's forward axis,
in metres clipped at :data:`RAY_RANGE_M`. The optional local height grid (``scene_height_grid``, off by default)
is the terrain around the same pelvis on a k x k grid in the body frame (:meth:`EnvScene.height_grid`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import torch

from latentrl.envs.goal import body_forward
from latentrl.errors import ConfigError
from latentrl.motion.skeleton import PELVIS
from latentrl.resources import packaged, task_file
from latentrl.scenes.courses import POOLS, Course, CoursePool
from latentrl.scenes.random import RandomObstacles, clear_around
from latentrl.scenes.scene import Box, Cylinder, Scene, SceneBatch
from latentrl.scenes.spec import load_scene, parse_scene

NUM_RAYS = 16
RAY_RANGE_M = 4.0
HEIGHT_GRID_SPACING_M = 0.25
"""Default distance between neighbouring samples of the height grid, metres."""
HEIGHT_GRID_CLIP_M = 1.0
"""Height-grid values are clipped to +/- this (a wall reads +1 m, as a tall step would)."""
MAX_HEIGHT_GRID = 15
"""Largest height-grid side (samples per row)."""


def height_grid_problem(size: object, spacing: object) -> str | None:
    """Why (``size``, ``spacing``) cannot be a height grid (0 = none, else an odd side 3..15, spacing in (0, 2] m)."""
    if isinstance(size, bool) or not isinstance(size, int) or not (size == 0 or (3 <= size <= MAX_HEIGHT_GRID
                                                                                 and size % 2 == 1)):
        return f"height_grid: expected 0 (none) or an odd number of samples per side in [3, {MAX_HEIGHT_GRID}], " \
               f"got {size!r:.30}"
    if isinstance(spacing, bool) or not isinstance(spacing, (int, float)) or not 0 < spacing <= 2.0:
        return f"height_grid_spacing: expected metres in (0, 2], got {spacing!r:.30}"
    return None


RANDOM_KINDS = {"random_obstacles": RandomObstacles, **POOLS}
"""The scenes drawn per episode, by their ``env.scene`` key."""


def scene_spec(value: Any) -> Scene | RandomObstacles | CoursePool | None:
    """The scene ``env.scene`` names: None, a scene file, an inline scene, a random kind or an object.

    Random kinds: ``{random_obstacles: {...}}`` and the course pools ``{random_mazes: {...}}``,
    ``{random_stairs: {...}}``.

    One-line :class:`ConfigError` / :class:`~latentrl.errors.DataError` on a bad value.
    """
    if value is None or isinstance(value, (Scene, RandomObstacles, CoursePool)):
        return value
    if isinstance(value, (str, Path)):
        return load_scene(value)
    if isinstance(value, dict):
        for key, kind in RANDOM_KINDS.items():
            if key in value:
                if len(value) != 1:
                    raise ConfigError(f"scene: {key} stands alone, got the keys {sorted(value)}")
                return kind.of(dict(value[key] or {}))
        if "format" in value:
            return parse_scene(value, "env.scene")
    raise ConfigError(f"scene: expected a scene file, a latentrl.scene/1 object, {{random_obstacles: {{...}}}}, "
                      f"{{random_mazes: {{...}}}} or {{random_stairs: {{...}}}}, got {str(value)[:60]}")


def resolve_scene(value: Any) -> Scene | RandomObstacles | CoursePool | None:
    """:func:`scene_spec` with a file name looked up as task files are: a path, or a name in ``tasks/scenes``."""
    if isinstance(value, str):
        found = task_file(value, "scenes")
        if found is None:
            raise ConfigError(f"scene: scene file not found: {value} (looked in {Path.cwd()} and "
                              f"{packaged() / 'tasks' / 'scenes'})")
        value = found
    return scene_spec(value)


class EnvScene:
    """The scenes of N envs on one device: ``batch`` (one row for a fixed scene, N for scenes drawn per episode).

    Course pools (random mazes, random stairs): :attr:`courses` holds the pool and :attr:`pool` its scenes; the path
    task draws a course per episode (:meth:`draw`) and walks its route, so :meth:`reset` leaves course rows to it.
    """

    def __init__(self, spec: Scene | RandomObstacles | CoursePool, num_envs: int, device: torch.device,
                 floor_height: float):
        self.spec = spec
        self.floor_height = float(floor_height)
        self.courses: list[Course] = []
        if isinstance(spec, RandomObstacles):
            self.batch = spec.empty(num_envs, device)
            self.batch.floor_height[:] = self.floor_height
        elif isinstance(spec, CoursePool):
            self.courses = spec.courses()
            self.pool = SceneBatch.from_scenes([Scene(c.scene.objects, self.floor_height) for c in self.courses],
                                               device)
            self._course = torch.zeros(num_envs, dtype=torch.long, device=device)
            self.batch = self.pool.index(self._course)
        else:
            self.batch = SceneBatch.from_scenes([spec], device)
        angles = torch.linspace(-math.pi / 2, math.pi / 2, NUM_RAYS, device=device)
        self._cos, self._sin = torch.cos(angles), torch.sin(angles)

    @property
    def num_rays(self) -> int:
        """R, the size of the ``scene_rays`` observation group."""
        return NUM_RAYS

    @property
    def random(self) -> bool:
        """Each env has its own scene, drawn per episode (random obstacles or a course pool)."""
        return isinstance(self.spec, (RandomObstacles, CoursePool))

    def draw(self, idx: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
        """Course pools: a course of the pool for each of envs ``idx``, put in place; returns their (M,) ids."""
        ids = torch.randint(len(self.courses), (len(idx),), generator=generator, device=self._course.device)
        self._course[idx] = ids
        self.batch.set_rows(idx, self.pool.index(ids))
        return ids

    def reset(self, idx: torch.Tensor, history_world: torch.Tensor, goal: torch.Tensor,
              generator: torch.Generator) -> None:
        """New obstacles for envs ``idx`` (random obstacles), clear of their start pelvis and ``goal`` ((M, 3)).

        A maze is drawn by the path task with its route (:meth:`draw`), before the goal exists.
        """
        if not isinstance(self.spec, RandomObstacles):
            return
        forward, pelvis = body_forward(history_world[:, -1])
        self.batch.set_rows(idx, self.spec.sample(pelvis, forward, goal, generator, self.floor_height))

    def clear_goals(self, goal: torch.Tensor) -> None:
        """Random obstacles: drop those a new goal (N, 3) landed on (fixed scenes and mazes are never changed)."""
        if isinstance(self.spec, RandomObstacles):
            clear_around(self.batch, goal, self.spec.clearance)

    def row(self, i: int) -> SceneBatch:
        """Env ``i``'s scene as a one-row batch."""
        return self.batch.index(slice(i, i + 1)) if self.random else self.batch

    def scene_of(self, i: int) -> Scene:
        """Env ``i``'s scene as objects (random obstacles as they stand now), e.g. to write beside its motion."""
        if not self.random:
            return self.spec
        if self.courses:
            return Scene(self.courses[int(self._course[i])].scene.objects, self.floor_height)
        s = self.row(i)
        objects = []
        for (x, y, z), (hx, hy, hz), yaw in zip(s.box_center[0][s.box_mask[0]].tolist(),
                                                s.box_half[0][s.box_mask[0]].tolist(),
                                                s.box_yaw[0][s.box_mask[0]].tolist()):
            objects.append(Box((x, y), (2 * hx, 2 * hy, 2 * hz), math.degrees(yaw), z - hz))
        for (x, y, z), r, hh in zip(s.cyl_center[0][s.cyl_mask[0]].tolist(), s.cyl_radius[0][s.cyl_mask[0]].tolist(),
                                    s.cyl_half_height[0][s.cyl_mask[0]].tolist()):
            objects.append(Cylinder((x, y), r, 2 * hh, z - hh))
        return Scene(tuple(objects), self.floor_height)

    def replace(self, scene: Scene) -> None:
        """Put ``scene`` in place of a fixed scene, for every env from the next step on.

        Why: ``latentrl play`` drops boxes while the policy walks; collisions, contact, the floor snap and the
        ``scene_rays`` observation all read :attr:`batch`, so they see the new objects at once. Random obstacles
        and mazes are drawn per episode and are not replaced.
        """
        if self.random:
            raise ConfigError("scene: random scenes are drawn per episode; only a fixed scene can be replaced")
        device = self.batch.floor_height.device
        self.spec = scene
        self.batch = SceneBatch.from_scenes([scene], device)

    def rays(self, history_world: torch.Tensor) -> torch.Tensor:
        """(N, NUM_RAYS) distances from the last history frame's pelvis, right to left, clipped at RAY_RANGE_M."""
        origin, dirs = ray_fan(history_world, self._cos, self._sin)
        return self.batch.rays(origin, dirs, RAY_RANGE_M)

    def height_grid(self, history_world: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
        """(N, K) terrain height at ``offsets`` (K, 2) (:func:`grid_offsets`) around the last history frame's pelvis.

        Each value is the terrain under the sample minus the terrain under the pelvis (the ground the body stands
        on or sits over), metres, clipped to +/- :data:`HEIGHT_GRID_CLIP_M`: a step up ahead reads +riser.
        """
        forward, pelvis = body_forward(history_world[:, -1])
        fx, fy = forward[:, None, 0], forward[:, None, 1]
        a, b = offsets[None, :, 0], offsets[None, :, 1]
        xy = torch.stack((pelvis[:, None, 0] + a * fx - b * fy, pelvis[:, None, 1] + a * fy + b * fx), dim=-1)
        ground = self.batch.height(torch.cat((pelvis[:, None, :2], xy), dim=1))  # (N, 1 + K)
        return (ground[:, 1:] - ground[:, :1]).clamp(-HEIGHT_GRID_CLIP_M, HEIGHT_GRID_CLIP_M)


def ray_fan(history_world: torch.Tensor, cos: torch.Tensor | None = None, sin: torch.Tensor | None = None
            ) -> tuple[torch.Tensor, torch.Tensor]:
    """Where the ``scene_rays`` start and point: (N, 2) origins and (N, R, 2) unit xy directions.

    The origin is the last history frame's pelvis; the directions run right (-90 degrees) to left (+90) of the
    body's forward axis. ``cos``/``sin`` of the :data:`NUM_RAYS` angles may be given (an env keeps them); an
    exported controller outputs the fan so an engine casts the rays in its own world.
    """
    if cos is None or sin is None:
        angles = torch.linspace(-math.pi / 2, math.pi / 2, NUM_RAYS, device=history_world.device)
        cos, sin = torch.cos(angles), torch.sin(angles)
    forward, _ = body_forward(history_world[:, -1])
    fx, fy = forward[:, :1], forward[:, 1:2]
    dirs = torch.stack((cos * fx - sin * fy, sin * fx + cos * fy), dim=-1)
    return history_world[:, -1, PELVIS, :2], dirs


def grid_offsets(size: int, spacing: float, device: torch.device | str = "cpu") -> torch.Tensor:
    """(size * size, 2) body-frame offsets (forward, left) of the height grid, metres.

    Row-major: rows run from behind the pelvis to in front of it along the forward axis, and within a row the
    samples run from right to left (as the rays do); the middle sample is the pelvis itself.
    """
    half = (size - 1) / 2
    steps = (torch.arange(size, dtype=torch.float32, device=device) - half) * spacing
    fwd, left = torch.meshgrid(steps, steps, indexing="ij")
    return torch.stack((fwd.reshape(-1), left.reshape(-1)), dim=-1)


def env_scene(value: Any, num_envs: int, device: torch.device, floor_height: float) -> EnvScene | None:
    """The :class:`EnvScene` of an env's ``scene`` argument (None: no scene)."""
    spec = scene_spec(value)
    return None if spec is None else EnvScene(spec, num_envs, device, floor_height)
