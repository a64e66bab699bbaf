"""The PPO update: clipped surrogate, clipped value loss and entropy over minibatches (Schulman et al. 2017).

The math follows CleanRL's ``ppo_continuous_action.py`` (which DART adapted). The logged statistics
follow SB3's ``PPO.train`` so that native and SB3 runs overlay in TensorBoard:

- ``policy_gradient_loss``, ``value_loss``, ``entropy_loss`` (= -entropy), ``clip_fraction``: means
  over every minibatch of every epoch run;
- ``approx_kl``: mean over the minibatches of the last epoch run, estimator ``E[(r - 1) - log r]``
  (http://joschu.net/blog/kl-approx.html);
- ``value_loss`` is logged *without* CleanRL's factor 0.5 (SB3's MSE scale); the loss uses
  ``vf_coef * 0.5 * value_loss``, so ``vf_coef`` means what it means in CleanRL and DART.
"""

from __future__ import annotations

from typing import NamedTuple

import torch
from torch import nn

from latentrl.ppo.config import PPOConfig
from latentrl.ppo.distributed import SINGLE, Collective
from latentrl.ppo.policy import ActorCritic
from latentrl.ppo.storage import Batch, RolloutBuffer


class LossTerms(NamedTuple):
    """Scalar tensors of one minibatch; ``loss`` carries the graph, the rest are detached."""

    loss: torch.Tensor
    policy_loss: torch.Tensor
    value_loss: torch.Tensor
    entropy: torch.Tensor
    approx_kl: torch.Tensor
    clip_fraction: torch.Tensor


def ppo_loss(policy: ActorCritic, batch: Batch, cfg: PPOConfig) -> LossTerms:
    """Clipped PPO objective of one minibatch, to be minimized."""
    new = policy.evaluate(batch.obs, batch.actions)
    log_ratio = new.log_prob - batch.log_probs
    ratio = log_ratio.exp()  # r = pi(a|s) / pi_old(a|s)
    adv = batch.advantages
    if cfg.norm_adv and adv.numel() > 1:
        adv = (adv - adv.mean()) / (adv.std() + 1e-8)
    # L^CLIP = E[min(r A, clip(r, 1 - eps, 1 + eps) A)]; we minimize its negative
    eps = cfg.clip_coef
    policy_loss = torch.max(-adv * ratio, -adv * ratio.clamp(1.0 - eps, 1.0 + eps)).mean()
    # L^VF = (V - R)^2, optionally max'ed with the loss of V clipped to V_old +/- eps
    value_sq = (new.value - batch.returns).square()
    if cfg.clip_vloss:
        clipped = batch.values + (new.value - batch.values).clamp(-eps, eps)
        value_sq = torch.max(value_sq, (clipped - batch.returns).square())
    value_loss = value_sq.mean()
    entropy = new.entropy.mean()
    loss = policy_loss - cfg.ent_coef * entropy + cfg.vf_coef * 0.5 * value_loss
    with torch.no_grad():
        approx_kl = ((ratio - 1.0) - log_ratio).mean()
        clip_fraction = ((ratio - 1.0).abs() > eps).float().mean()
    return LossTerms(loss, policy_loss.detach(), value_loss.detach(), entropy.detach(), approx_kl, clip_fraction)


def explained_variance(values: torch.Tensor, returns: torch.Tensor) -> torch.Tensor:
    """``1 - Var[R - V] / Var[R]``: 1 is a perfect critic, 0 no better than a constant; NaN if Var[R] = 0."""
    var_returns = returns.var()
    return torch.where(var_returns == 0, torch.nan, 1.0 - (returns - values).var() / var_returns)


def ppo_update(policy: ActorCritic, optimizer: torch.optim.Optimizer, buffer: RolloutBuffer, cfg: PPOConfig,
               minibatch_size: int, collective: Collective = SINGLE) -> dict[str, float]:
    """Run ``cfg.update_epochs`` epochs of minibatch steps on a filled buffer; return SB3-named stats.

    Each step clips the global gradient norm to ``cfg.max_grad_norm``. With ``cfg.target_kl`` set, the
    update stops before the step of the first minibatch whose approx-KL exceeds ``1.5 * target_kl``
    (SB3's rule; this costs one host sync per minibatch, none otherwise).

    Under ``torchrun`` (``collective`` of several ranks) the gradients are averaged over ranks before
    clipping, and the KL early stop reads the mean approx-KL over ranks, so every rank steps alike.
    """
    dev = buffer.device
    totals = torch.zeros(5, device=dev)  # policy, value, entropy, clip fraction, grad norm
    grad_steps, minibatches, epochs_run, stopped = 0, 0, 0, False
    for _ in range(cfg.update_epochs):
        kl_sum, kl_count = torch.zeros((), device=dev), 0
        for batch in buffer.minibatches(minibatch_size):
            terms = ppo_loss(policy, batch, cfg)
            totals[:4] += torch.stack((terms.policy_loss, terms.value_loss, terms.entropy, terms.clip_fraction))
            kl_sum, kl_count, minibatches = kl_sum + terms.approx_kl, kl_count + 1, minibatches + 1
            if cfg.target_kl is not None and float(collective.mean(terms.approx_kl)) > 1.5 * cfg.target_kl:
                stopped = True
                break
            optimizer.zero_grad(set_to_none=True)
            terms.loss.backward()
            collective.average_gradients(policy.parameters())
            totals[4] += nn.utils.clip_grad_norm_(policy.parameters(), cfg.max_grad_norm).detach()
            optimizer.step()
            grad_steps += 1
        epochs_run += 1
        if stopped:
            break
    flat = buffer.flat()
    means = (totals[:4] / minibatches).tolist()
    return {
        "policy_gradient_loss": means[0],
        "value_loss": means[1],
        "entropy_loss": -means[2],
        "clip_fraction": means[3],
        "approx_kl": float(kl_sum / kl_count),
        "loss": float(terms.loss.detach()),
        "explained_variance": float(explained_variance(flat.values, flat.returns)),
        "std": float(policy.log_std.detach().exp().mean()),
        "clip_range": cfg.clip_coef,
        "grad_norm": float(totals[4] / max(grad_steps, 1)),
        "epochs": float(epochs_run),
        "early_stop": float(stopped),
    }
