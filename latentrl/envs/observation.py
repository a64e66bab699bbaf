"""The observation of a latent-motion env: its layout and the one pure function that assembles it.

An observation is ``[goal | text | motion | scene]``: the task's goal fields, the prompt embedding,
the canonical 2-frame history and the pelvis height above the floor; an env with a scene appends
``scene_rays``, the distances to the objects around, and optionally ``scene_height_grid``, the terrain around
the pelvis (:mod:`latentrl.envs.scene`). The env and the exported ONNX
controller (:mod:`latentrl.export.onnx`) both build it with :func:`observe`, so a policy sees the same
vector in both.
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Sequence

import torch

from latentrl.motion.representation import FEATURE_DIM, HISTORY_LENGTH
from latentrl.motion.skeleton import PELVIS


class ObservationLayout:
    """Where each field and group sits in the observation vector.

    Args:
        goal_fields: the task's ``(name, size)`` goal fields, in order.
        text_dim: E, the size of a prompt embedding.
        rays: R, the scene rays (0: no scene, no ``scene_rays`` group).
        grid: K, the samples of the local height grid (0: no ``scene_height_grid`` group).
        task_group: goal fields that form a group of their own after ``goal``, named ``task``. Why: a task that
            adds fields to a goal-reaching task's (the sit task's seat and phase) keeps ``goal`` the size it has
            in a reach policy, so that policy can warm-start it (``ppo.init_from``: a new group starts silent).
    """

    def __init__(self, goal_fields: Sequence[tuple[str, int]], text_dim: int, rays: int = 0, grid: int = 0,
                 task_group: Sequence[str] = ()):
        named = (*goal_fields, ("text", text_dim), ("motion", HISTORY_LENGTH * FEATURE_DIM), ("scene", 1),
                 *((("scene_rays", rays),) if rays else ()), *((("scene_height_grid", grid),) if grid else ()))
        self.fields: OrderedDict[str, tuple[int, int]] = OrderedDict()
        """Field name -> ``[start, stop)``: the goal fields, text, motion, scene."""
        start = 0
        for name, size in named:
            self.fields[name] = (start, start + size)
            start += size
        self.size = start
        """Length of the observation vector."""
        names = [name for name, _ in goal_fields]
        split = len(names) - len(task_group)  # the task group is the last len(task_group) goal fields
        if task_group and not (split > 0 and set(names[split:]) == set(task_group)):
            raise ValueError(f"task_group {list(task_group)} must be the goal fields' tail after at least one field")
        goal_stop = self.fields[names[split - 1]][1]
        task = {"task": (goal_stop, self.fields[names[-1]][1])} if split < len(names) else {}
        self.groups: OrderedDict[str, tuple[int, int]] = OrderedDict(
            goal=(0, goal_stop), **task, **{k: self.fields[k] for k in ("text", "motion", "scene", "scene_rays",
                                                                        "scene_height_grid") if k in self.fields})
        """Group name -> ``[start, stop)``: goal[, task], text, motion, scene[, scene_rays][, scene_height_grid]
        (what trainers split by)."""


def observe(history: torch.Tensor, history_world: torch.Tensor, goal: torch.Tensor, text: torch.Tensor,
            floor_height: float, rays: torch.Tensor | None = None, grid: torch.Tensor | None = None) -> torch.Tensor:
    """(N, obs_dim) float32 ``[goal | text | motion | scene[ | scene_rays][ | scene_height_grid]]``.

    ``history`` (N, 2, 276) canonical features, ``history_world`` (N, 2, 22, 3) their world joints,
    ``goal`` (N, G) the task's goal observation, ``text`` (N, E) the prompt embeddings, ``rays`` (N, R) the
    scene's ray distances (None: no scene), ``grid`` (N, K) the local height grid (None: none).
    """
    scene = floor_height - history_world[:, 0, PELVIS, 2:3]
    parts = (goal, text, history.reshape(history.shape[0], -1), scene)
    if rays is not None:
        parts = (*parts, rays.to(scene.dtype))
    if grid is not None:
        parts = (*parts, grid.to(scene.dtype))
    return torch.cat(parts, dim=1)
