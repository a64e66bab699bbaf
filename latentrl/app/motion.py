"""Bodies of the ``latentrl motion ...`` commands: info, sample, train and export-bvh."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

from latentrl.constants import GUIDANCE_SCALE
from latentrl.errors import ConfigError

MAX_BATCH = 1024
"""Most motions one ``latentrl motion sample`` call writes."""


@dataclass
class InfoRequest:
    """``latentrl motion info``: which model to describe."""

    motion: str = "default"
    seed_history: str | None = None


@dataclass
class SampleRequest:
    """``latentrl motion sample``: a model, a text timeline and where to write the motion."""

    motion: str = "default"
    seed_history: str | None = None
    text: list[str] | None = None
    seconds: float | None = None
    seed: int = 0
    guidance: float = GUIDANCE_SCALE
    batch: int = 1
    device: str = "cpu"
    out: str = "motion.npz"
    render: str | None = None
    foot_lock: bool = False
    no_floor_snap: bool = False


DEFAULT_SECONDS = 10.0
"""Length of a sampled motion when no ``--seconds`` and no durations are given."""
PRIMITIVE_SECONDS = 8 / 30
"""One primitive: 8 frames at 30 fps; timelines are rounded to whole primitives."""


def _segment(text: str) -> list[tuple[str, float | None, int | None]]:
    """One ``--text`` value -> ``(prompt, seconds or None, primitives or None)`` segments.

    ``walk`` (a share of what is left), ``walk:3`` (3 seconds) or DART's ``walk*20,turn left*6``
    (20 and 6 primitives of 8 frames).
    """
    if "*" in text:
        segments = []
        for part in text.split(","):
            prompt, _, count = part.rpartition("*")
            if not prompt.strip() or not count.strip().isdigit() or int(count) < 1:
                raise ConfigError(f"--text '{text}': expected DART's PROMPT*N[,PROMPT*N...] with N a whole number "
                                  f"of primitives >= 1, got '{part}'")
            segments.append((prompt.strip(), None, int(count)))
        return segments
    prompt, colon, tail = text.rpartition(":")
    if not colon:
        return [(text, None, None)]
    try:
        seconds = float(tail)
    except ValueError:
        seconds = float("nan")
    if not 0 < seconds <= 3600 or not prompt.strip():
        raise ConfigError(f"--text '{text}': expected PROMPT or PROMPT:SECONDS with SECONDS a number in (0, 3600]")
    return [(prompt.strip(), seconds, None)]


def timeline(texts: list[str], seconds: float | None) -> list[str]:
    """The prompt of every primitive of a ``motion sample`` timeline.

    Segments with a duration (``walk:3``) get ``round(seconds / (8/30))`` primitives (at least 1),
    DART segments (``walk*20``) their count; texts without either share what is left of
    ``seconds`` (default 10 s, rounded up to whole primitives) equally, in order. ``seconds``
    together with a duration on every text is refused: the durations already fix the length.
    """
    segments = [s for text in texts for s in _segment(text)]
    counts = [n if n is not None else None if sec is None else max(1, round(sec / PRIMITIVE_SECONDS))
              for _, sec, n in segments]
    shared = [i for i, c in enumerate(counts) if c is None]
    fixed = sum(c for c in counts if c is not None)
    if not shared and seconds is not None:
        raise ConfigError(f"--seconds {seconds:g}: every --text already has a duration ({fixed * PRIMITIVE_SECONDS:.1f}"
                          " s in all); drop --seconds or a duration")
    if shared:
        total = DEFAULT_SECONDS if seconds is None else seconds
        free = max(1, math.ceil(total / PRIMITIVE_SECONDS - 1e-9)) - fixed
        if free < len(shared):
            raise ConfigError(f"--seconds {total:g}: leaves {max(free, 0)} primitives of 8 frames for "
                              f"{len(shared)} texts without a duration after the {fixed} the durations take")
        for k, i in enumerate(shared):  # the first texts get the extra primitives, as before durations existed
            counts[i] = -(-(k + 1) * free // len(shared)) + (-k * free // len(shared))
    return [prompt for (prompt, _, _), n in zip(segments, counts) for _ in range(n)]


@dataclass
class MotionTrainRequest:
    """``latentrl motion train``: a config (or a run to resume), overrides and outputs."""

    config: str | None = None
    overrides: list[str] = field(default_factory=list)
    run_dir: str | None = None
    resume: str | None = None
    out: str | None = None
    vae_from: str | None = None
    progress: bool = True


@dataclass
class ExportBvhRequest:
    """``latentrl motion export-bvh``: a motion ``.npz`` and the BVH file to write."""

    motion: str
    out: str | None = None


def info(req: InfoRequest) -> int:
    """Print what a motion model is: source, sizes, sampler, texts."""
    from latentrl.motion.checkpoint import load_motion_model

    model = load_motion_model(req.motion, seed_history=req.seed_history)
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
    source = model.info.get("seed")
    print(f"seeds:       {seeds}" + (f" ({source})" if source and seeds else ""))
    return 0


def _check_sample(req: SampleRequest, texts: list[str]) -> list[str]:
    from latentrl.config import seed_problem
    from latentrl.constants import MAX_GUIDANCE
    from latentrl.motion.text import prompt_problem
    from latentrl.preflight import check_device, check_output_file
    from latentrl.render import video_problem

    if req.seconds is not None and not 0 < req.seconds <= 3600:  # also refuses nan
        raise ConfigError(f"--seconds must be in (0, 3600], got {req.seconds}")
    per_step = timeline(texts, req.seconds)
    if not 1 <= req.batch <= MAX_BATCH:
        raise ConfigError(f"--batch must be in [1, {MAX_BATCH}], got {req.batch}")
    if not math.isfinite(req.guidance) or abs(req.guidance) > MAX_GUIDANCE:
        raise ConfigError(f"--guidance must be a finite number in [-{MAX_GUIDANCE:g}, {MAX_GUIDANCE:g}], "
                          f"got {req.guidance}")
    if seed_problem(req.seed) is not None:
        raise ConfigError(f"--seed: {seed_problem(req.seed)}")
    for text in dict.fromkeys(per_step):
        if prompt_problem(text) is not None:
            raise ConfigError(f"--text: {prompt_problem(text)}")
    if not req.out.endswith(".npz"):
        raise ConfigError(f"--out must name a .npz file, got '{req.out}'")
    if req.render and video_problem(req.render):
        raise ConfigError(f"--render {video_problem(req.render)}")
    check_device(req.device, "--device")
    for out_file in (req.out, req.render):
        if out_file:
            check_output_file(out_file, "--render" if out_file == req.render else "--out")
    return per_step


def sample(req: SampleRequest) -> int:
    """``latentrl motion sample``: roll the model out over a text timeline; write .npz (and a GIF)."""
    import torch

    from latentrl.motion.checkpoint import load_motion_model
    from latentrl.motion.clip import MotionClip, primitive_layout
    from latentrl.render import render_video

    per_step = _check_sample(req, req.text or ["walk"])
    model = load_motion_model(req.motion, seed_history=req.seed_history, device=req.device)
    model.encode_text(list(dict.fromkeys(per_step)))  # fail early on unknown prompts
    steps = len(per_step)
    model.foot_lock = req.foot_lock
    if req.no_floor_snap:
        model.floor_snap = None
    g = torch.Generator().manual_seed(req.seed)
    roll = model.rollout(per_step, steps, batch=req.batch, generator=g, guidance_scale=req.guidance)
    if not torch.isfinite(roll.joints_world).all():  # never write a NaN motion
        from latentrl.errors import NonFiniteError

        bad = (~torch.isfinite(roll.joints_world)).flatten(2).any(-1)
        raise NonFiniteError(f"motion sample: the rollout diverged ({int(bad.sum())} of {bad.numel()} frames hold "
                             f"NaN or inf; --guidance {req.guidance:g}, model {req.motion}); nothing written")
    frame_texts = [""] * 2 + [t for t in per_step for _ in range(8)]
    for b in range(req.batch):
        path = req.out if req.batch == 1 else req.out.replace(".npz", f"_{b}.npz")
        clip = MotionClip(
            roll.joints_world[b].cpu().numpy(),
            texts=frame_texts,
            actions=roll.noise[:, b, 0].cpu().numpy(),
            features=roll.features_world[b].cpu().numpy(),
            primitive=primitive_layout(steps),
            meta={"seed": req.seed, "guidance_scale": req.guidance, "motion_model": model.info.get("sha256", ""),
                  "foot_lock": req.foot_lock, "floor_snap": not req.no_floor_snap},
        )
        clip.save(path)
        frames = roll.joints_world.shape[1]
        print(f"wrote {Path(path).resolve()} ({frames} frames, {frames / 30:.1f} s; {_describe(per_step)})")
    if req.render:
        render_video(req.render, roll.joints_world[0].cpu().numpy(), texts=frame_texts)
        print(f"wrote {Path(req.render).resolve()}")
    first = req.out if req.batch == 1 else req.out.replace(".npz", "_0.npz")
    print(f"watch it: latentrl view {first}")
    return 0


def _describe(per_step: list[str]) -> str:
    """``walk 3.0 s, turn left 1.6 s``: the timeline's segments as sampled."""
    runs: list[list] = []
    for text in per_step:
        if runs and runs[-1][0] == text:
            runs[-1][1] += 1
        else:
            runs.append([text, 1])
    return ", ".join(f"{text} {n * PRIMITIVE_SECONDS:.2f} s" for text, n in runs)


def train(req: MotionTrainRequest) -> int:
    """Body of ``latentrl motion train``: every input is checked before the run directory is created."""
    from latentrl.config import load_config
    from latentrl.motion_training.trainer import MotionTrainConfig, MotionTrainer
    from latentrl.preflight import NewOutput, check_device, check_free_space, check_output_file, check_writable
    from latentrl.resources import config_file
    from latentrl.runlock import RunLock

    if req.resume:
        run_dir = Path(req.resume)
        cfg_path = run_dir / "config.yaml"
        if not cfg_path.is_file():
            raise ConfigError(f"--resume {run_dir}: no config.yaml there; is it a motion training run directory?")
        if req.overrides:
            raise ConfigError(f"--set {req.overrides[0]}: a resumed run keeps its own config.yaml; "
                              "start a new run instead")
        if req.vae_from:
            raise ConfigError(f"--vae-from {req.vae_from}: a resumed run keeps the VAE it has; start a new run instead")
        cfg = load_config(MotionTrainConfig, cfg_path)
    else:
        if not req.config:
            raise ConfigError("give a CONFIG file (e.g. configs/motion/default.yaml) or --resume RUN_DIR")
        cfg = load_config(MotionTrainConfig, config_file(req.config), req.overrides)
        run_dir = Path(req.run_dir) if req.run_dir else Path("runs") / f"motion-{time.strftime('%Y%m%d-%H%M%S')}"
        if (run_dir / "config.yaml").is_file() or (run_dir / "checkpoints" / "state.pt").is_file():
            raise ConfigError(f"--run-dir {run_dir} already holds a motion training run; continue it with "
                              f"--resume {run_dir} or choose another --run-dir")
    check_device(cfg.device, "device")
    if cfg.data.source != "locomotion" and not Path(cfg.data.source).is_dir():
        raise ConfigError(f"data.source: folder not found: {cfg.data.source} (give 'locomotion' or a folder of "
                          "motion-text .npz files)")
    check_writable(run_dir, "run directory")
    if req.out:
        check_output_file(req.out)
    lock = RunLock(run_dir)
    with NewOutput(run_dir) as output:  # a failure before training starts removes the folder it created
        try:
            lock.acquire()  # one writer per run directory; a second fails here at once
        except ConfigError:
            output.keep()
            raise
        try:
            trainer = MotionTrainer(cfg, run_dir, out=req.out, progress=req.progress)
            ckpt = run_dir / "checkpoints" / "state.pt"
            if req.resume and ckpt.is_file():
                trainer.load_checkpoint(ckpt)
            if req.vae_from:
                trainer.start_from_vae(req.vae_from)
            check_free_space(run_dir, trainer.disk_estimate(), "run directory")
        except BaseException:
            lock.release()
            raise
        output.keep()
    with lock:
        out = trainer.run()
    print(f"motion model written to {out} ({trainer.elapsed:.0f} s of training)")
    return 0


def export_bvh(req: ExportBvhRequest) -> int:
    """``latentrl motion export-bvh``: a motion ``.npz`` (shared format) as BVH (SMPL-22, Y-up, cm)."""
    from latentrl.preflight import check_output_file
    from latentrl.render import load_motion_npz, save_bvh

    motion = load_motion_npz(req.motion)
    out = Path(req.out) if req.out else Path(req.motion).with_suffix(".bvh")
    check_output_file(out)
    save_bvh(out, motion["joints"], float(motion["fps"]))
    print(f"wrote {out} ({len(motion['joints'])} frames at {float(motion['fps']):g} fps)")
    return 0
