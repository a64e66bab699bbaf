"""What the benchmarks share: devices to run on, JSON output, and the models they time."""

from __future__ import annotations

import json

import torch

from latentrl.errors import LatentRLError


def write_json(path: str | None, data: dict) -> None:
    """Write a benchmark's results as JSON (atomically) when ``--json`` names a file; say where."""
    if path:
        from latentrl.safe_io import atomic_write_text

        atomic_write_text(path, json.dumps(data, indent=2) + "\n")
        print(f"wrote {path}")


def default_devices(requested: list[str] | None) -> list[str]:
    """The devices to time: those asked for (CUDA refused when absent), else CPU and CUDA when present."""
    if requested:
        for d in requested:
            if d.startswith("cuda") and not torch.cuda.is_available():
                raise LatentRLError(f"device '{d}' requested but CUDA is not available on this machine")
        return requested
    return ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


def check_amp(amp: list[str] | str | None, devices: list[str]) -> None:
    """Refuse ``--amp fp16`` with a CPU among the devices, before any timing.

    Autocast in fp16 on the CPU gave NaN motion with exit 0; bf16 is the CPU's autocast dtype.
    """
    asked = [amp] if isinstance(amp, str) else list(amp or [])
    cpus = [d for d in devices if not d.startswith("cuda")]
    if "fp16" in asked and cpus:
        raise LatentRLError(f"--amp fp16: fp16 autocast runs on CUDA only, and the devices include {cpus[0]}; use "
                            "--amp bf16 on the CPU, or --device cuda")


def check_bench_memory(count: int, per_unit: int, flag: str, what: str) -> None:
    """The largest size a benchmark times (``count`` units of ``per_unit`` bytes) must fit the available memory."""
    from latentrl.memory import PROCESS_BYTES, require_memory

    require_memory(PROCESS_BYTES + count * per_unit, flag, f"{what} of {count:,}", f"lower {flag}")


def official_size_model():
    """DART's released architecture with random weights, for timing only.

    8-layer 512-wide transformer denoiser, 7-layer 256-wide VAE, latent (1, 256), CLIP 512.
    """
    from latentrl.motion.denoiser import DenoiserConfig, build_denoiser
    from latentrl.motion.diffusion import DiffusionConfig
    from latentrl.motion.representation import Normalizer
    from latentrl.motion.rollout import MotionModel
    from latentrl.motion.vae import PrimitiveVAE, VAEConfig

    g = torch.random.fork_rng()
    with g:
        torch.manual_seed(0)
        vae = PrimitiveVAE(VAEConfig())
        den = build_denoiser(DenoiserConfig())
    return MotionModel(
        vae,
        den,
        DiffusionConfig(),
        Normalizer(torch.zeros(276), torch.ones(276)),
        info={"source": "official-size (random weights)"},
    )
