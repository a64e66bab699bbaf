"""Stable-Baselines3 adapter: ``PPO("MlpPolicy", Sb3VecEnv(env))`` trains on a torch vector env.

Modelled on Isaac Lab's fast ``Sb3VecEnvWrapper``: one device-to-host copy per output tensor,
and the episode-end keys (``terminal_observation``, ``TimeLimit.truncated``, ``episode``,
``is_success``) only in the info dicts of envs whose episode ended, which is all SB3 reads.
Every info dict also carries the unweighted ``reward/<term>`` floats of its env (what
:mod:`latentrl.ppo.sb3` logs); ``reward_terms=False`` drops them to save the per-env Python work.
Envs whose motion diverged this step get ``diverged=True`` (counted as ``rollout/diverged``).
The wrapped env must use SAME_STEP autoreset, SB3's own convention.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env import VecEnv

from latentrl.envs.base import LatentMotionVectorEnv
from latentrl.errors import ConfigError


def _numpy(x: torch.Tensor) -> np.ndarray:
    return x.detach().cpu().numpy()


class Sb3VecEnv(VecEnv):
    """SB3 ``VecEnv`` view of a :class:`~latentrl.envs.base.LatentMotionVectorEnv`.

    Observations and rewards come back as numpy float32, dones as bool. ``seed(s)`` then
    ``reset()`` seeds the wrapped env with ``s``. ``get_attr``/``set_attr``/``env_method``
    act on the one batched env and repeat its answer per index. ``metadata`` keeps the env's
    ``observation_layout`` and ``observation_fields``.

    Args:
        env: the torch env (``autoreset_mode`` SAME_STEP).
        reward_terms: put each env's ``reward/<term>`` values in its info dict at every step.
    """

    reports_diverged = True
    """Info dicts carry ``diverged=True`` for envs whose motion diverged (absent otherwise)."""

    def __init__(self, env: LatentMotionVectorEnv, reward_terms: bool = True):
        if env.metadata.get("autoreset_mode") != AutoresetMode.SAME_STEP:
            raise ConfigError("Sb3VecEnv needs an env with autoreset_mode=SAME_STEP (SB3 resets in the same step)")
        self.env = env
        self._actions: np.ndarray | None = None
        self._start = time.perf_counter()
        self.reward_terms = reward_terms
        super().__init__(env.num_envs, env.single_observation_space, env.single_action_space)
        self.metadata = {**env.metadata, "render_modes": self.metadata["render_modes"]}

    def reset(self) -> np.ndarray:
        """Reset every env (with the seed of :meth:`seed`, if one was set); numpy observations."""
        obs, _ = self.env.reset(seed=self._seeds[0])
        self._reset_seeds()
        self._reset_options()
        self.reset_infos = [{} for _ in range(self.num_envs)]
        return _numpy(obs).astype(np.float32, copy=False)

    def step_async(self, actions: np.ndarray) -> None:
        """Keep the actions for :meth:`step_wait` (the torch env steps synchronously)."""
        self._actions = actions

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        """Step the torch env; numpy observations, rewards, dones and per-env SB3 infos."""
        obs, reward, terminated, truncated, infos = self.env.step(self._actions)
        terminated, truncated = _numpy(terminated), _numpy(truncated)
        dones = terminated | truncated
        out = self._reward_infos(infos) if self.reward_terms else [{} for _ in range(self.num_envs)]
        for i in np.flatnonzero(_numpy(infos["diverged"])):
            out[i]["diverged"] = True
        done_ids = np.flatnonzero(dones)
        if len(done_ids):
            final = _numpy(infos["final_obs"])
            success = _numpy(infos["is_success"])
            ret, length = _numpy(infos["episode"]["r"]), _numpy(infos["episode"]["l"])
            elapsed = round(time.perf_counter() - self._start, 6)
            for i in done_ids:
                out[i].update(
                    terminal_observation=final[i],
                    episode={"r": float(ret[i]), "l": int(length[i]), "t": elapsed},
                    is_success=bool(success[i]),
                )
                out[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
        return _numpy(obs), _numpy(reward), dones, out

    def _reward_infos(self, infos: dict[str, Any]) -> list[dict[str, Any]]:
        """One dict per env holding its ``reward/<term>`` floats."""
        terms = {k: _numpy(v).tolist() for k, v in infos.items() if k.startswith("reward/")}
        return [{k: values[i] for k, values in terms.items()} for i in range(self.num_envs)]

    def close(self) -> None:
        """Close the torch env."""
        self.env.close()

    def _indices(self, indices: None | int | Sequence[int]) -> list[int]:
        return list(self._get_indices(indices))

    def get_attr(self, attr_name: str, indices: None | int | Sequence[int] = None) -> list[Any]:
        """The torch env's attribute, once per selected env (they share one object)."""
        value = getattr(self.env, attr_name)
        return [value for _ in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: None | int | Sequence[int] = None) -> None:
        """Set the attribute on the torch env (shared by every index)."""
        setattr(self.env, attr_name, value)

    def env_method(
        self, method_name: str, *method_args, indices: None | int | Sequence[int] = None, **method_kwargs
    ) -> list[Any]:
        """Call the torch env's method once, and return its result once per selected env."""
        result = getattr(self.env, method_name)(*method_args, **method_kwargs)
        return [result for _ in self._indices(indices)]

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper], indices: None | int | Sequence[int] = None
    ) -> list[bool]:
        """False for every selected env: the torch env sits in no Gymnasium wrapper."""
        return [False for _ in self._indices(indices)]

    def get_images(self) -> Sequence[np.ndarray | None]:
        """No images: these envs do not render (export histories and render them with :mod:`latentrl.render`)."""
        return [None for _ in range(self.num_envs)]
