"""PPO, the algorithm (Schulman et al. 2017, CleanRL's continuous-action variant as DART adapted it), in paper order.

For each iteration: **act** with the current policy and **store** the transition for ``num_steps``
steps of every env; compute the **returns** (GAE advantages, bootstrapping truncated episodes);
**update** the policy with clipped-surrogate epochs over minibatches. The loop around it (envs,
logging, evaluation, checkpoints) is the runner's (:mod:`latentrl.ppo.runner`).
"""

from __future__ import annotations

from typing import Any

import torch

from latentrl.ppo.config import BatchPlan, PPOConfig
from latentrl.ppo.distributed import SINGLE, Collective
from latentrl.ppo.policy import ActorCritic, PolicyStep
from latentrl.ppo.storage import RolloutBuffer
from latentrl.ppo.update import ppo_update


def adam_kwargs(ppo: PPOConfig) -> dict[str, Any]:
    """Adam settings of both trainers: ``eps`` from the config, and the fused kernel where torch has one.

    Fused means one kernel for all parameters instead of a loop over ~30 tensors: ~25% off a small policy's step.
    """
    return {"eps": ppo.adam_eps, "fused": torch.device(ppo.device).type in ("cpu", "cuda")}


class PPO:
    """The policy, its optimizer and the rollout buffer of ``plan.num_steps`` x ``num_envs`` transitions."""

    def __init__(self, policy: ActorCritic, cfg: PPOConfig, plan: BatchPlan, num_envs: int, device: torch.device,
                 collective: Collective = SINGLE):
        self.policy, self.cfg, self.plan, self.collective = policy, cfg, plan, collective
        self.optimizer = torch.optim.Adam(policy.parameters(), lr=cfg.learning_rate, **adam_kwargs(cfg))
        self.buffer = RolloutBuffer(cfg.num_steps, num_envs, policy.obs_dim, policy.action_dim, device)

    # 1. act
    def act(self, obs: torch.Tensor) -> PolicyStep:
        """Sample actions (with log-probs and values) for observations (N, D)."""
        return self.policy.act(obs)

    # 2. store
    def store(self, t: int, obs: torch.Tensor, step: PolicyStep, reward: Any, terminated: Any, truncated: Any,
              final_obs: Any = None) -> None:
        """Keep step ``t``'s transition (the unclipped action the policy sampled)."""
        self.buffer.insert(t, obs, step.action, step.log_prob, step.value, torch.as_tensor(reward),
                           torch.as_tensor(terminated), torch.as_tensor(truncated),
                           None if final_obs is None else torch.as_tensor(final_obs))

    # 3. returns
    def compute_returns(self, next_obs: torch.Tensor) -> None:
        """GAE advantages and returns of the filled buffer, bootstrapped from the observation after it."""
        cfg = self.cfg
        self.buffer.compute_returns(self.policy.value(next_obs), self.policy.value, cfg.gamma, cfg.gae_lambda,
                                    cfg.bootstrap_truncated)

    # 4. update
    def set_learning_rate(self, iteration: int) -> float:
        """CleanRL's annealing: ``lr_k = (1 - k / K) lr_0`` for iteration k = 0..K-1."""
        lr = self.cfg.learning_rate
        if self.cfg.anneal_lr:
            lr *= 1.0 - iteration / self.plan.num_iterations
        for group in self.optimizer.param_groups:
            group["lr"] = lr
        return lr

    def update(self) -> dict[str, float]:
        """PPO epochs on the filled buffer, then fold this rollout (every rank's) into the observation normalizer."""
        self.policy.train()
        stats = ppo_update(self.policy, self.optimizer, self.buffer, self.cfg, self.plan.minibatch_size,
                           self.collective)
        self.collective.fold_moments(self.policy.obs_normalizer, self.buffer.obs)
        self.policy.eval()
        return stats
