"""A single ``gymnasium.Env`` view of a one-env vector env (numpy in, numpy out).

Two uses: Gymnasium's own ``check_env`` (which only checks single envs) can then check our
dynamics, and ``gymnasium.vector.SyncVectorEnv`` over many of them is the per-env-loop baseline
the benchmark compares the batched env against.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

from latentrl.envs.base import LatentMotionVectorEnv
from latentrl.errors import ConfigError


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
