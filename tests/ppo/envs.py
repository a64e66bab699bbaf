"""Small torch VectorEnvs with latentrl's env conventions, and a numpy SB3 VecEnv adapter, for the PPO tests.

Conventions copied from the env contract (SAME_STEP autoreset): ``infos["final_obs"]`` (N, D) dense with
``_final_obs``; ``episode = {"r", "l"}`` with ``_episode``; ``is_success`` (N,) bool; ``reward/<term>`` (N,).
"""

from __future__ import annotations

import numpy as np
import torch
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space
from stable_baselines3.common.vec_env import VecEnv

REACH_LAYOUT = {"goal_dir": [0, 3], "goal_dist": [3, 4], "text": [4, 8], "motion": [8, 12], "scene": [12, 13]}


class ReachVecEnv(VectorEnv):
    """Move a point to a goal in the plane: a stand-in for the latent reach task.

    Observation (13): ``[0:3] goal_dir`` unit vector (z = 0), ``[3:4] goal_dist`` m (clipped at 5),
    ``[4:8] text`` a fixed random embedding of one of 3 "texts", ``[8:12] motion`` last two
    displacements, ``[12:13] scene`` constant -0.9. Action (A): ``0.1 * a[:2]`` (clamped to the Box)
    is the displacement; other dims are ignored. Rewards: ``dist`` (progress, m), ``success`` (1 within
    0.2 m, terminates), ``effort`` (-mean a^2); total = dist + success + 0.01 effort. Truncated at
    ``max_episode_steps``.
    """

    def __init__(self, num_envs: int = 8, action_dim: int = 4, max_episode_steps: int = 16, device: str = "cpu"):
        self.num_envs, self.device, self.max_episode_steps = num_envs, torch.device(device), max_episode_steps
        self.single_observation_space = spaces.Box(-np.inf, np.inf, (13,), np.float32)
        self.single_action_space = spaces.Box(-4.0, 4.0, (action_dim,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "observation_layout": dict(REACH_LAYOUT)}
        self.generator = torch.Generator(device=self.device).manual_seed(0)
        self.texts = torch.randn(3, 4, generator=torch.Generator().manual_seed(7)).to(self.device)
        n, dev = num_envs, self.device
        self.pos, self.goal = torch.zeros(n, 2, device=dev), torch.zeros(n, 2, device=dev)
        self.moves = torch.zeros(n, 4, device=dev)
        self.text = torch.zeros(n, dtype=torch.long, device=dev)
        self.steps = torch.zeros(n, dtype=torch.long, device=dev)
        self.ep_return = torch.zeros(n, device=dev)

    def get_rng_state(self) -> torch.Tensor:
        return self.generator.get_state()

    def set_rng_state(self, state: torch.Tensor) -> None:
        self.generator.set_state(state)

    def _reset_envs(self, mask: torch.Tensor) -> None:
        n, g = self.num_envs, self.generator
        angle = torch.rand(n, generator=g, device=self.device) * 2 * torch.pi
        dist = 0.5 + 1.5 * torch.rand(n, generator=g, device=self.device)
        goal = torch.stack((torch.cos(angle), torch.sin(angle)), -1) * dist[:, None]
        text = torch.randint(0, 3, (n,), generator=g, device=self.device)
        m = mask[:, None]
        self.pos = torch.where(m, 0.0, self.pos)
        self.goal = torch.where(m, goal, self.goal)
        self.moves = torch.where(m, 0.0, self.moves)
        self.text = torch.where(mask, text, self.text)
        self.steps = torch.where(mask, 0, self.steps)
        self.ep_return = torch.where(mask, 0.0, self.ep_return)

    def _obs(self) -> torch.Tensor:
        delta = self.goal - self.pos
        dist = delta.norm(dim=-1, keepdim=True)
        goal_dir = torch.cat((delta / dist.clamp_min(1e-6), torch.zeros_like(dist)), -1)
        scene = torch.full_like(dist, -0.9)
        return torch.cat((goal_dir, dist.clamp(max=5.0), self.texts[self.text], self.moves, scene), -1)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        if seed is not None:
            self.generator.manual_seed(seed)
        self._reset_envs(torch.ones(self.num_envs, dtype=torch.bool, device=self.device))
        return self._obs(), {}

    def step(self, actions: torch.Tensor):
        a = torch.as_tensor(actions, device=self.device, dtype=torch.float32).clamp(-4.0, 4.0)
        old = (self.goal - self.pos).norm(dim=-1)
        move = 0.1 * a[:, :2]
        self.pos = self.pos + move
        self.moves = torch.cat((self.moves[:, 2:], move), -1)
        new = (self.goal - self.pos).norm(dim=-1)
        terms = {"dist": old - new, "success": (new < 0.2).float(), "effort": -a.square().mean(-1)}
        reward = terms["dist"] + terms["success"] + 0.01 * terms["effort"]
        self.steps += 1
        self.ep_return += reward
        terminated = new < 0.2
        truncated = (self.steps >= self.max_episode_steps) & ~terminated
        done = terminated | truncated
        infos = {f"reward/{k}": v for k, v in terms.items()}
        infos.update(final_obs=self._obs(), _final_obs=done, episode={"r": self.ep_return.clone(),
                     "l": self.steps.clone()}, _episode=done, is_success=terminated.clone())
        self._reset_envs(done)
        return self._obs(), reward, terminated, truncated, infos


class CountingVecEnv(VectorEnv):
    """Observation ``[steps into the episode, env index]``; reward 1 only at the episode's last step.

    Every episode lasts ``episode_length`` steps and then terminates (``truncate=False``) or is
    truncated (``truncate=True``); env ``n`` starts ``n % episode_length`` steps into its first episode,
    so ends are staggered. ``final_obs`` is ``[episode_length, n]``.
    """

    def __init__(self, num_envs: int = 4, episode_length: int = 5, truncate: bool = False):
        self.num_envs, self.episode_length, self.truncate = num_envs, episode_length, truncate
        self.single_observation_space = spaces.Box(-np.inf, np.inf, (2,), np.float32)
        self.single_action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.metadata = {"autoreset_mode": AutoresetMode.SAME_STEP}
        self.index = torch.arange(num_envs, dtype=torch.float32)
        self.count = torch.zeros(num_envs)

    def _obs(self) -> torch.Tensor:
        return torch.stack((self.count, self.index), -1)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        self.count = self.index % self.episode_length
        return self._obs(), {}

    def step(self, actions: torch.Tensor):
        self.count = self.count + 1
        ended = self.count >= self.episode_length
        reward = ended.float()
        final = self._obs()
        terminated = ended & (not self.truncate)
        truncated = ended & self.truncate
        self.count = torch.where(ended, 0.0, self.count)
        infos = {"final_obs": final, "_final_obs": ended,
                 "episode": {"r": torch.ones(self.num_envs), "l": torch.full((self.num_envs,), self.episode_length)},
                 "_episode": ended, "is_success": terminated.clone()}
        return self._obs(), reward, terminated, truncated, infos


class NumpyVecEnv(VecEnv):
    """SB3 ``VecEnv`` over a torch VectorEnv (what ``latentrl.envs.Sb3VecEnv`` will be): numpy out, per-env infos."""

    def __init__(self, env: VectorEnv):
        self.env = env
        super().__init__(env.num_envs, env.single_observation_space, env.single_action_space)
        self.metadata["observation_layout"] = env.metadata.get("observation_layout")
        self._actions = None

    def reset(self) -> np.ndarray:
        seed = self._seeds[0]
        obs, _ = self.env.reset(seed=seed)
        self._reset_seeds()
        return obs.cpu().numpy()

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = torch.as_tensor(actions)

    def step_wait(self):
        obs, reward, terminated, truncated, infos = self.env.step(self._actions)
        done = (terminated | truncated).cpu().numpy()
        terms = {k: v.cpu().numpy() for k, v in infos.items() if k.startswith("reward/")}
        out = [{k: float(v[i]) for k, v in terms.items()} for i in range(self.num_envs)]
        final = infos["final_obs"].cpu().numpy()
        ep_r, ep_l = infos["episode"]["r"].cpu().numpy(), infos["episode"]["l"].cpu().numpy()
        success, trunc, term = infos["is_success"].cpu().numpy(), truncated.cpu().numpy(), terminated.cpu().numpy()
        for i in np.flatnonzero(done):
            out[i].update(terminal_observation=final[i], episode={"r": float(ep_r[i]), "l": int(ep_l[i])},
                          is_success=bool(success[i]))
            out[i]["TimeLimit.truncated"] = bool(trunc[i] and not term[i])
        return obs.cpu().numpy(), reward.cpu().numpy().astype(np.float32), done, out

    def close(self) -> None:
        pass

    def get_attr(self, attr_name, indices=None):
        return [getattr(self.env, attr_name, None) for _ in self._get_indices(indices)]

    def set_attr(self, attr_name, value, indices=None) -> None:
        setattr(self.env, attr_name, value)

    def env_method(self, method_name, *method_args, indices=None, **method_kwargs):
        return [getattr(self.env, method_name)(*method_args, **method_kwargs) for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class, indices=None):
        return [False for _ in self._get_indices(indices)]

    def get_rng_state(self) -> torch.Tensor:
        return self.env.get_rng_state()

    def set_rng_state(self, state: torch.Tensor) -> None:
        self.env.set_rng_state(state)
