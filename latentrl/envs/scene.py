"""An env's scene: a fixed scene shared by every env, or random obstacles drawn per episode, and its rays.

The env (:class:`~latentrl.envs.base.LatentMotionVectorEnv`, argument ``scene``) holds one :class:`EnvScene`
when a scene is set and None otherwise, so a flat-floor env runs exactly the code it ran before scenes existed.
With a scene, :attr:`EnvScene.batch` is also the terrain each step's floor snap places the motion on.
The scene observation (``scene_rays``) is :data:`NUM_RAYS` horizontal distances from the pelvis of the last
history frame over the front half-plane, right (-90 degrees) to left (+90 degrees) of the body's forward axis,
in metres clipped at :data:`RAY_RANGE_M`.
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
from latentrl.scenes.random import RandomObstacles, clear_around
from latentrl.scenes.scene import Box, Cylinder, Scene, SceneBatch
from latentrl.scenes.spec import load_scene, parse_scene

NUM_RAYS = 16
RAY_RANGE_M = 4.0


def scene_spec(value: Any) -> Scene | RandomObstacles | None:
    """The scene ``env.scene`` names: None, a scene file, an inline scene, ``{random_obstacles: {...}}`` or an object.

    One-line :class:`ConfigError` / :class:`~latentrl.errors.DataError` on a bad value.
    """
    if value is None or isinstance(value, (Scene, RandomObstacles)):
        return value
    if isinstance(value, (str, Path)):
        return load_scene(value)
    if isinstance(value, dict):
        if "random_obstacles" in value:
            if len(value) != 1:
                raise ConfigError(f"scene: random_obstacles stands alone, got the keys {sorted(value)}")
            return RandomObstacles.of(dict(value["random_obstacles"] or {}))
        if "format" in value:
            return parse_scene(value, "env.scene")
    raise ConfigError(f"scene: expected a scene file, a latentrl.scene/1 object or {{random_obstacles: {{...}}}}, "
                      f"got {str(value)[:60]}")


def resolve_scene(value: Any) -> Scene | RandomObstacles | None:
    """:func:`scene_spec` with a file name looked up as task files are: a path, or a name in ``tasks/scenes``."""
    if isinstance(value, str):
        found = task_file(value, "scenes")
        if found is None:
            raise ConfigError(f"scene: scene file not found: {value} (looked in {Path.cwd()} and "
                              f"{packaged() / 'tasks' / 'scenes'})")
        value = found
    return scene_spec(value)


class EnvScene:
    """The scenes of N envs on one device: ``batch`` (one row for a fixed scene, N for random obstacles)."""

    def __init__(self, spec: Scene | RandomObstacles, num_envs: int, device: torch.device, floor_height: float):
        self.spec = spec
        self.floor_height = float(floor_height)
        if isinstance(spec, RandomObstacles):
            self.batch = spec.empty(num_envs, device)
            self.batch.floor_height[:] = self.floor_height
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
        """Obstacles are drawn per episode."""
        return isinstance(self.spec, RandomObstacles)

    def reset(self, idx: torch.Tensor, history_world: torch.Tensor, goal: torch.Tensor,
              generator: torch.Generator) -> None:
        """New obstacles for envs ``idx`` (random scenes), clear of their start pelvis and ``goal`` ((M, 3))."""
        if not self.random:
            return
        forward, pelvis = body_forward(history_world[:, -1])
        self.batch.set_rows(idx, self.spec.sample(pelvis, forward, goal, generator, self.floor_height))

    def clear_goals(self, goal: torch.Tensor) -> None:
        """Random scenes: drop the obstacles a new goal (N, 3) landed on (a fixed scene is never changed)."""
        if self.random:
            clear_around(self.batch, goal, self.spec.clearance)

    def row(self, i: int) -> SceneBatch:
        """Env ``i``'s scene as a one-row batch."""
        return self.batch.index(slice(i, i + 1)) if self.random else self.batch

    def scene_of(self, i: int) -> Scene:
        """Env ``i``'s scene as objects (random obstacles as they stand now), e.g. to write beside its motion."""
        if not self.random:
            return self.spec
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

    def rays(self, history_world: torch.Tensor) -> torch.Tensor:
        """(N, NUM_RAYS) distances from the last history frame's pelvis, right to left, clipped at RAY_RANGE_M."""
        forward, _ = body_forward(history_world[:, -1])
        fx, fy = forward[:, :1], forward[:, 1:2]
        dirs = torch.stack((self._cos * fx - self._sin * fy, self._sin * fx + self._cos * fy), dim=-1)  # (N, R, 2)
        return self.batch.rays(history_world[:, -1, PELVIS, :2], dirs, RAY_RANGE_M)


def env_scene(value: Any, num_envs: int, device: torch.device, floor_height: float) -> EnvScene | None:
    """The :class:`EnvScene` of an env's ``scene`` argument (None: no scene)."""
    spec = scene_spec(value)
    return None if spec is None else EnvScene(spec, num_envs, device, floor_height)
