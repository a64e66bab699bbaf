"""``latentrl bench env``: batched-env throughput against a per-env loop over the same model.

For each model, device and env count N it times :meth:`ReachLocationEnv.step` on one batched env
of N envs, and ``gymnasium.vector.SyncVectorEnv`` over N :class:`SingleEnv` wrappers (each a
``num_envs=1`` env sharing the same model), which is what a plain Gymnasium setup would do.
Figures: env steps/s (N x vector steps/s), frames/s (8 per env step) and the speed ratio, all
measured in the same run, beside the bare sampler's primitives/s at the same batch
(``MotionModel.rollout_step`` alone, no env): their ratio is what the env adds per step.
``--scene`` also times the env with :data:`BENCH_SCENE` (8 random obstacles per env, docs/scenes.md) and
prints its step-time ratio to the flat env of the same run (``scene_cost``).
Combinations whose estimated time exceeds ``max_seconds`` are skipped with a note (estimated from
the previous N of the same model, device and kind, which scales about linearly once the machine is
saturated).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import partial

import gymnasium as gym
import numpy as np
import torch
from gymnasium.vector import AutoresetMode

from latentrl.app.bench.common import (
    check_amp,
    check_bench_memory,
    default_devices,
    official_size_model,
    write_json,
)
from latentrl.envs.reach import ReachLocationEnv
from latentrl.envs.single import SingleEnv
from latentrl.motion.rollout import MotionModel
from latentrl.scenes.random import RandomObstacles
from latentrl.timing import hardware, mean_time


@dataclass
class EnvBenchRequest:
    """``latentrl bench env`` flags (tests may pass any object with these attributes)."""

    models: list[str] = field(default_factory=lambda: ["default", "official"])
    num_envs: list[int] = field(default_factory=lambda: [1, 64, 256, 1024])
    device: list[str] | None = None
    steps: int = 5
    max_seconds: float = 120.0
    baseline: bool = True
    compile: bool = False
    amp: str | None = None
    threads: int | None = None
    json: str | None = None
    scene: bool = False


BENCH_SCENE = RandomObstacles(count=[8, 8])
"""``--scene``: 8 obstacle slots per env, each a box or a cylinder, drawn per episode."""

def standing_seed() -> tuple[torch.Tensor, torch.Tensor]:
    """(1, 2, 276) canonical seed of a motionless 1.75 m rest body and its (3,) ``pelvis_delta``.

    For models without seeds (the random-weight official-size model), so their env can run.
    """
    from latentrl.datasets.body import rest_joints
    from latentrl.motion.canonical import canonicalize
    from latentrl.motion.representation import compute_features

    rest = torch.as_tensor(rest_joints(1.75), dtype=torch.float32)
    frames = 3  # 2 history frames + 1 for the forward differences
    rotations = torch.eye(3).expand(frames, 22, 3, 3)
    feats = compute_features(torch.zeros(frames, 3), rotations, rest.expand(frames, 22, 3))[None]
    seed, _, _ = canonicalize(feats, rest[0])
    return seed, rest[0]


def bench_model(name: str) -> MotionModel:
    """'default', 'official' (DART size, random weights), 'tiny' (test size, random weights) or a path.

    Models without seed history, ``pelvis_delta`` or text encoder get a standing seed and a
    hashed text encoder, which changes nothing about the cost of a step.
    """
    from latentrl.motion.checkpoint import load_motion_model
    from latentrl.motion.text import HashedTextEncoder

    if name == "official":
        model = official_size_model()
    elif name == "tiny":
        model = tiny_model()
    else:
        model = load_motion_model(name)
    if model.seed_history is None or model.pelvis_delta is None:
        model.seed_history, model.pelvis_delta = standing_seed()
    if model.text_encoder is None:
        model.text_encoder = HashedTextEncoder(model.text_dim)
    return model


def tiny_model() -> MotionModel:
    """The test suite's model size (VAE and denoiser 32 wide, latent (1, 16), text 32), random weights."""
    from latentrl.motion.denoiser import DenoiserConfig, build_denoiser
    from latentrl.motion.diffusion import DiffusionConfig
    from latentrl.motion.representation import Normalizer
    from latentrl.motion.vae import PrimitiveVAE, VAEConfig

    with torch.random.fork_rng():
        torch.manual_seed(0)
        vae = PrimitiveVAE(VAEConfig(latent_dim=(1, 16), h_dim=32, ff_size=64, num_layers=3, num_heads=4))
        den = build_denoiser(
            DenoiserConfig(h_dim=32, ff_size=64, num_layers=2, num_heads=4, clip_dim=32, noise_shape=(1, 16))
        )
    return MotionModel(
        vae,
        den,
        DiffusionConfig(),
        Normalizer(torch.zeros(276), torch.ones(276) * 0.5),
        info={"source": "tiny (random weights)"},
    )


def time_vector_env(model: MotionModel, num_envs: int, device: str, steps: int, compile: bool = False,
                    amp: str | None = None, scene: RandomObstacles | None = None) -> float:
    """Seconds per step of one batched ReachLocation env of ``num_envs`` envs.

    ``compile``: its step compiled; ``amp``: the env's ``amp`` (undone on the model afterwards); ``scene``: the
    env's scene (None: the flat floor). A compiled
    env takes two untimed steps first: the first compiles, and on CUDA the second records the CUDA graph
    that later steps replay.
    """
    before = model.amp_dtype
    try:
        env = ReachLocationEnv(num_envs, motion=model, device=device, compile=compile, amp=amp,
                               **({"scene": scene} if scene is not None else {}))
        env.reset(seed=0)
        actions = torch.randn(num_envs, model.latent_dim, generator=torch.Generator().manual_seed(0)).to(device)
        if compile:
            env.step(actions)
        return mean_time(lambda: env.step(actions), steps, device)
    finally:
        model.amp_dtype = before


def time_bare_sampler(model: MotionModel, num_envs: int, device: str, steps: int) -> float:
    """Seconds per ``rollout_step`` of ``num_envs`` rollouts: the motion model alone, without the env."""
    generator = torch.Generator().manual_seed(0)
    state = model.initial_state(num_envs, generator=generator)
    text = model.encode_text(["walk"] * num_envs)
    noise = torch.randn(num_envs, *model.latent_shape, generator=generator).to(device)

    def step() -> None:
        nonlocal state
        state = model.rollout_step(state, text, noise).state

    return mean_time(step, steps, device)


def _single(model: MotionModel, device: str) -> SingleEnv:
    return SingleEnv(ReachLocationEnv(1, motion=model, device=device, autoreset_mode=AutoresetMode.DISABLED))


def time_loop_env(model: MotionModel, num_envs: int, device: str, steps: int) -> float:
    """Seconds per step of ``SyncVectorEnv`` over ``num_envs`` single-env wrappers of the same model."""
    env = gym.vector.SyncVectorEnv([partial(_single, model, device) for _ in range(num_envs)])
    env.reset(seed=0)
    actions = np.random.default_rng(0).standard_normal((num_envs, model.latent_dim)).astype(np.float32)
    return mean_time(lambda: env.step(actions), steps, device)


def _figures(seconds_per_step: float, num_envs: int) -> dict:
    rate = num_envs / seconds_per_step
    return {"ms_per_step": seconds_per_step * 1e3, "env_steps_per_s": rate, "frames_per_s": 8 * rate}


def _run_kind(kind: str, timer, model, name, device, n, args, last: dict) -> dict | None:
    """Time one kind ('vector' or 'loop') unless the estimate from the previous N exceeds the budget."""
    key = (name, device, kind)
    if key in last:
        prev_n, prev_s = last[key]
        estimate = prev_s * max(n / prev_n, 1.0) * (args.steps + 1)
        if estimate > args.max_seconds:
            return {"skipped": f"estimated {estimate:.0f} s > --max-seconds {args.max_seconds:g}"}
    seconds = timer(model, n, device, args.steps)
    last[key] = (n, seconds)
    return _figures(seconds, n)


VARIANTS = (
    # row key, printed label, key of its ratio to the eager fp32 env, that ratio's label, compiled?, with ``amp``?
    ("compiled", "compiled", "compile_speedup", "eager", True, False),
    ("amp", "amp", "amp_speedup", "fp32", False, True),
    ("amp_compiled", "amp compiled", "amp_compiled_speedup", "fp32 eager", True, True),
)
"""The env variants ``--compile`` and ``--amp`` time beside the eager fp32 env, in the order they run."""


def _rate_ratio(a: dict, b: dict) -> float | None:
    """``a``'s env steps/s over ``b``'s, or None when either figure was skipped."""
    if "env_steps_per_s" in a and "env_steps_per_s" in b:
        return a["env_steps_per_s"] / b["env_steps_per_s"]
    return None


def bench_env(args: EnvBenchRequest) -> int:
    """Env steps/s and frames/s per model, device and env count; batched env vs per-env loop.

    ``args`` fields (``latentrl bench env`` flags): ``models`` (list: 'default', 'official',
    'tiny' or paths), ``num_envs`` (list of N), ``device`` (list or ``None`` = cpu plus cuda
    when present), ``steps`` (timed steps per figure, after one warm-up), ``max_seconds``
    (skip figures estimated longer), ``baseline`` (time the SyncVectorEnv loop too), ``compile``
    (time the env with ``compile=True`` too; the warm-up steps compile and are not timed), ``amp`` (time the env
    with that ``amp`` too, e.g. 'bf16'; with ``compile`` also both together),
    ``threads`` (torch CPU threads or ``None``), ``json`` (output path or ``None``), ``scene`` (time the env with
    :data:`BENCH_SCENE` too).
    """
    from latentrl.memory import ENV_BYTES

    devices = default_devices(args.device)
    check_amp(args.amp, devices)
    check_bench_memory(max(args.num_envs), ENV_BYTES, "--num-envs", "a batched env")
    if args.threads:
        torch.set_num_threads(args.threads)
    if args.compile:  # refuse before any timing when torch cannot compile here
        from latentrl.preflight import check_compile

        for device in devices:
            check_compile(device, "--compile", "leave out --compile")
    out = {
        "benchmark": "env",
        "task": "latentrl/ReachLocation-v0",
        "hardware": hardware(),
        "steps": args.steps,
        "models": {},
        "notes": [],
    }
    gpu = f"; {out['hardware']['gpu']}" if "gpu" in out["hardware"] else ""
    print(f"hardware: {out['hardware']['cpu']} ({out['hardware']['torch_threads']} threads){gpu}")
    loaded = {name: bench_model(name) for name in args.models}  # a bad name fails before any timing
    for name, model in loaded.items():
        rows, last = [], {}
        for device in devices:
            model = model.to(device)
            for n in args.num_envs:
                row = {
                    "device": device,
                    "num_envs": n,
                    "vector": _run_kind("vector", time_vector_env, model, name, device, n, args, last),
                    "sampler": _run_kind("sampler", time_bare_sampler, model, name, device, n, args, last),
                }
                for key, _, ratio_key, _, compile, amp in VARIANTS:
                    if (compile and not args.compile) or (amp and not args.amp):
                        continue
                    timer = partial(time_vector_env, compile=compile, amp=args.amp if amp else None)
                    row[key] = _run_kind(key, timer, model, name, device, n, args, last)
                    if (ratio := _rate_ratio(row[key], row["vector"])) is not None:
                        row[ratio_key] = ratio
                if (ratio := _rate_ratio(row["vector"], row["sampler"])) is not None:
                    row["env_share"] = 1.0 - ratio
                if getattr(args, "scene", False):
                    timer = partial(time_vector_env, scene=BENCH_SCENE)
                    row["scene"] = _run_kind("scene", timer, model, name, device, n, args, last)
                    if (ratio := _rate_ratio(row["vector"], row["scene"])) is not None:
                        row["scene_cost"] = ratio
                if args.baseline:
                    row["loop"] = _run_kind("loop", time_loop_env, model, name, device, n, args, last)
                    if (ratio := _rate_ratio(row["vector"], row["loop"])) is not None:
                        row["speedup"] = ratio
                rows.append(row)
                print(_line(name, row))
        out["models"][name] = {
            "latent_shape": list(model.latent_shape),
            "source": model.info.get("source"),
            "results": rows,
        }
    write_json(args.json, out)
    return 0


def _line(name: str, row: dict) -> str:
    def fmt(fig: dict | None) -> str:
        if fig is None:
            return "-"
        if "skipped" in fig:
            return f"skipped ({fig['skipped']})"
        return f"{fig['env_steps_per_s']:9.1f} steps/s {fig['frames_per_s']:10.1f} frames/s"

    text = f"{name:>10} {row['device']:>5} N={row['num_envs']:>5}: batched {fmt(row['vector'])}"
    text += f" | bare sampler {fmt(row['sampler'])}"
    if "env_share" in row:
        text += f" (env adds {100 * row['env_share']:.0f}%)"
    if "scene_cost" in row:
        text += f" | 8-object scene: x{row['scene_cost']:.3f} the flat step time"
    for key, label, ratio_key, versus, _, _ in VARIANTS:
        if key in row:
            text += f" | {label} {fmt(row[key])}"
        if ratio_key in row:
            text += f" ({row[ratio_key]:.2f}x {versus})"
    if "loop" in row:
        text += f" | loop {fmt(row['loop'])}"
    if "speedup" in row:
        text += f" | {row['speedup']:.1f}x"
    return text
