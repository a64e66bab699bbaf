"""Gymnasium ids of the latentrl tasks; importing :mod:`latentrl` registers them.

Create them with ``gymnasium.make_vec(id, num_envs=N, **kwargs)`` (the batched env itself, through its
``vector_entry_point``), where ``kwargs`` are the task's constructor arguments (``motion``, ``texts``,
``device``, ...), or with ``gymnasium.make(id, **kwargs)``: one numpy env, a
:class:`~latentrl.envs.single.SingleEnv` (its ``entry_point`` is a :class:`~latentrl.envs.single.SingleEntryPoint`).
Each id is a :class:`~latentrl.envs.tasks.TaskSpec`'s ``gym_id``; registration imports nothing but
Gymnasium and the task registry; the env modules (and torch) load on ``make_vec``.
"""

from __future__ import annotations

import gymnasium

from latentrl.envs.single import SingleEntryPoint
from latentrl.envs.tasks import TASKS

#: id -> (vector entry point, max_episode_steps passed to the constructor by make_vec).
ENV_IDS: dict[str, tuple[str, int]] = {
    spec.gym_id: (spec.env, spec.max_episode_steps) for spec in TASKS.values() if spec.gym_id is not None
}


def register_envs() -> None:
    """Register every id in :data:`ENV_IDS` that Gymnasium does not know yet."""
    for env_id, (entry_point, max_steps) in ENV_IDS.items():
        if env_id not in gymnasium.registry:
            gymnasium.register(id=env_id, entry_point=SingleEntryPoint(entry_point, max_steps),
                               vector_entry_point=entry_point, max_episode_steps=max_steps)


register_envs()
