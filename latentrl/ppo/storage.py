"""Preallocated (T, N, ...) rollout storage on the device, GAE, and minibatches as named ``Batch`` tuples.

Index convention: row ``t`` holds the observation ``s_t`` the policy acted on, its action, log-prob
and value, the reward ``r_t`` the env returned, and ``done_t`` = the episode ended *in* step t
(terminated or truncated). With SAME_STEP autoreset ``obs[t + 1]`` then already belongs to the next
episode, and the observation that ended the episode is ``final_obs[t]``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import NamedTuple

import torch


class Batch(NamedTuple):
    """One minibatch of flattened transitions (B = minibatch size)."""

    obs: torch.Tensor
    """(B, D) raw observations."""
    actions: torch.Tensor
    """(B, A) sampled (unclamped) actions."""
    log_probs: torch.Tensor
    """(B,) log-probabilities at collection time."""
    values: torch.Tensor
    """(B,) value estimates at collection time."""
    advantages: torch.Tensor
    """(B,) GAE advantages (not normalized)."""
    returns: torch.Tensor
    """(B,) value targets ``advantages + values``."""


class RolloutBuffer:
    """Tensors for one PPO iteration: T steps of N envs, allocated once on ``device``."""

    def __init__(self, num_steps: int, num_envs: int, obs_dim: int, action_dim: int,
                 device: str | torch.device = "cpu"):
        T, N, dev = num_steps, num_envs, torch.device(device)
        self.num_steps, self.num_envs, self.device = T, N, dev
        self.obs = torch.zeros(T, N, obs_dim, device=dev)
        self.actions = torch.zeros(T, N, action_dim, device=dev)
        self.log_probs = torch.zeros(T, N, device=dev)
        self.values = torch.zeros(T, N, device=dev)
        self.rewards = torch.zeros(T, N, device=dev)
        self.dones = torch.zeros(T, N, dtype=torch.bool, device=dev)
        """(T, N) the episode ended in step t (terminated or truncated)."""
        self.time_outs = torch.zeros(T, N, dtype=torch.bool, device=dev)
        """(T, N) truncated and not terminated: the return continues beyond ``final_obs``."""
        self.final_obs = torch.zeros(T, N, obs_dim, device=dev)
        """(T, N, D) the last observation of each ended episode (meaningful where ``dones``)."""
        self.advantages = torch.zeros(T, N, device=dev)
        self.returns = torch.zeros(T, N, device=dev)

    def insert(self, t: int, obs: torch.Tensor, actions: torch.Tensor, log_probs: torch.Tensor,
               values: torch.Tensor, rewards: torch.Tensor, terminated: torch.Tensor, truncated: torch.Tensor,
               final_obs: torch.Tensor | None = None) -> None:
        """Store step ``t``: obs (N, D), actions (N, A), log_probs/values/rewards (N,), terminated/truncated (N,) bool.

        ``final_obs`` (N, D) is the env's ``infos["final_obs"]``; only rows that ended are read. Without
        it no truncation of this step can be bootstrapped. No host synchronisation happens here.
        """
        self.obs[t].copy_(obs)
        self.actions[t].copy_(actions)
        self.log_probs[t].copy_(log_probs)
        self.values[t].copy_(values)
        self.rewards[t].copy_(rewards)
        terminated, truncated = terminated.to(self.device, torch.bool), truncated.to(self.device, torch.bool)
        torch.logical_or(terminated, truncated, out=self.dones[t])
        if final_obs is None:
            self.time_outs[t].zero_()
        else:
            torch.logical_and(truncated, ~terminated, out=self.time_outs[t])
            self.final_obs[t].copy_(final_obs)

    @torch.no_grad()
    def compute_returns(self, last_value: torch.Tensor, value_fn: Callable[[torch.Tensor], torch.Tensor],
                        gamma: float, gae_lambda: float, bootstrap_truncated: bool = True) -> None:
        """Fill ``advantages`` and ``returns`` with GAE(gamma, lambda) (Schulman et al. 2016, eq. 16).

        Args:
            last_value: (N,) V(s_T), the value of the observation after the last step.
            value_fn: critic on raw observations (M, D) -> (M,), called once on all time-out rows.
            gamma: discount per step.
            gae_lambda: GAE lambda.
            bootstrap_truncated: add ``gamma * V(final_obs)`` to time-out rewards; otherwise a
                truncation is treated like a termination (DART).
        """
        rewards = self.rewards.clone()
        if bootstrap_truncated:
            # r_t <- r_t + gamma V(s_final) where the episode was cut off by time: one batched critic call
            rows = self.time_outs.nonzero(as_tuple=True)
            if rows[0].numel():
                rewards[rows] += gamma * value_fn(self.final_obs[rows])
        next_value, next_advantage = last_value, torch.zeros_like(last_value)
        for t in reversed(range(self.num_steps)):
            not_done = (~self.dones[t]).float()
            # delta_t = r_t + gamma V(s_{t+1}) (1 - done_t) - V(s_t)
            delta = rewards[t] + gamma * next_value * not_done - self.values[t]
            # A_t = delta_t + gamma lambda (1 - done_t) A_{t+1}
            next_advantage = delta + gamma * gae_lambda * not_done * next_advantage
            self.advantages[t] = next_advantage
            next_value = self.values[t]
        # R_t = A_t + V(s_t): the TD(lambda) target of the value loss
        torch.add(self.advantages, self.values, out=self.returns)

    def flat(self) -> Batch:
        """All T * N transitions as one ``Batch`` of views (row index = t * N + n)."""
        T, N = self.num_steps, self.num_envs
        return Batch(self.obs.view(T * N, -1), self.actions.view(T * N, -1), self.log_probs.view(-1),
                     self.values.view(-1), self.advantages.view(-1), self.returns.view(-1))

    def minibatches(self, minibatch_size: int, generator: torch.Generator | None = None) -> Iterator[Batch]:
        """One epoch: a random permutation of all transitions cut into ``minibatch_size`` rows each."""
        flat = self.flat()
        total = flat.obs.shape[0]
        perm = torch.randperm(total, device=self.device, generator=generator)
        for start in range(0, total, minibatch_size):
            idx = perm[start : start + minibatch_size]
            yield Batch(*(field[idx] for field in flat))
