"""Bodies of the ``latentrl motion ...`` commands (argument parsing lives in :mod:`latentrl.cli`)."""

from __future__ import annotations

import argparse

from latentrl.motion.checkpoint import load_motion_model

MAX_BATCH = 1024
"""Most motions one ``latentrl motion sample`` call writes."""


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


def sample(args: argparse.Namespace) -> int:
    """``latentrl motion sample``: roll the model out over a text timeline; write .npz (and a GIF)."""
    import math

    import torch

    from latentrl.errors import ConfigError
    from latentrl.motion.text import prompt_problem
    from latentrl.preflight import check_device, check_output_file
    from latentrl.render import render_gif, save_motion_npz

    if not 0 < args.seconds <= 3600:  # also refuses nan
        raise ConfigError(f"--seconds must be in (0, 3600], got {args.seconds}")
    if not 1 <= args.batch <= MAX_BATCH:
        raise ConfigError(f"--batch must be in [1, {MAX_BATCH}], got {args.batch}")
    if not math.isfinite(args.guidance):
        raise ConfigError(f"--guidance must be a finite number, got {args.guidance}")
    texts = args.text or ["walk"]
    for text in texts:
        if prompt_problem(text) is not None:
            raise ConfigError(f"--text: {prompt_problem(text)}")
    if not args.out.endswith(".npz"):
        raise ConfigError(f"--out must name a .npz file, got '{args.out}'")
    if args.render and not args.render.endswith(".gif"):
        raise ConfigError(f"--render must name a .gif file, got '{args.render}'")
    check_device(args.device, "--device")
    for out_file in (args.out, args.render):
        if out_file:
            check_output_file(out_file, "--render" if out_file == args.render else "--out")
    model = load_motion_model(args.motion, seed_history=args.seed_history, device=args.device)
    model.encode_text(texts)  # fail early on unknown prompts
    steps = max(1, math.ceil(args.seconds * 30 / 8))
    # each text gets an equal share of the steps, in the order given
    per_step = [texts[min(len(texts) - 1, i * len(texts) // steps)] for i in range(steps)]
    g = torch.Generator().manual_seed(args.seed)
    roll = model.rollout(per_step, steps, batch=args.batch, generator=g, guidance_scale=args.guidance)
    frame_texts = [""] * 2 + [t for t in per_step for _ in range(8)]
    primitive = [-1] * 2 + [i for i in range(steps) for _ in range(8)]
    out = args.out
    for b in range(args.batch):
        path = out if args.batch == 1 else out.replace(".npz", f"_{b}.npz")
        save_motion_npz(
            path,
            roll.joints_world[b].cpu(),
            texts=frame_texts,
            features=roll.features_world[b].cpu(),
            actions=roll.noise[:, b, 0].cpu(),
            primitive=primitive,
            seed=args.seed,
            guidance_scale=args.guidance,
            motion_model=model.info.get("sha256", ""),
        )
        print(f"wrote {path} ({roll.joints_world.shape[1]} frames, {roll.joints_world.shape[1] / 30:.1f} s)")
    if args.render:
        render_gif(args.render, roll.joints_world[0].cpu().numpy(), texts=frame_texts)
        print(f"wrote {args.render}")
    return 0
