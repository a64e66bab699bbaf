"""A single ``gymnasium.Env`` view of a one-env vector env (numpy in, numpy out).

Three uses: ``gymnasium.make(id)`` returns one (through :class:`SingleEntryPoint`, so code written
for single envs runs unchanged), Gymnasium's own ``check_env`` (which only checks single envs) can
then check our dynamics, and ``gymnasium.vector.SyncVectorEnv`` over many of them is the
per-env-loop baseline the benchmark compares the batched env against.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import load_env_creator
from gymnasium.vector import AutoresetMode

from latentrl.errors import ConfigError

if TYPE_CHECKING:  # the registration imports this module, and must not load torch
    from latentrl.envs.base import LatentMotionVectorEnv


class SingleEnv(gym.Env):
    """``gymnasium.Env`` over a :class:`LatentMotionVectorEnv` with ``num_envs=1`` and DISABLED autoreset.

    Observations are float32 numpy arrays; ``info`` carries ``is_success`` and the unweighted
    ``reward/<term>`` values as floats.
    """

    metadata = {"render_modes": []}

    def __init__(self, env: LatentMotionVectorEnv):
        if env.num_envs != 1 or env.metadata.get("autoreset_mode") != AutoresetMode.DISABLED:
            raise ConfigError("SingleEnv needs a vector env with num_envs=1 and autoreset_mode=DISABLED")
        self.env = env
        self.observation_space = env.single_observation_space
        self.action_space = env.single_action_space

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict]:
        """Reset the one env; its observation as a numpy vector."""
        super().reset(seed=seed)
        obs, _ = self.env.reset(seed=seed, options=options)
        return obs[0].cpu().numpy(), {}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Step the one env with ``action`` (D,); the reward terms come as floats in ``info``."""
        obs, reward, terminated, truncated, infos = self.env.step(np.asarray(action, dtype=np.float32)[None])
        info = {k: float(v[0]) for k, v in infos.items() if k.startswith("reward/")}
        info["is_success"] = bool(infos["is_success"][0])
        return obs[0].cpu().numpy(), float(reward[0]), bool(terminated[0]), bool(truncated[0]), info

    def close(self) -> None:
        """Close the wrapped vector env."""
        self.env.close()


@dataclass(frozen=True)
class SingleEntryPoint:
    """The ``entry_point`` of a task's Gymnasium id: ``gymnasium.make(id, **kwargs)`` builds a :class:`SingleEnv`.

    ``kwargs`` are the task's constructor arguments, as for ``make_vec``; the vector env is built with one env,
    autoreset off and the id's ``max_episode_steps`` (``gymnasium.make``'s own ``max_episode_steps`` only adds
    its ``TimeLimit``, so it can end episodes earlier, never later).
    """

    vector_entry_point: type | str
    """The task's env class, or ``"module:Class"`` (imported on the first ``make``)."""
    max_episode_steps: int
    """Truncation passed to the constructor, as ``make_vec`` does."""

    def __call__(self, **kwargs: Any) -> SingleEnv:
        """Build the one-env vector env with ``kwargs`` and wrap it."""
        for name in ("num_envs", "autoreset_mode"):
            if name in kwargs:
                raise ConfigError(f"gymnasium.make builds one env with autoreset off; {name}={kwargs[name]!r} "
                                  "belongs to gymnasium.make_vec(id, num_envs=N, ...)")
        kwargs.setdefault("max_episode_steps", self.max_episode_steps)
        create = self.vector_entry_point
        if isinstance(create, str):
            create = load_env_creator(create)
        return SingleEnv(create(1, autoreset_mode=AutoresetMode.DISABLED, **kwargs))
