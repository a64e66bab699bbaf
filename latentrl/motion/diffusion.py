"""Gaussian diffusion over latents: schedules, respacing, ``q_sample``, DDPM and DDIM loops.

Follows DART (itself MDM / guided-diffusion): tables in float64, but every value gathered for a
step is cast to float32 *before* touching ``x`` (``_extract_into_tensor``), which matters for
bit-level parity. The model predicts ``x_0`` (DART's ``ModelMeanType.START_X``), and variances
are ``FIXED_SMALL`` (``sigma_small``) by default.

A ``model_fn(x_t, t)`` is any callable returning the x0 prediction for step ``t`` (an int64 tensor
of *original* step indices); classifier-free guidance lives in the caller
(:class:`latentrl.motion.rollout.MotionModel`), not here.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch


@dataclass
class DiffusionConfig:
    """DART's ``DiffusionArgs``."""

    diffusion_steps: int = 10
    """Training steps T."""
    noise_schedule: str = "cosine"
    """'cosine' or 'linear'."""
    sigma_small: bool = True
    """FIXED_SMALL posterior variances (DART) instead of FIXED_LARGE."""
    respacing: str = ""
    """Which steps sampling visits: '' (all), 'ddimN', or comma-separated section counts."""


def betas_for_schedule(name: str, steps: int) -> np.ndarray:
    """(steps,) float64 betas of the named schedule (Nichol & Dhariwal's cosine, max beta 0.999)."""
    if name == "linear":
        scale = 1000 / steps
        return np.linspace(scale * 0.0001, scale * 0.02, steps, dtype=np.float64)
    if name == "cosine":

        def alpha_bar(t: float) -> float:
            return math.cos((t + 0.008) / 1.008 * math.pi / 2) ** 2

        return np.array(
            [min(1 - alpha_bar((i + 1) / steps) / alpha_bar(i / steps), 0.999) for i in range(steps)], dtype=np.float64
        )
    raise ValueError(f"unknown noise schedule {name!r}; expected 'cosine' or 'linear'")


def space_timesteps(num_timesteps: int, respacing: str) -> list[int]:
    """Original step indices kept by a respacing spec ('' keeps all; 'ddimN'; 'a,b,...' sections)."""
    if respacing in ("", None):
        return list(range(num_timesteps))
    if respacing.startswith("ddim"):
        desired = int(respacing[len("ddim") :])
        for stride in range(1, num_timesteps + 1):
            if len(range(0, num_timesteps, stride)) == desired:
                return list(range(0, num_timesteps, stride))
        raise ValueError(f"cannot create exactly {desired} steps with an integer stride from {num_timesteps}")
    counts = [int(c) for c in respacing.split(",")]
    size_per, extra = divmod(num_timesteps, len(counts))
    kept, start = [], 0
    for i, count in enumerate(counts):
        size = size_per + (1 if i < extra else 0)
        if size < count:
            raise ValueError(f"cannot divide a section of {size} steps into {count}")
        frac = 1 if count <= 1 else (size - 1) / (count - 1)
        cur = 0.0
        for _ in range(count):
            kept.append(start + round(cur))
            cur += frac
        start += size
    return sorted(set(kept))


class GaussianDiffusion:
    """Diffusion tables for the visited steps, and the sampling loops."""

    def __init__(self, config: DiffusionConfig):
        self.config = config
        base_betas = betas_for_schedule(config.noise_schedule, config.diffusion_steps)
        self.timestep_map = space_timesteps(config.diffusion_steps, config.respacing)
        base_acp = np.cumprod(1.0 - base_betas)
        self.base_alphas_cumprod = base_acp
        """Cumulative alphas of the un-respaced process, by original step index (what the model sees)."""
        if len(self.timestep_map) == config.diffusion_steps:
            betas = base_betas
        else:  # respaced: recompute betas from the kept cumulative products (guided-diffusion)
            betas, last = [], 1.0
            for i in self.timestep_map:
                betas.append(1 - base_acp[i] / last)
                last = base_acp[i]
            betas = np.array(betas, dtype=np.float64)
        self.betas = betas
        self.num_timesteps = len(betas)
        acp = np.cumprod(1.0 - betas)
        acp_prev = np.append(1.0, acp[:-1])
        self.alphas_cumprod, self.alphas_cumprod_prev = acp, acp_prev
        self.sqrt_alphas_cumprod = np.sqrt(acp)
        self.sqrt_one_minus_alphas_cumprod = np.sqrt(1.0 - acp)
        self.sqrt_recip_alphas_cumprod = np.sqrt(1.0 / acp)
        self.sqrt_recipm1_alphas_cumprod = np.sqrt(1.0 / acp - 1)
        self.posterior_variance = betas * (1.0 - acp_prev) / (1.0 - acp)
        self.posterior_log_variance_clipped = np.log(np.append(self.posterior_variance[1], self.posterior_variance[1:]))
        self.posterior_mean_coef1 = betas * np.sqrt(acp_prev) / (1.0 - acp)
        self.posterior_mean_coef2 = (1.0 - acp_prev) * np.sqrt(1.0 - betas) / (1.0 - acp)
        if config.sigma_small:
            self.model_log_variance = self.posterior_log_variance_clipped
        else:
            self.model_log_variance = np.log(np.append(self.posterior_variance[1], betas[1:]))
        self._f32: dict[tuple[str, str], torch.Tensor] = {}
        self.warm("cpu")

    def tables(self) -> dict[str, np.ndarray]:
        """The float64 tables, under DART's names (for inspection and parity checks)."""
        names = (
            "betas",
            "alphas_cumprod",
            "alphas_cumprod_prev",
            "sqrt_recip_alphas_cumprod",
            "sqrt_recipm1_alphas_cumprod",
            "posterior_variance",
            "posterior_log_variance_clipped",
            "posterior_mean_coef1",
            "posterior_mean_coef2",
        )
        out = {n: getattr(self, n) for n in names}
        out["timestep_map"] = np.array(self.timestep_map)
        return out

    #: The tables the samplers gather from (``_coef`` names).
    COEFFICIENTS: tuple[str, ...] = (
        "alphas_cumprod", "alphas_cumprod_prev", "model_log_variance", "posterior_mean_coef1",
        "posterior_mean_coef2", "sqrt_alphas_cumprod", "sqrt_one_minus_alphas_cumprod", "sqrt_recip_alphas_cumprod",
        "sqrt_recipm1_alphas_cumprod",
    )

    def warm(self, device: str | torch.device) -> None:
        """Copy every table to ``device`` now, so that sampling never fills the cache.

        Why: a compiled step (``compile=True`` envs) guards on this cache; a first call that fills it
        would recompile the whole step once more on the next call.
        """
        for name in self.COEFFICIENTS:
            self._coef(name, torch.device(device))
        self._timesteps(torch.device(device))

    def _coef(self, name: str, device: torch.device) -> torch.Tensor:
        """float32 copy of a table on ``device`` (the cast DART applies when it gathers values)."""
        key = (name, str(device))
        if key not in self._f32:
            self._f32[key] = torch.from_numpy(getattr(self, name)).to(device=device).float()
        return self._f32[key]

    def model_timestep(self, t: int, device: torch.device) -> torch.Tensor:
        """The original step index the model sees for visited step ``t`` (a 0-dim int64 tensor)."""
        return self._timesteps(device)[t]  # a view of a device table: no host-to-device copy per step

    def _timesteps(self, device: torch.device) -> torch.Tensor:
        """(T,) int64 :attr:`timestep_map` on ``device`` (cached, filled by :meth:`warm`)."""
        key = ("timestep_map", str(device))
        if key not in self._f32:
            self._f32[key] = torch.tensor(self.timestep_map, dtype=torch.int64, device=device)
        return self._f32[key]

    # --------------------------------------------------------------- forward process
    def q_sample(self, x0: torch.Tensor, t: torch.Tensor, noise: torch.Tensor) -> torch.Tensor:
        """Noise clean ``x0`` (B, ...) to visited steps ``t`` (B,): sqrt(acp) x0 + sqrt(1 - acp) eps."""
        shape = (-1,) + (1,) * (x0.dim() - 1)
        a = self._coef("sqrt_alphas_cumprod", x0.device)[t].reshape(shape)
        s = self._coef("sqrt_one_minus_alphas_cumprod", x0.device)[t].reshape(shape)
        return a * x0 + s * noise

    # --------------------------------------------------------------- reverse steps
    def ddim_step(
        self, x_t: torch.Tensor, x0_pred: torch.Tensor, t: int, eta: float = 0.0, noise: torch.Tensor | None = None
    ) -> torch.Tensor:
        """One DDIM step from visited step ``t`` given the x0 prediction (eta 0: deterministic)."""
        dev = x_t.device
        acp = self._coef("alphas_cumprod", dev)[t]
        acp_prev = self._coef("alphas_cumprod_prev", dev)[t]
        eps = (self._coef("sqrt_recip_alphas_cumprod", dev)[t] * x_t - x0_pred) / self._coef(
            "sqrt_recipm1_alphas_cumprod", dev
        )[t]
        sigma = eta * torch.sqrt((1 - acp_prev) / (1 - acp)) * torch.sqrt(1 - acp / acp_prev)
        x_prev = x0_pred * torch.sqrt(acp_prev) + torch.sqrt(1 - acp_prev - sigma**2) * eps
        if eta > 0 and t > 0:
            x_prev = x_prev + sigma * noise
        return x_prev

    def ddpm_step(self, x_t: torch.Tensor, x0_pred: torch.Tensor, t: int, noise: torch.Tensor | None) -> torch.Tensor:
        """One ancestral step: posterior mean + exp(0.5 log var) * noise (no noise at t = 0)."""
        dev = x_t.device
        mean = self._coef("posterior_mean_coef1", dev)[t] * x0_pred + self._coef("posterior_mean_coef2", dev)[t] * x_t
        if t == 0:
            return mean
        return mean + torch.exp(0.5 * self._coef("model_log_variance", dev)[t]) * noise

    # --------------------------------------------------------------- loops
    def sample_loop(
        self,
        model_fn: Callable[[torch.Tensor, torch.Tensor], torch.Tensor],
        noise: torch.Tensor,
        sampler: str = "ddim",
        eta: float = 0.0,
        step_noise: torch.Tensor | None = None,
        generator: torch.Generator | None = None,
        trace: list | None = None,
    ) -> torch.Tensor:
        """Run the reverse process from ``x_T = noise`` and return ``x_0``.

        Args:
            model_fn: ``(x_t, t_model) -> x0`` with ``t_model`` a 0-dim int64 original step index.
            noise: (B, ...) initial latent (the RL action).
            sampler: 'ddim' (DDIM, ``eta``; eta 0 is deterministic) or 'ddpm' (ancestral).
            step_noise: (T, B, ...) per-step noises in loop order (t = T-1 ... 0) for DDPM or
                DDIM with eta > 0; drawn from ``generator`` when omitted.
            trace: if a list, receives ``(t, x_t_after, x0_pred)`` for each step.
        """
        if sampler not in ("ddim", "ddpm"):
            raise ValueError(f"sampler must be 'ddim' or 'ddpm', got {sampler!r}")
        x = noise
        for i, t in enumerate(reversed(range(self.num_timesteps))):
            x0 = model_fn(x, self.model_timestep(t, x.device))
            stochastic = sampler == "ddpm" or eta > 0
            eps = None
            if stochastic:
                eps = (
                    step_noise[i]
                    if step_noise is not None
                    else torch.randn(x.shape, device=x.device, dtype=x.dtype, generator=generator)
                )
            x = self.ddim_step(x, x0, t, eta, eps) if sampler == "ddim" else self.ddpm_step(x, x0, t, eps)
            if trace is not None:
                trace.append((self.timestep_map[t], x, x0))
        return x
