"""Small real models and hand-made motions shared by the tests."""

from __future__ import annotations

import torch

from latentrl.motion.canonical import canonicalize
from latentrl.motion.denoiser import DenoiserConfig, build_denoiser
from latentrl.motion.diffusion import DiffusionConfig
from latentrl.motion.representation import Normalizer, compute_features
from latentrl.motion.rollout import MotionModel
from latentrl.motion.rotations import axis_angle_to_matrix
from latentrl.motion.skeleton import forward_kinematics
from latentrl.motion.text import HashedTextEncoder, TableTextEncoder
from latentrl.motion.vae import PrimitiveVAE, VAEConfig

PELVIS_DELTA = torch.tensor([0.0, 0.0, 0.93])


def rest_joints() -> torch.Tensor:
    """A plausible 1.75 m rest skeleton (z up, facing +y, +x = body right)."""
    j = torch.zeros(22, 3)
    j[0] = PELVIS_DELTA
    j[1] = j[0] + torch.tensor([-0.09, 0.0, -0.08])
    j[2] = j[0] + torch.tensor([0.09, 0.0, -0.08])
    j[3] = j[0] + torch.tensor([0.0, 0.0, 0.12])
    j[4] = j[1] + torch.tensor([0.0, 0.0, -0.42])
    j[5] = j[2] + torch.tensor([0.0, 0.0, -0.42])
    j[6] = j[3] + torch.tensor([0.0, 0.0, 0.14])
    j[7] = j[4] + torch.tensor([0.0, 0.0, -0.41])
    j[8] = j[5] + torch.tensor([0.0, 0.0, -0.41])
    j[9] = j[6] + torch.tensor([0.0, 0.0, 0.05])
    j[10] = j[7] + torch.tensor([0.0, 0.13, -0.005])
    j[11] = j[8] + torch.tensor([0.0, 0.13, -0.005])
    j[12] = j[9] + torch.tensor([0.0, 0.0, 0.22])
    j[13] = j[9] + torch.tensor([-0.07, 0.0, 0.15])
    j[14] = j[9] + torch.tensor([0.07, 0.0, 0.15])
    j[15] = j[12] + torch.tensor([0.0, 0.02, 0.1])
    j[16] = j[13] + torch.tensor([-0.12, 0.0, 0.0])
    j[17] = j[14] + torch.tensor([0.12, 0.0, 0.0])
    j[18] = j[16] + torch.tensor([0.0, 0.0, -0.28])
    j[19] = j[17] + torch.tensor([0.0, 0.0, -0.28])
    j[20] = j[18] + torch.tensor([0.0, 0.0, -0.25])
    j[21] = j[19] + torch.tensor([0.0, 0.0, -0.25])
    return j


def walking_clip(frames: int = 11, speed: float = 1.2, yaw: float = 0.0, seed: int = 0) -> dict:
    """A simple forward-moving clip (world frame) with random small joint rotations."""
    g = torch.Generator().manual_seed(seed)
    t = torch.arange(frames) / 30.0
    poses = 0.2 * torch.randn(frames, 22, 3, generator=g)
    poses[:, 0] = torch.tensor([0.0, 0.0, yaw])
    rot = axis_angle_to_matrix(poses)
    heading = torch.tensor([-torch.sin(torch.tensor(yaw)), torch.cos(torch.tensor(yaw)), 0.0])
    transl = t[:, None] * speed * heading + torch.tensor([0.3, -0.2, 0.0])
    joints, _ = forward_kinematics(rest_joints(), rot, transl)
    return {"transl": transl, "rotations": rot, "joints": joints}


def seed_history() -> torch.Tensor:
    """(1, 2, 276) canonical seed made from a standing clip."""
    clip = walking_clip(3, speed=0.0)
    feats = compute_features(clip["transl"], clip["rotations"], clip["joints"])[None]
    canon, _, _ = canonicalize(feats, PELVIS_DELTA)
    return canon


def make_tiny_model(latent: int = 16, text_dim: int = 32, seed: int = 0) -> MotionModel:
    torch.manual_seed(seed)
    vae = PrimitiveVAE(VAEConfig(latent_dim=(1, latent), h_dim=32, ff_size=64, num_layers=3, num_heads=4))
    vae.latent_std.fill_(0.8)
    den = build_denoiser(
        DenoiserConfig(h_dim=32, ff_size=64, num_layers=2, num_heads=4, clip_dim=text_dim, noise_shape=(1, latent))
    )
    norm = Normalizer(torch.zeros(276), torch.ones(276) * 0.5)
    hashed = HashedTextEncoder(text_dim)
    table = TableTextEncoder(
        {p: hashed.encode([p])[0] for p in ("walk", "run", "hop on left leg")}, name=hashed.name, fallback=hashed
    )
    return MotionModel(vae, den, DiffusionConfig(), norm, table, pelvis_delta=PELVIS_DELTA, seed_history=seed_history())
