"""What a task adds to :class:`~latentrl.envs.base.LatentMotionVectorEnv`: the hooks it implements, and helpers.

A task samples its goal at reset (:meth:`TaskHooks._reset_task`), observes it
(:meth:`TaskHooks._goal_observation`, fields named in ``goal_fields``), says where it is
(:attr:`TaskHooks.goal_world`) and reacts when it is reached (:meth:`TaskHooks._advance_task`).
The env calls these; everything else (motion, rewards, counters, autoreset) is the env's.
"""

from __future__ import annotations

from typing import Any

import torch


class TaskHooks:
    """The task contract of the latent-motion envs (mixed into ``LatentMotionVectorEnv``)."""

    @property
    def goal_world(self) -> torch.Tensor:
        """(N, 3) the goal each env is heading to now, world metres."""
        raise NotImplementedError

    def _reset_task(self, idx: torch.Tensor) -> None:
        """Choose texts and goals for envs ``idx`` ((M,) long) whose motion state was just reset."""
        raise NotImplementedError

    def _goal_observation(self, history_world: torch.Tensor) -> torch.Tensor:
        """(N, 2, 22, 3) world joints of the history -> (N, G) goal observation (``goal_fields``)."""
        raise NotImplementedError

    def _advance_task(self, reached: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """React to (N,) reached goals after the motion state moved on.

        Returns ``(terminated, is_success)``, both (N,) bool: task terminations and the
        ``is_success`` info of this step.
        """
        raise NotImplementedError

    def _task_infos(self, infos: dict[str, Any], reached: torch.Tensor) -> None:
        """Add task-specific infos (batched, with ``_key`` masks); ``reached`` is the (N,) goal mask."""

    def _reward_inputs(
        self, before: torch.Tensor, future: torch.Tensor, goal: torch.Tensor, reached: torch.Tensor
    ) -> dict[str, torch.Tensor]:
        """Task fields of :class:`~latentrl.rewards.RewardInputs` for this step (``command``, ...); none here.

        Called before :meth:`_advance_task`, with the (N, 2, 22, 3) history before the step, the (N, 8, 22, 3)
        new frames, the (N, 3) goal in force and the (N,) reached mask.
        """
        return {}

    def _all_texts(self, texts: tuple[str, ...]) -> tuple[str, ...]:
        """Every prompt the env may use; tasks with their own texts (paths) extend it."""
        return texts

    # ------------------------------------------------------------------ helpers for tasks
    def _sample_texts(self, count: int) -> torch.Tensor:
        """(count,) indices into ``texts``, drawn with ``text_weights`` from the env generator."""
        return self.text_table.sample(count, self._generator)

    def _uniform(self, count: int, low: float, high: float) -> torch.Tensor:
        """(count,) uniform samples in [low, high) from the env generator."""
        u = torch.rand(count, generator=self._generator, device=self.device)
        return low + (high - low) * u
