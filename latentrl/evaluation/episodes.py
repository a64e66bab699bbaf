"""The batched episode loop every evaluator shares: step a no-autoreset batch until each env has ended.

Paths (:mod:`latentrl.evaluation.runner`), command timelines and timed paths (:mod:`~latentrl.evaluation.task_eval`)
all run one batch of episodes per suite entry and need the same per-env outcome: how many steps, and whether
the episode completed, diverged, got lost or ran out of steps.
"""

from __future__ import annotations

from collections.abc import Callable

import torch


def rollout(env, act: Callable[[torch.Tensor], torch.Tensor], budget: int, seed: int,
            on_step: Callable[[int, dict, torch.Tensor], None] | None = None) -> dict[str, torch.Tensor]:
    """Step a no-autoreset batch until every env ended or ``budget`` steps; per-env (CPU) outcomes.

    ``on_step(k, infos, live)`` sees every step's infos (k from 1) with the (N,) mask of envs still
    counting. Returns ``steps`` (N,) and ``complete``/``diverged``/``lost`` (N,) bool.
    """
    torch.manual_seed(seed)
    obs, _ = env.reset(seed=seed)
    n, dev = env.num_envs, env.device
    done = torch.zeros(n, dtype=torch.bool, device=dev)
    out = {k: torch.zeros(n, dtype=torch.bool, device=dev) for k in ("complete", "diverged", "lost")}
    steps = torch.full((n,), budget, dtype=torch.long, device=dev)
    for k in range(1, budget + 1):
        obs, _, terminated, truncated, infos = env.step(act(obs))
        live = ~done
        if on_step is not None:
            on_step(k, infos, live)
        out["complete"] |= infos["is_success"] & live
        out["diverged"] |= infos["diverged"] & live
        ended = live & (terminated | truncated)
        out["lost"] |= ended & terminated & ~infos["is_success"] & ~infos["diverged"]
        steps = torch.where(ended, k, steps)
        done |= ended
        if bool(done.all()):
            break
    return {"steps": steps.cpu(), **{k: v.cpu() for k, v in out.items()}}


def end_of(outcome: dict[str, torch.Tensor], i: int, complete: str = "complete") -> str:
    """How episode ``i`` ended: ``complete`` (the name its report uses), diverged, lost or timeout."""
    for name in (complete, "diverged", "lost"):
        if bool(outcome[name][i]):
            return name
    return "timeout"
