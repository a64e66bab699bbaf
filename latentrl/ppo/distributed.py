"""Data-parallel PPO on ``torch.distributed``: rank helpers and the collectives the runner needs.

Launched by ``torchrun`` (or ``latentrl train --nproc N``), every process is one rank with its own
envs. :func:`current` reads torchrun's ``RANK``/``WORLD_SIZE``/``LOCAL_RANK`` and returns a
:class:`Collective`; without them it returns :data:`SINGLE`, whose methods do nothing, so the
trainers run one code path. What is synchronized (rsl_rl's scheme):

- the policy's weights and buffers are broadcast from rank 0 at the start (and after a resume);
- gradients are averaged over ranks before every optimizer step (:meth:`Collective.average_gradients`),
  so Adam takes the same step everywhere and the weights stay identical;
- the observation normalizer folds in the moments of *all* ranks' rollouts (:meth:`Collective.fold_moments`);
- the approx-KL early stop decides on the mean over ranks (every rank stops at the same minibatch);
- episode statistics and reward terms are gathered for logging (:meth:`Collective.gather`);
- rank 0 alone logs, evaluates and checkpoints; the stop flag of its evaluation is broadcast.

A rank that fails makes ``torchrun`` stop the others; the process-group timeout
(``LATENTRL_DIST_TIMEOUT`` seconds, default 1800, since the other ranks wait while rank 0 evaluates)
bounds every collective in case a rank hangs.
"""

from __future__ import annotations

import datetime
import os
from collections.abc import Iterable
from typing import Any

import torch
from torch import nn

from latentrl.errors import ConfigError

TIMEOUT_VAR = "LATENTRL_DIST_TIMEOUT"
DEFAULT_TIMEOUT_S = 1800.0


def launched() -> bool:
    """Whether this process was started by torchrun (``WORLD_SIZE`` and ``RANK`` set)."""
    return "WORLD_SIZE" in os.environ and "RANK" in os.environ


def local_rank() -> int:
    """This process's GPU index on its node (torchrun's ``LOCAL_RANK``; 0 outside torchrun)."""
    return int(os.environ.get("LOCAL_RANK", "0"))


def rank_device(device: str) -> str:
    """The device of this rank: ``cuda`` (any index) becomes ``cuda:LOCAL_RANK`` under torchrun; CPU stays."""
    if launched() and torch.device(device).type == "cuda":
        if local_rank() >= torch.cuda.device_count():
            raise ConfigError(f"rank with LOCAL_RANK {local_rank()} needs GPU {local_rank()}, but this node has "
                              f"{torch.cuda.device_count()}; start at most one rank per GPU (--nproc-per-node)")
        return f"cuda:{local_rank()}"
    return device


def backend_for(device: str) -> str:
    """The process-group backend: nccl for CUDA ranks, gloo for CPU ranks."""
    return "nccl" if torch.device(device).type == "cuda" else "gloo"


class Collective:
    """One rank of a process group (or, as :data:`SINGLE`, the only process: every method is the identity)."""

    def __init__(self, rank: int = 0, world_size: int = 1):
        self.rank, self.world_size = rank, world_size

    @property
    def enabled(self) -> bool:
        """More than one rank: only then do the collectives communicate."""
        return self.world_size > 1

    @property
    def is_main(self) -> bool:
        """Rank 0: the one that logs, evaluates and writes checkpoints."""
        return self.rank == 0

    # ------------------------------------------------------------------ start
    @torch.no_grad()
    def broadcast_module(self, module: nn.Module) -> None:
        """Copy rank 0's parameters and buffers to every rank."""
        if not self.enabled:
            return
        for tensor in list(module.parameters()) + list(module.buffers()):
            torch.distributed.broadcast(tensor.data, src=0)

    def broadcast_object(self, value: Any) -> Any:
        """Rank 0's ``value`` on every rank (a run directory, a stop flag)."""
        if not self.enabled:
            return value
        box = [value]
        torch.distributed.broadcast_object_list(box, src=0)
        return box[0]

    # ------------------------------------------------------------------ update
    def average_gradients(self, params: Iterable[nn.Parameter]) -> None:
        """Replace every gradient by its mean over ranks (one flat all-reduce)."""
        if not self.enabled:
            return
        grads = [p.grad for p in params if p.grad is not None]
        if not grads:
            return
        flat = torch.cat([g.reshape(-1) for g in grads])
        torch.distributed.all_reduce(flat)
        flat /= self.world_size
        offset = 0
        for g in grads:
            g.copy_(flat[offset:offset + g.numel()].view_as(g))
            offset += g.numel()

    def mean(self, value: torch.Tensor) -> torch.Tensor:
        """Mean of a tensor over ranks (a new tensor)."""
        if not self.enabled:
            return value
        value = value.detach().clone()
        torch.distributed.all_reduce(value)
        return value / self.world_size

    @torch.no_grad()
    def fold_moments(self, normalizer: nn.Module | None, obs: torch.Tensor) -> None:
        """Fold every rank's observations ``obs`` (..., D) into ``normalizer`` (a ``RunningNormalizer``).

        Each rank's (count, mean, M2) are combined exactly (Chan et al.): two all-reduces, then the
        same ``update_from_moments`` on every rank, so the statistics stay identical.
        """
        if normalizer is None:
            return
        if not self.enabled:
            normalizer.update(obs)
            return
        batch = obs.reshape(-1, obs.shape[-1]).to(normalizer.mean.dtype)
        n_local = float(batch.shape[0])
        mean_local = batch.mean(0)
        head = torch.cat((torch.tensor([n_local], dtype=batch.dtype, device=batch.device), mean_local * n_local))
        torch.distributed.all_reduce(head)
        n = head[0]
        mean = head[1:] / n
        m2 = (batch - mean).square().sum(0)  # this rank's squared deviations from the global mean
        torch.distributed.all_reduce(m2)
        normalizer.update_from_moments(mean, m2 / n, int(n.item()))

    # ------------------------------------------------------------------ logging
    def gather(self, value: Any) -> list[Any]:
        """Every rank's picklable ``value``, in rank order (``[value]`` in one process)."""
        if not self.enabled:
            return [value]
        out: list[Any] = [None] * self.world_size
        torch.distributed.all_gather_object(out, value)
        return out

    @torch.no_grad()
    def check_identical(self, module: nn.Module) -> str | None:
        """None if ``module``'s parameters agree on every rank, else which rank and tensor differ."""
        if not self.enabled:
            return None
        names, tensors = zip(*module.named_parameters())
        sums = torch.stack([t.detach().double().sum() for t in tensors]).cpu()
        everyone = self.gather(sums)
        for r, other in enumerate(everyone):
            if not torch.equal(other, everyone[0]):
                i = int((other != everyone[0]).nonzero()[0, 0])
                return f"policy weight '{names[i]}' differs between rank 0 and rank {r}"
        return None

    def barrier(self) -> None:
        """Wait until every rank gets here (nothing to wait for in one process)."""
        if self.enabled:
            torch.distributed.barrier()


SINGLE = Collective()
"""The single-process collective (no process group)."""

_current: Collective = SINGLE


def init(device: str) -> Collective:
    """Join torchrun's process group (nccl on CUDA, gloo on CPU) once; :data:`SINGLE` when not launched."""
    global _current
    if not launched() or _current is not SINGLE:
        return _current
    if torch.device(device).type == "cuda":
        torch.cuda.set_device(local_rank())
    timeout = datetime.timedelta(seconds=float(os.environ.get(TIMEOUT_VAR, DEFAULT_TIMEOUT_S)))
    torch.distributed.init_process_group(backend_for(device), timeout=timeout)
    _current = Collective(torch.distributed.get_rank(), torch.distributed.get_world_size())
    return _current


def current() -> Collective:
    """The collective :func:`init` set up, or :data:`SINGLE`."""
    return _current


def shutdown() -> None:
    """Leave the process group (end of a run)."""
    global _current
    if _current is not SINGLE and torch.distributed.is_initialized():
        torch.distributed.destroy_process_group()
    _current = SINGLE
