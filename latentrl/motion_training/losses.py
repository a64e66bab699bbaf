"""Training a DART motion model: the VAE stage, then the denoiser stage (DART appendices C, D).

Both stages run DART's *scheduled training*: windows of N consecutive primitives, where the
history of primitive k+1 is either the ground truth or the model's own prediction for primitive
k (re-canonicalized), with the rollout probability 0 in the supervised stage, rising linearly in
the scheduled stage, and 1 in the rollout stage. Each primitive is one optimizer step.

- VAE: smooth-L1 reconstruction + KL (weight 1e-6) + auxiliary temporal-difference consistency
  (translation, orientation and joint deltas vs. the differences of predicted frames, weight 100).
  Optional, off by default: the planted-foot loss (``plant_weight``) and the seam loss (``seam_weight``, the
  step from the last history frame to the first decoded frame against the data's), in both stages.
  Afterwards ``latent_std`` is the standard deviation of encoded latents (Rombach et al.).
- Denoiser: smooth-L1 on the predicted clean latent (DDPM x0 objective) + reconstruction and
  auxiliary losses on the decoded frames (weights 1 and 1e4); text dropped with probability 0.1
  for classifier-free guidance; rollout histories come from a full DDPM sampling loop of the
  model being trained.

AdamW with linear LR annealing, gradient clipping, optional EMA weights (what we ship), TensorBoard
scalars, a progress bar, periodic atomic checkpoints with resume, and seeded determinism.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass, field
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from latentrl.config import require
from latentrl.motion.canonical import canonicalize
from latentrl.motion.denoiser import DenoiserConfig, build_denoiser
from latentrl.motion.diffusion import DiffusionConfig, GaussianDiffusion
from latentrl.motion.representation import Normalizer, joints_of, split_frames
from latentrl.motion.rotations import matrix_to_rotation_6d, rotation_6d_to_matrix
from latentrl.motion.vae import PrimitiveVAE, VAEConfig


@dataclass
class StageConfig:
    """Optimization schedule shared by the two stages."""

    steps: int = 3000
    """Optimizer steps (one per primitive, as DART counts them)."""
    batch_size: int = 256
    learning_rate: float = 1e-4
    anneal_lr: bool = True
    """Anneal the learning rate linearly to 0."""
    weight_decay: float = 0.01
    grad_clip: float = 1.0
    ema_decay: float = 0.999
    """Exponential moving average of the weights (0 = off); the EMA weights are what is saved."""
    num_primitives: int = 4
    """Consecutive primitives per window (the maximum number of rollouts)."""
    supervised_fraction: float = 1 / 3
    """Share of steps in the supervised stage (ground-truth histories only)."""
    scheduled_fraction: float = 1 / 3
    """Share of steps in the scheduled stage (rollout probability rising 0 -> 1); the rest is rollout."""

    def validate(self) -> None:
        """Check every field once; a bad one raises a one-line ``ConfigError`` naming it."""
        require(self.steps >= 0, "steps", f"must be >= 0, got {self.steps}")
        require(self.batch_size > 0, "batch_size", f"must be > 0, got {self.batch_size}")
        require(self.learning_rate > 0, "learning_rate", f"must be > 0, got {self.learning_rate}")
        require(0 <= self.ema_decay < 1, "ema_decay", f"must be in [0, 1), got {self.ema_decay}")
        require(self.num_primitives >= 1, "num_primitives", f"must be >= 1, got {self.num_primitives}")
        require(
            0 <= self.supervised_fraction <= 1
            and 0 <= self.scheduled_fraction <= 1
            and self.supervised_fraction + self.scheduled_fraction <= 1,
            "supervised_fraction",
            "supervised_fraction + scheduled_fraction must lie in [0, 1]",
        )

    def rollout_probability(self, step: int) -> float:
        """DART's Algorithm 4 (steps counted from 0)."""
        s1 = self.supervised_fraction * self.steps
        s2 = self.scheduled_fraction * self.steps
        if step < s1:
            return 0.0
        if step >= s1 + s2:
            return 1.0
        return (step - s1) / max(s2, 1e-9)


@dataclass
class VAETrainConfig(StageConfig):
    """Settings of the VAE stage: loss weights (KL, temporal consistency, planted feet) and its batch shape."""
    kl_weight: float = 1e-6
    aux_weight: float = 100.0
    """Weight of each temporal-difference consistency term."""
    plant_weight: float = 0.0
    """Weight of the planted-foot loss (``plant_loss``): feet still in the data stay still when decoded."""
    seam_weight: float = 0.0
    """Weight of the seam loss (``seam_loss``): the first decoded frame continues the history as the data does."""
    batch_size: int = 128
    num_primitives: int = 8

    def validate(self) -> None:
        """Check the common stage fields, then that the loss weights are not negative."""
        super().validate()
        require(self.kl_weight >= 0, "kl_weight", f"must be >= 0, got {self.kl_weight}")
        require(self.aux_weight >= 0, "aux_weight", f"must be >= 0, got {self.aux_weight}")
        require(self.plant_weight >= 0, "plant_weight", f"must be >= 0, got {self.plant_weight}")
        require(self.seam_weight >= 0, "seam_weight", f"must be >= 0, got {self.seam_weight}")


@dataclass
class DenoiserTrainConfig(StageConfig):
    """Settings of the denoiser stage: its reconstruction, consistency and planted-foot loss weights."""
    latent_rec_weight: float = 1.0
    feature_rec_weight: float = 1.0
    aux_weight: float = 1e4
    rollout_history_latent: bool = True
    """Encode the target latent with the rollout history (DART's ``train_rollout_history rollout``)."""
    plant_weight: float = 0.0
    """Weight of the planted-foot loss on the decoded prediction (see ``VAETrainConfig.plant_weight``)."""
    seam_weight: float = 0.0
    """Weight of the seam loss on the decoded prediction (see ``VAETrainConfig.seam_weight``)."""

    def validate(self) -> None:
        """Check the common stage fields, then that the loss weights are not negative."""
        super().validate()
        for name in ("latent_rec_weight", "feature_rec_weight", "aux_weight", "plant_weight", "seam_weight"):
            require(getattr(self, name) >= 0, name, f"must be >= 0, got {getattr(self, name)}")


@dataclass
class ModelShapeConfig:
    """Architecture of the model being trained (DART's names)."""

    vae: VAEConfig = field(
        default_factory=lambda: VAEConfig(latent_dim=(1, 64), h_dim=128, ff_size=256, num_layers=5, dropout=0.1)
    )
    denoiser: DenoiserConfig = field(
        default_factory=lambda: DenoiserConfig(h_dim=256, ff_size=512, num_layers=4, clip_dim=384, noise_shape=(1, 64))
    )
    diffusion: DiffusionConfig = field(default_factory=DiffusionConfig)


# ----------------------------------------------------------------------------- losses
def huber(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """DART's ``HuberLoss(delta=1)`` = smooth L1 with beta 1, mean over elements."""
    return F.smooth_l1_loss(a, b, beta=1.0)


def consistency_losses(history_last: torch.Tensor, future: torch.Tensor) -> dict[str, torch.Tensor]:
    """Temporal-difference consistency of predicted frames (DART's auxiliary losses).

    Args:
        history_last: (B, 1, 276) last history frame, unnormalized.
        future: (B, F, 276) predicted future frames, unnormalized.

    The delta features of frames ``[h_last, f_0 .. f_{F-2}]`` must equal the differences of the
    frames themselves (joints, translation, and ``R[t+1] R[t]^T`` for the global orientation).
    """
    seq = split_frames(torch.cat((history_last, future), dim=1))
    orient = rotation_6d_to_matrix(seq.poses_6d[:, :, 0])
    calc_orient_delta = matrix_to_rotation_6d(orient[:, 1:] @ orient[:, :-1].transpose(-1, -2))
    return {
        "joints_delta": huber(seq.joints[:, 1:] - seq.joints[:, :-1], seq.joints_delta[:, :-1]),
        "transl_delta": huber(seq.transl[:, 1:] - seq.transl[:, :-1], seq.transl_delta[:, :-1]),
        "orient_delta": huber(calc_orient_delta, seq.global_orient_delta_6d[:, :-1]),
    }


#: Joints whose stillness marks a planted foot: both ankles and both toe bases (SMPL-22 indices).
PLANT_JOINTS = (7, 8, 10, 11)
#: A joint moving less than this per frame in the data counts as planted (metres; 15 cm/s at 30 fps).
PLANT_STILL_M = 0.005


def plant_loss(future: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Mean squared per-frame displacement (m^2) of predicted foot joints where the data's stand still.

    Why: free rollouts of the first default model slid their feet (walk skate 26 cm/s once kept on
    the floor) although the data has none; reconstruction and consistency losses weigh a few
    millimetres of foot drift per frame as nothing. Both inputs (B, F, 276) unnormalized, same frame.
    """
    def step(x: torch.Tensor) -> torch.Tensor:
        j = joints_of(x)[..., list(PLANT_JOINTS), :]
        return j[:, 1:] - j[:, :-1]

    planted = (step(target).norm(dim=-1) < PLANT_STILL_M).float()
    return (step(future).pow(2).sum(-1) * planted).sum() / planted.sum().clamp(min=1.0)


def seam_loss(
    history: torch.Tensor, future: torch.Tensor, target_history: torch.Tensor, target: torch.Tensor
) -> torch.Tensor:
    """Mean squared error (m^2) of every joint's step from the last history frame to the first decoded frame.

    Why: the rollout hands the last H decoded frames on as the next history, so the step across a primitive
    boundary is always this one. The planted-foot and consistency losses weigh it as one transition among
    nine or not at all, and a decoder trained without this term places its whole future a few centimetres off
    the history: a planted foot jumps 3.3 cm at the seam against 0.2 cm inside a reconstructed primitive
    (docs/motion.md, "Pops at primitive boundaries"). The target step is the data's, from its own history (in
    the rollout stages the input history is the model's, ``history``, and the data's is ``target_history``).
    Inputs unnormalized: histories (B, H, 276), futures (B, F, 276); squared norms over xyz, mean over joints
    and batch.
    """
    step = joints_of(future[:, 0]) - joints_of(history[:, -1])
    true_step = joints_of(target[:, 0]) - joints_of(target_history[:, -1])
    return (step - true_step).pow(2).sum(-1).mean()


def rollout_history(
    future_n: torch.Tensor, normalizer: Normalizer, pelvis_delta: torch.Tensor, history: int
) -> torch.Tensor:
    """Next history from predicted (normalized) frames: last H frames, re-canonicalized, normalized."""
    last = normalizer.denormalize(future_n[:, -history:])
    canon, _, _ = canonicalize(last, pelvis_delta)
    return normalizer.normalize(canon)


class EMA:
    """Exponential moving average of a module's parameters (a frozen copy)."""

    def __init__(self, module: nn.Module, decay: float):
        self.decay = decay
        self.module = copy.deepcopy(module).eval().requires_grad_(False)

    @torch.no_grad()
    def update(self, module: nn.Module) -> None:
        """Move the average towards ``module``'s parameters (a plain copy when ``decay`` is 0); buffers are copied."""
        if self.decay <= 0:
            self.module.load_state_dict(module.state_dict())
            return
        for avg, p in zip(self.module.parameters(), module.parameters()):
            avg.mul_(self.decay).add_(p.detach(), alpha=1 - self.decay)
        for avg, b in zip(self.module.buffers(), module.buffers()):
            avg.copy_(b)


def make_optimizer(module: nn.Module, cfg: StageConfig) -> torch.optim.Optimizer:
    """AdamW over the trainable parameters, with the stage's learning rate and weight decay."""
    return torch.optim.AdamW(
        [p for p in module.parameters() if p.requires_grad], lr=cfg.learning_rate, weight_decay=cfg.weight_decay
    )


def set_lr(optimizer: torch.optim.Optimizer, cfg: StageConfig, step: int) -> float:
    """Set and return the learning rate of ``step``: linearly annealed to 0 over the stage, or constant."""
    lr = cfg.learning_rate * (1.0 - step / max(cfg.steps, 1)) if cfg.anneal_lr else cfg.learning_rate
    for group in optimizer.param_groups:
        group["lr"] = lr
    return lr


# ----------------------------------------------------------------------------- one step each
def vae_step(
    vae: PrimitiveVAE,
    history_n: torch.Tensor,
    future_n: torch.Tensor,
    normalizer: Normalizer,
    cfg: VAETrainConfig,
    generator: torch.Generator | None = None,
    history_gt_n: torch.Tensor | None = None,
) -> tuple[torch.Tensor, dict, torch.Tensor]:
    """Loss of one VAE step. Inputs normalized: history (B, H, 276), future (B, F, 276).

    ``history_gt_n``: the data's history of ``future_n`` (the seam loss's reference), default ``history_n``.
    Returns ``(loss, terms, prediction_normalized)``.
    """
    mu, std = vae.encode(future_n, history_n)
    eps = torch.randn(mu.shape, generator=generator, device=mu.device)
    z = mu + std * eps
    pred = vae.decode(z, history_n, future_n.shape[1], scale_latent=False)
    kl = 0.5 * (mu.pow(2) + std.pow(2) - 1.0 - 2.0 * torch.log(std)).mean()
    terms = {"rec": huber(pred, future_n), "kl": kl}
    terms.update(consistency_losses(normalizer.denormalize(history_n[:, -1:]), normalizer.denormalize(pred)))
    loss = (
        terms["rec"]
        + cfg.kl_weight * kl
        + cfg.aux_weight * (terms["joints_delta"] + terms["transl_delta"] + terms["orient_delta"])
    )
    if cfg.plant_weight:
        terms["plant"] = plant_loss(normalizer.denormalize(pred), normalizer.denormalize(future_n))
        loss = loss + cfg.plant_weight * terms["plant"]
    if cfg.seam_weight:
        gt = history_n if history_gt_n is None else history_gt_n
        terms["seam"] = _seam(history_n, pred, gt, future_n, normalizer)
        loss = loss + cfg.seam_weight * terms["seam"]
    terms["loss"] = loss
    return loss, terms, pred


def _seam(history_n, pred_n, history_gt_n, future_n, normalizer: Normalizer) -> torch.Tensor:
    """:func:`seam_loss` of normalized inputs (only the last history frame and the first future frame)."""
    return seam_loss(normalizer.denormalize(history_n[:, -1:]), normalizer.denormalize(pred_n[:, :1]),
                     normalizer.denormalize(history_gt_n[:, -1:]), normalizer.denormalize(future_n[:, :1]))


def denoiser_step(
    denoiser,
    vae: PrimitiveVAE,
    diffusion: GaussianDiffusion,
    history_n: torch.Tensor,
    history_gt_n: torch.Tensor,
    future_n: torch.Tensor,
    text: torch.Tensor,
    normalizer: Normalizer,
    cfg: DenoiserTrainConfig,
    generator: torch.Generator | None = None,
):
    """Loss of one denoiser step (x0 objective + decoded reconstruction + consistency)."""
    with torch.no_grad():
        enc_hist = history_n if cfg.rollout_history_latent else history_gt_n
        mu, std = vae.encode(future_n, enc_hist)
        latent_gt = (mu + std * torch.randn(mu.shape, generator=generator, device=mu.device)) / vae.latent_std
    b = future_n.shape[0]
    t = torch.randint(diffusion.num_timesteps, (b,), generator=generator, device=future_n.device)
    noise = torch.randn(latent_gt.shape, generator=generator, device=future_n.device)
    x_t = diffusion.q_sample(latent_gt, t, noise)
    text = denoiser.mask_text(text, generator)
    x0 = denoiser(x_t, t, history_n, text)
    pred = vae.decode(x0, history_n, future_n.shape[1], scale_latent=True)
    terms = {"latent_rec": huber(x0, latent_gt), "feature_rec": huber(pred, future_n)}
    terms.update(consistency_losses(normalizer.denormalize(history_n[:, -1:]), normalizer.denormalize(pred)))
    loss = (
        cfg.latent_rec_weight * terms["latent_rec"]
        + cfg.feature_rec_weight * terms["feature_rec"]
        + cfg.aux_weight * (terms["joints_delta"] + terms["transl_delta"] + terms["orient_delta"])
    )
    if cfg.plant_weight:
        terms["plant"] = plant_loss(normalizer.denormalize(pred), normalizer.denormalize(future_n))
        loss = loss + cfg.plant_weight * terms["plant"]
    if cfg.seam_weight:
        terms["seam"] = _seam(history_n, pred, history_gt_n, future_n, normalizer)
        loss = loss + cfg.seam_weight * terms["seam"]
    terms["loss"] = loss
    return loss, terms


@torch.no_grad()
def sample_for_rollout(
    denoiser,
    vae: PrimitiveVAE,
    diffusion: GaussianDiffusion,
    history_n: torch.Tensor,
    text: torch.Tensor,
    generator: torch.Generator | None = None,
) -> torch.Tensor:
    """Full DDPM loop (no guidance) then decode: the model's own next primitive, normalized."""
    was_training = denoiser.training
    denoiser.eval()
    cond = denoiser.condition(history_n, text)
    shape = (history_n.shape[0], *denoiser.config.noise_shape)
    noise = torch.randn(shape, generator=generator, device=history_n.device)
    x0 = diffusion.sample_loop(lambda x, t: denoiser.denoise(x, t, cond), noise, sampler="ddpm", generator=generator)
    denoiser.train(was_training)
    return vae.decode(x0, history_n, vae.config.future_length, scale_latent=True)


@torch.no_grad()
def latent_scale(
    vae: PrimitiveVAE, history_n: torch.Tensor, future_n: torch.Tensor, generator: torch.Generator | None = None
) -> float:
    """Std of sampled latents over a batch (DART's ``get_latent_scale``)."""
    mu, std = vae.encode(future_n, history_n)
    z = mu + std * torch.randn(mu.shape, generator=generator, device=mu.device)
    return float((z - z.mean()).pow(2).mean().sqrt())


def build_models(shape: ModelShapeConfig) -> tuple[PrimitiveVAE, torch.nn.Module]:
    """Fresh VAE and denoiser whose sizes agree (the denoiser's noise shape is the VAE's latent)."""
    den_cfg = copy.deepcopy(shape.denoiser)
    den_cfg.noise_shape = tuple(shape.vae.latent_dim)
    den_cfg.history_shape = (shape.vae.history_length, shape.vae.nfeats)
    return PrimitiveVAE(shape.vae), build_denoiser(den_cfg)


def timer() -> float:
    """Wall-clock seconds for measuring stage and step durations."""
    return time.perf_counter()


def ensure_dir(path: str | Path) -> Path:
    """The folder ``path``, created with its parents if missing."""
    p = Path(path)
    p.mkdir(parents=True, exist_ok=True)
    return p
