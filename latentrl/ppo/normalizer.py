"""Running observation normalization whose statistics live in the policy's state dict.

The statistics are buffers, so they travel with ``ActorCritic.state_dict()`` into every checkpoint
and onto the policy's device. They change only when a trainer calls :meth:`RunningNormalizer.update`;
``forward`` never updates, which is what "frozen at evaluation" means here.

Both trainers update once per iteration, *after* the PPO update, from that iteration's rollout
observations. The statistics are therefore constant within an iteration, so the log-probabilities
recomputed during the update match the ones stored during collection (the first-epoch ratio is 1).
"""

from __future__ import annotations

import torch
from torch import nn


class RunningNormalizer(nn.Module):
    """``clip((x - mean) / sqrt(var + eps), -clip, clip)`` with Chan et al.'s parallel mean/var update.

    Before the first update (count 0) the mean is 0 and the variance 1, so ``forward`` only clips.
    """

    def __init__(self, dim: int, clip: float = 10.0, eps: float = 1e-8):
        super().__init__()
        self.clip, self.eps = float(clip), float(eps)
        self.register_buffer("mean", torch.zeros(dim))
        self.register_buffer("var", torch.ones(dim))
        self.register_buffer("count", torch.zeros((), dtype=torch.float64))

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """Normalize ``obs`` (..., D) with the current statistics (never updates them)."""
        return ((obs - self.mean) * torch.rsqrt(self.var + self.eps)).clamp(-self.clip, self.clip)

    @torch.no_grad()
    def update(self, obs: torch.Tensor) -> None:
        """Fold a batch ``obs`` (..., D) into the running statistics."""
        batch = obs.reshape(-1, obs.shape[-1]).to(self.mean.dtype)
        self.update_from_moments(batch.mean(0), batch.var(0, unbiased=False), batch.shape[0])

    @torch.no_grad()
    def update_from_moments(self, mean: torch.Tensor, var: torch.Tensor, count: int) -> None:
        """Combine (mean, var, count) of a batch with the running ones (Chan, Golub & LeVeque 1979).

        With ``n_a, n_b`` counts and ``delta = mean_b - mean_a``:
        ``mean = mean_a + delta * n_b / n``, ``M2 = var_a n_a + var_b n_b + delta^2 n_a n_b / n``, ``var = M2 / n``.
        """
        if count <= 0:
            return
        mean = torch.as_tensor(mean, dtype=self.mean.dtype, device=self.mean.device)
        var = torch.as_tensor(var, dtype=self.var.dtype, device=self.var.device)
        n_a, n_b = self.count.to(self.mean.dtype), float(count)
        n = n_a + n_b
        delta = mean - self.mean
        m2 = self.var * n_a + var * n_b + delta.square() * n_a * n_b / n
        self.mean += delta * n_b / n
        self.var.copy_(m2 / n)
        self.count += count
