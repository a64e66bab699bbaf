"""The torch-native backend: :class:`NativeTrainer` runs :class:`~latentrl.ppo.algorithm.PPO` on a torch ``VectorEnv``.

One iteration: collect (act + store for ``num_steps`` steps, then returns) -> update -> log, with
everything on the env's device; the runner (:mod:`latentrl.ppo.runner`) evaluates, checkpoints and
guards. The env contract is :mod:`latentrl.ppo.contract` (SAME_STEP autoreset). Inside the
collection loop nothing is moved to the host (no ``.item()``); statistics are summarized once per
iteration. After each collection the rollout (observations, rewards, values, advantages) and after
each update the losses and weights are checked (one host sync each).
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from typing import Any

import numpy as np
import torch

from latentrl.monitor import RolloutStats
from latentrl.ppo.algorithm import PPO
from latentrl.ppo.config import PolicyConfig
from latentrl.ppo.contract import FINAL_OBS, action_magnitude, observation_layout, reward_weights
from latentrl.ppo.episodes import EpisodeRecorder
from latentrl.ppo.policy import ActorCritic
from latentrl.ppo.runner import (
    ROLLOUT_HINT,
    Runner,
    nonfinite_rollout,
    nonfinite_update,
    stop_if_nonfinite,
)


def _now(device: torch.device) -> float:
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return time.perf_counter()


class NativeTrainer(Runner):
    """Torch-native PPO on a torch ``VectorEnv`` (arguments: :class:`~latentrl.ppo.runner.Runner`)."""

    name = "native"

    def build(self, policy_cfg: PolicyConfig, layout: Mapping[str, Any] | None) -> None:
        """Our PPO, its rollout buffer and the episode recorder, sized for this env."""
        env, ppo = self.env, self.cfg
        self.device = torch.device(ppo.device)
        obs_dim = int(np.prod(env.single_observation_space.shape))
        action_dim = int(np.prod(env.single_action_space.shape))
        self.policy = ActorCritic(obs_dim, action_dim, policy_cfg, observation_layout(env, layout)).to(self.device)
        self.algorithm = PPO(self.policy, ppo, self.plan, env.num_envs, self.device, self.dist)
        self.optimizer, self.buffer = self.algorithm.optimizer, self.algorithm.buffer
        self.episodes = EpisodeRecorder(ppo.num_steps, env.num_envs, self.device, ppo.stats_window,
                                        reward_weights(env))
        space = env.single_action_space
        self.action_low = torch.as_tensor(space.low, dtype=torch.float32, device=self.device)
        self.action_high = torch.as_tensor(space.high, dtype=torch.float32, device=self.device)

    def rollout_stats(self) -> RolloutStats:
        """Statistics of the episode recorder's rolling window."""
        return self.episodes.stats()

    def _reset_env(self) -> torch.Tensor:
        """Fresh runs reset with ``seed``; resumed runs with ``seed + iteration``, then restore the saved RNGs.

        An env whose saved state covers its episodes (latentrl's envs) continues them: its
        ``observation()`` after the restore is where the interrupted run stood. Under torchrun rank r
        resets with ``seed + r + iteration * world_size`` (distinct on every rank).
        """
        obs, _ = self.env.reset(seed=self.rank_seed + self.iteration * self.dist.world_size)
        if self.restore_pending_rng() and callable(getattr(self.env, "observation", None)):
            obs = self.env.observation()
        return torch.as_tensor(obs)

    @torch.no_grad()
    def collect(self, obs: torch.Tensor) -> torch.Tensor:
        """Fill the buffer with ``num_steps`` steps from ``obs`` (N, D); compute GAE; return the next obs."""
        env_device, ppo, cfg = obs.device, self.algorithm, self.cfg
        for t in range(cfg.num_steps):
            obs = obs.to(self.device)
            step = ppo.act(obs)
            action = step.action.clamp(self.action_low, self.action_high) if cfg.clip_actions else step.action
            next_obs, reward, terminated, truncated, infos = self.env.step(action.to(env_device))
            ppo.store(t, obs, step, reward, terminated, truncated, infos.get(FINAL_OBS))
            self.episodes.record(t, infos)
            obs = torch.as_tensor(next_obs)
        ppo.compute_returns(obs.to(self.device))
        return obs

    def action_magnitude(self) -> tuple[float, float] | None:
        """``(mean |z|, share beyond sqrt(d))`` of this rank's last rollout, as the env received the actions."""
        actions = self.buffer.actions
        if self.cfg.clip_actions:
            actions = actions.clamp(self.action_low, self.action_high)
        return action_magnitude(actions)

    def update(self) -> dict[str, float]:
        """One PPO update over the collected rollout; returns its statistics."""
        return self.algorithm.update()

    def learn(self) -> None:
        """Collect, update, log, evaluate and checkpoint until the planned iterations are done or a stop is asked."""
        obs = self._reset_env()
        self.restart_clock()
        while self.iteration < self.plan.num_iterations and not self.stop_requested:
            lr = self.algorithm.set_learning_rate(self.iteration)
            t0 = _now(self.device)
            obs = self.collect(obs)
            stop_if_nonfinite(self, self.bar, nonfinite_rollout(self.buffer), ROLLOUT_HINT)
            summary = self.episodes.summarize(self.dist)
            t1 = _now(self.device)
            self.last_train = {**self.update(), "learning_rate": lr}
            stop_if_nonfinite(self, self.bar, nonfinite_update(self.last_train, self.policy))
            t2 = _now(self.device)
            fps = self.count_iteration(self.env_steps + self.global_batch_size, t1 - t0, t2 - t1)
            if self.logging_now:
                step, monitor = self.env_steps, self.monitor
                monitor.log_rollout(step, summary.stats, summary.diverged)
                monitor.log_train(step, self.last_train)
                monitor.log_rewards(step, summary.reward_terms)
                monitor.log_episode_rewards(step, summary.episode_terms)
                monitor.log_actions(step, *(self.action_magnitude() or (None, None)))
                monitor.log_time(step, fps, t1 - t0, t2 - t1)
                self.bar.log_iteration(self.iteration, step, fps, summary.stats, self.last_train, t1 - t0, t2 - t1,
                                       summary.reward_terms, summary.diverged)
            self.finish_iteration(fps, summary.stats)
