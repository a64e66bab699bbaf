"""DART's noise descent, shared by every noise optimizer (refine, the scene filter, the planned sit).

Adam on the noise with DART's unit gradient (each env's gradient scaled to norm 1, so a far goal and a near one
move at the same pace), the learning rate decaying linearly to 0, the noise clamped to the action bound, and each
env's lowest-loss noise kept: Adam may overshoot, and the last step is not always the best one.
"""

from __future__ import annotations

from collections.abc import Callable

import torch


def descend(start: torch.Tensor, loss_of: Callable[[torch.Tensor], torch.Tensor], steps: int, lr: float,
            bound: float, env_dim: int = 0) -> tuple[torch.Tensor, torch.Tensor]:
    """(kept noise shaped as ``start``, (N,) its loss) after ``steps`` Adam steps from ``start``.

    ``loss_of(noise) -> (N,)`` is evaluated ``steps + 1`` times (the last step's noise is scored too). The envs are
    axis ``env_dim`` of ``start``: 0 for one primitive's noise (N, 1, D), 1 for plans (S, N, 1, D), whose unit
    gradient spans all their primitives. An env whose loss is never finite keeps ``start``.
    """
    if env_dim not in (0, 1):
        raise ValueError(f"descend: env_dim must be 0 or 1, got {env_dim}")
    n = start.shape[env_dim]
    view = [1] * start.dim()
    view[env_dim] = n
    z = start.clone().requires_grad_(True)
    opt = torch.optim.Adam([z], lr=lr)
    kept, kept_loss = start.clone(), torch.full((n,), float("inf"), device=start.device)
    for step in range(steps + 1):
        with torch.enable_grad():
            loss = loss_of(z)
        with torch.no_grad():
            better = loss.detach() < kept_loss
            kept = torch.where(better.view(view), z.detach(), kept)
            kept_loss = torch.where(better, loss.detach(), kept_loss)
        if step == steps:
            break
        opt.zero_grad(set_to_none=True)
        loss.sum().backward()
        with torch.no_grad():  # DART's unit gradient per env
            g = z.grad
            norm = g.flatten(1).norm(dim=1) if env_dim == 0 else g.flatten(2).norm(dim=(0, 2))
            g /= norm.clamp(min=1e-12).view(view)
            for group in opt.param_groups:
                group["lr"] = lr * (1.0 - step / steps)
        opt.step()
        with torch.no_grad():
            z.clamp_(-bound, bound)
    return kept, kept_loss
