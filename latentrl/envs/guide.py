"""A route guide: the policy sees the next point of a planned route among the objects in place of its goal.

Why: a scene policy finds its way by its rays alone and walks twice the straight line where a route clear of every
object is a few per cent longer (docs/scenes.md, "Routes"). An env made with ``route`` (``env.route``,
``latentrl eval --route``) holds a :class:`RouteGuide`: it plans each goal's route once
(:class:`~latentrl.scenes.route.RouteMap`) and, every observation, rewrites the ``goal_dir`` / ``goal_dist`` fields
so that the goal the policy sees lies in the direction of the farthest route point in clear sight, as far away as
the route's length left: the policy walks as it was trained to, toward a goal that happens to lie along the route.
Where the straight line to the goal is clear the observation is left as it is, bit for bit. Success, rewards and
metrics keep the task's own goal; the rays still see the objects; ``--avoid``'s scene filter acts after the policy.
A joystick has no goal: its route leads to where the command points a few metres ahead, and the guide turns the
command's direction toward the route (the speed stays the command's).
"""

from __future__ import annotations

import numpy as np
import torch

from latentrl.errors import ConfigError
from latentrl.motion.skeleton import PELVIS
from latentrl.scenes.route import RouteMap, RouteSettings, footprint_distance

MOVING_TARGET_STEP_M = 0.5
"""A target that moves with the body (a joystick's) is planned anew once it has moved into another cell of this
size: a route from any point of the map is as good, and planning costs ~20 ms."""


class RouteGuide:
    """The route maps of a vector env's envs, one per (goal, scene) pair, planned when either changes.

    ``env``: a vector env with a scene whose task is ``routable()``: it names where to plan to (``route_target``)
    and how to show a route's point in its observation (``routed_observation``; :class:`LatentMotionVectorEnv`).
    """

    def __init__(self, env, settings: RouteSettings | None = None):
        settings = settings or RouteSettings()
        settings.check()
        if not (callable(getattr(env, "routable", None)) and env.routable()):
            raise ConfigError(f"route: the {type(env).__name__} task has no place on the floor to guide to "
                              "(reach, path, timed and joystick tasks have)")
        self.env, self.settings = env, settings
        self._maps: dict[int, tuple[tuple, RouteMap]] = {}
        self.plans = 0
        """Routes planned so far (a new goal or a changed scene plans anew)."""

    def _scene_keys(self) -> list[tuple]:
        """One hashable key per env's scene row (a fixed scene: one row for all), read in one pass per call."""
        s = self.env.scene.batch
        rows = torch.cat((s.box_center.flatten(1), s.box_half.flatten(1), s.box_yaw, s.box_mask.to(s.box_yaw.dtype),
                          s.cyl_center.flatten(1), s.cyl_radius, s.cyl_half_height,
                          s.cyl_mask.to(s.cyl_radius.dtype)), dim=1)
        keys = [tuple(r) for r in rows.tolist()]
        return keys * self.env.num_envs if len(keys) == 1 else keys

    def goals(self, history_world: torch.Tensor | None = None) -> torch.Tensor:
        """(N, 3) the goal each env's policy should see now (the task's goal where no object is in the way).

        ``history_world``: the env's :meth:`history_world`, when the caller holds it already.
        """
        return self._seen(history_world)[1]

    def _seen(self, history_world: torch.Tensor | None) -> tuple[torch.Tensor, torch.Tensor]:
        """(N, 3) the envs' route targets and (N, 3) the goals their policies should see (:meth:`goals`)."""
        env = self.env
        history_world = env.history_world() if history_world is None else history_world
        goal = env.route_target(history_world).detach().to("cpu", torch.float64)
        out = goal.clone()
        scene = getattr(env, "scene", None)
        if scene is None:
            return goal, out
        counts = scene.batch.object_counts().cpu()
        pelvis = history_world[:, -1, PELVIS, :2].detach().to("cpu", torch.float64).numpy()
        scene_keys = self._scene_keys()
        cell = MOVING_TARGET_STEP_M if env.route_target_moves else 1e-5
        clear = self._clear_line(history_world[:, -1, PELVIS], goal) if env.route_target_moves else None
        for i in range(env.num_envs):
            if int(counts[i if counts.numel() > 1 else 0]) == 0 or (clear is not None and bool(clear[i])):
                continue
            key = (tuple(round(v / cell) for v in goal[i, :2].tolist()), scene_keys[i])
            held = self._maps.get(i)
            if held is None or held[0] != key:
                held = (key, RouteMap(scene.row(i), pelvis[i], goal[i, :2].numpy(), self.settings))
                self._maps[i] = held
                self.plans += 1
            point, left = held[1].carrot(pelvis[i])
            if np.allclose(point, held[1].goal):  # the target in clear sight: the task's own observation
                continue
            away = point - pelvis[i]
            norm = float(np.hypot(*away))
            if norm < 1e-6:
                continue
            out[i, :2] = torch.from_numpy(pelvis[i] + away / norm * left)
        return goal, out

    def _clear_line(self, pelvis: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """(N,) whether the straight line from each (N, 3) pelvis to its target keeps the route's clearance.

        Why: a target that moves with the body would otherwise be planned for at nearly every step; where nothing
        is in the way no route is needed. The clearance asked is the walker's own distance where it stands nearer
        (as :meth:`RouteMap.carrot` asks), every object's footprint probed every 5 cm along the line.
        """
        batch = self.env.scene.batch
        start = pelvis[:, :2].detach().to(batch.box_center.dtype)
        end = target[:, :2].to(start.device, start.dtype)
        ts = torch.linspace(0.0, 1.0, max(2, int(float((end - start).norm(dim=-1).max()) / 0.05) + 1),
                            dtype=start.dtype, device=start.device)
        xy = start[:, None] + (end - start)[:, None] * ts[None, :, None]  # (N, T, 2)
        distance = footprint_distance(batch, xy, self.env.floor_height)  # (N, T)
        need = distance[:, 0].clamp(max=self.settings.clearance)
        return (distance >= need[:, None] - 1e-6).all(dim=1).cpu()

    def observe(self, obs: torch.Tensor, history_world: torch.Tensor | None = None) -> torch.Tensor:
        """``obs`` with the goal fields of every guided env showing :meth:`goals` (others untouched).

        ``history_world``: the env's :meth:`history_world` (the env's own observation passes what it computed).
        """
        history_world = self.env.history_world() if history_world is None else history_world
        goal, seen = self._seen(history_world)
        moved = (seen != goal).any(dim=1)
        if not bool(moved.any()):
            return obs
        rows = moved.nonzero().squeeze(1).to(torch.as_tensor(obs).device)
        return self.env.routed_observation(obs, rows, seen, history_world)
