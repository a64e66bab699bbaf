"""Bodies of the ``latentrl motion ...`` commands (argument parsing lives in :mod:`latentrl.cli`)."""

from __future__ import annotations

import argparse

from latentrl.motion.checkpoint import load_motion_model


def info(args: argparse.Namespace) -> int:
    """Print what a motion model is: source, sizes, sampler, texts."""
    model = load_motion_model(args.motion, seed_history=args.seed_history)
    vae, den = model.vae.config, model.denoiser.config
    n_vae = sum(p.numel() for p in model.vae.parameters())
    n_den = sum(p.numel() for p in model.denoiser.parameters())
    print(f"source:      {model.info.get('source')} ({model.info.get('format')})")
    print(f"sha256:      {model.info.get('sha256', '')[:16]}")
    print(f"latent:      {model.latent_shape} (the RL action has {model.latent_dim} values)")
    print(f"VAE:         {vae.num_layers} layers x {vae.h_dim} wide, ff {vae.ff_size}, {n_vae / 1e6:.2f} M parameters")
    print(f"denoiser:    {den.model_type}, {den.num_layers} layers x {den.h_dim} wide, {n_den / 1e6:.2f} M parameters")
    print(f"diffusion:   {model.diffusion_config.diffusion_steps} steps, {model.diffusion_config.noise_schedule}")
    print(f"text:        {model.text_dim}-D, encoder {getattr(model.text_encoder, 'name', None)}")
    prompts = getattr(model.text_encoder, "prompts", None)
    if prompts:
        print(f"prompts:     {', '.join(prompts)}")
    seeds = None if model.seed_history is None else model.seed_history.shape[0]
    print(f"seeds:       {seeds}")
    return 0
