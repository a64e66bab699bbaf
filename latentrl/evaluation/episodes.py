"""The batched episode loop every evaluator shares: step a no-autoreset batch until each env has ended.

Paths (:mod:`latentrl.evaluation.runner`), command timelines and timed paths (:mod:`~latentrl.evaluation.task_eval`)
all run one batch of episodes per suite entry and need the same per-env outcome: how many steps, and whether
the episode completed, diverged, got lost or ran out of steps.
"""

from __future__ import annotations

import contextlib
import contextvars
from collections.abc import Callable, Iterator

import torch

_RETURNS: contextvars.ContextVar[list[float] | None] = contextvars.ContextVar("latentrl_eval_returns", default=None)


@contextlib.contextmanager
def collect_returns() -> Iterator[list[float]]:
    """Gather the return (rewards summed until it ended) of every episode :func:`rollout` runs inside the block.

    A context rather than a result field: every evaluator runs its episodes through :func:`rollout`,
    so the trainer's periodic evaluation logs ``eval/mean_reward`` for every task without each
    evaluator's results (and reports) carrying rewards.
    """
    returns: list[float] = []
    token = _RETURNS.set(returns)
    try:
        yield returns
    finally:
        _RETURNS.reset(token)


def rollout(env, act: Callable[[torch.Tensor], torch.Tensor], budget: int, seed: int,
            on_step: Callable[[int, dict, torch.Tensor], None] | None = None) -> dict[str, torch.Tensor]:
    """Step a no-autoreset batch until every env ended or ``budget`` steps; per-env (CPU) outcomes.

    ``on_step(k, infos, live)`` sees every step's infos (k from 1) with the (N,) mask of envs still
    counting. Returns ``steps`` (N,) and ``complete``/``diverged``/``lost`` (N,) bool; inside
    :func:`collect_returns` each env's return joins the collected list.
    """
    torch.manual_seed(seed)
    obs, _ = env.reset(seed=seed)
    n, dev = env.num_envs, env.device
    done = torch.zeros(n, dtype=torch.bool, device=dev)
    out = {k: torch.zeros(n, dtype=torch.bool, device=dev) for k in ("complete", "diverged", "lost")}
    steps = torch.full((n,), budget, dtype=torch.long, device=dev)
    returns = _RETURNS.get()
    total = torch.zeros(n, device=dev)
    for k in range(1, budget + 1):
        obs, reward, terminated, truncated, infos = env.step(act(obs))
        live = ~done
        if returns is not None:
            total += torch.as_tensor(reward, dtype=total.dtype, device=dev) * live
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
    if returns is not None:
        returns.extend(total.cpu().tolist())
    return {"steps": steps.cpu(), **{k: v.cpu() for k, v in out.items()}}


def end_of(outcome: dict[str, torch.Tensor], i: int, complete: str = "complete") -> str:
    """How episode ``i`` ended: ``complete`` (the name its report uses), diverged, lost or timeout."""
    for name in (complete, "diverged", "lost"):
        if bool(outcome[name][i]):
            return name
    return "timeout"
