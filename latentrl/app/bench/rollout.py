"""``latentrl bench rollout``: primitives/s of the motion model, side by side with DART's own sampler."""

from __future__ import annotations

import copy
import json
import os
import subprocess
import sys
from dataclasses import dataclass, field
from pathlib import Path

import torch

from latentrl.app.bench.common import default_devices, official_size_model, write_json
from latentrl.constants import GUIDANCE_SCALE
from latentrl.errors import LatentRLError
from latentrl.motion.rollout import AMP_DTYPES
from latentrl.timing import hardware, matmul_peak_gflops, median_time


@dataclass
class RolloutBenchRequest:
    """``latentrl bench rollout`` flags."""

    batches: list[int] = field(default_factory=lambda: [1, 16, 256])
    models: list[str] = field(default_factory=lambda: ["official", "default"])
    device: list[str] | None = None
    repeats: int = 5
    threads: int | None = None
    amp: list[str] | None = None
    compile: bool = False
    cuda_graph: bool = False
    packed: bool = False
    dart_src: str | None = None
    dart_python: str | None = None
    dart_bench: str | None = None
    json: str | None = None


def analytic_flops_per_primitive(model) -> float:
    """2 x multiply-adds per primitive: 10 steps x 2 (CFG) denoiser passes + one VAE decode.

    Counts the work DART's sampler does (every token through every layer); our sampler skips
    some of it (the last layer only computes the read-out token), so achieved GFLOP/s above the
    matmul peak are possible and mean the same thing as a speed ratio.
    """
    den, vae = model.denoiser.config, model.vae.config

    def layer(tokens: int, d: int, ff: int) -> float:
        return tokens * 2 * (3 * d * d + d * d + 2 * d * ff) + 4 * tokens * tokens * d

    steps = model.diffusion.num_timesteps
    if den.model_type == "transformer":
        tokens = 2 + den.history_shape[0] + den.noise_shape[0]
        d = den.h_dim
        embed = 2 * 2 * d * d + 2 * den.clip_dim * d + 2 * den.history_shape[0] * den.history_shape[1] * d
        embed += 2 * den.noise_shape[0] * den.noise_shape[1] * d
        per_pass = embed + den.num_layers * layer(tokens, d, den.ff_size) + 2 * d * den.noise_shape[1]
    else:
        d = den.h_dim
        inp = d + den.clip_dim + den.history_shape[0] * den.history_shape[1] + den.noise_shape[0] * den.noise_shape[1]
        per_pass = 2 * 2 * d * d + 2 * inp * d + den.n_blocks * 2 * 2 * d * d + 2 * d * den.noise_shape[1]
    vtok = vae.latent_dim[0] + vae.history_length + vae.future_length
    h = vae.h_dim
    decode = (
        2 * vae.latent_dim[1] * h
        + 2 * vae.history_length * vae.nfeats * h
        + vae.num_layers * layer(vtok, h, vae.ff_size)
        + ((vae.num_layers - 1) // 2) * vtok * 4 * h * h
        + 2 * vae.future_length * h * vae.nfeats
    )
    return steps * 2 * per_pass + decode


def _sampler_inputs(model, batch: int, device: str, seed: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Seeded random (history, text embedding, noise) for one primitive of ``batch`` sequences on ``device``."""
    g = torch.Generator().manual_seed(seed)
    hist = torch.randn(batch, 2, 276, generator=g).to(device) * 0.1
    text = torch.randn(batch, model.text_dim, generator=g).to(device)
    noise = torch.randn(batch, *model.latent_shape, generator=g).to(device)
    return hist, text, noise


def time_sampler(model, batch: int, device: str, repeats: int, compiled: bool = False,
                 reference: torch.Tensor | None = None, cuda_graph: bool = False) -> dict:
    """Ms per primitive-batch of :meth:`MotionModel.sample_primitive` with DART's CFG (DDIM 10).

    ``compiled``: the whole primitive (10 guided denoiser passes and the decode) as one
    ``torch.compile(fullgraph=True)`` graph with inductor's weight freezing (constant weights let it
    prepack them for oneDNN); compiling happens in the untimed warm-up, and the row gets the largest
    difference from the eager sampler's output. ``cuda_graph`` (CUDA, with ``compiled``): that graph is also
    captured and replayed as a CUDA graph (``mode="reduce-overhead"``; each call marked as a new step, so a
    replay may overwrite the previous output). ``reference``: the plain sampler's output on the same inputs
    (:func:`_reference`); the row then gets the timed sampler's (largest, relative L2) difference from it.
    """
    hist, text, noise = _sampler_inputs(model, batch, device, seed=0)

    def sample(h, t, n):
        return model.sample_primitive(h, t, n, guidance_scale=GUIDANCE_SCALE).future

    extra = {}
    with torch.no_grad():
        if compiled:
            import torch._inductor.config as inductor_config

            model.prepare_compile()
            torch._dynamo.reset()
            with inductor_config.patch(freezing=True):
                graph = torch.compile(sample, fullgraph=True, dynamic=False,
                                      mode="reduce-overhead" if cuda_graph else "default")

                def fn(h, t, n):
                    if cuda_graph:
                        torch.compiler.cudagraph_mark_step_begin()
                    return graph(h, t, n)

                out = fn(hist, text, noise).float().clone()
                extra["max_abs_diff_vs_eager"] = float((out - sample(hist, text, noise)).abs().max())
                sec = median_time(lambda: fn(hist, text, noise), repeats=repeats, device=device)
            torch._dynamo.reset()
        else:
            out = sample(hist, text, noise).float()
            sec = median_time(lambda: sample(hist, text, noise), repeats=repeats, device=device)
    if reference is not None:
        extra["max_abs_diff_vs_plain"] = float((out - reference).abs().max())
        extra["rel_diff_vs_plain"] = float((out - reference).norm() / reference.norm())
    return {
        "batch": batch,
        "ms_per_batch": sec * 1e3,
        "ms_per_primitive": sec * 1e3 / batch,
        "primitives_per_s": batch / sec,
        "frames_per_s": 8 * batch / sec,
        **extra,
    }


def _variant_label(row: dict) -> str:
    """'eager', 'compiled', 'packed', 'compiled + packed', 'bf16 autocast + compiled + CUDA graph', ... for a row."""
    parts = [f"{row['amp']} autocast"] if row.get("amp") else []
    parts += [p for p, on in (("compiled", row.get("compiled")), ("CUDA graph", row.get("cuda_graph")),
                              ("packed", row.get("packed"))) if on]
    return " + ".join(parts) or "eager"


def _reference(model, batch: int, device: str) -> torch.Tensor:
    """The plain sampler's output (fp32, eager, unpacked) on :func:`time_sampler`'s inputs."""
    hist, text, noise = _sampler_inputs(model, batch, device, seed=0)
    with torch.no_grad():
        return model.sample_primitive(hist, text, noise, guidance_scale=GUIDANCE_SCALE).future.float()


def run_dart_peer(req: RolloutBenchRequest, batches: list[int], device: str = "cpu",
                  dtype: str = "fp32") -> dict | None:
    """Run shared/tools/dart_peer_bench.py (DART's own sampler) in its own Python environment.

    ``device`` and ``dtype`` ('fp32', or 'fp16': fp16 autocast, DART's own GPU mode) are passed on for CUDA.
    """
    src = req.dart_src or os.environ.get("DART_SRC")
    if not src:
        return None
    shared = Path(os.environ.get("LATENTRL_SHARED", Path.cwd().parent / "shared"))
    script = Path(req.dart_bench) if req.dart_bench else shared / "tools" / "dart_peer_bench.py"
    if not script.is_file():
        raise LatentRLError(f"DART peer benchmark not found at {script}; pass --dart-bench PATH")
    stubs = os.environ.get("DART_STUBS", str(script.parent / "dart_stubs"))
    python = req.dart_python or os.environ.get("DART_PYTHON") or sys.executable
    cmd = [python, str(script), "--batches", *map(str, batches)]
    if req.threads:
        cmd += ["--threads", str(req.threads)]
    if device != "cpu":
        cmd += ["--device", device, "--amp", "none" if dtype == "fp32" else dtype]
    env = {**os.environ, "DART_SRC": src, "DART_STUBS": stubs}
    print(f"running DART's sampler: {' '.join(cmd)}", file=sys.stderr)
    proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
    if proc.returncode != 0:
        raise LatentRLError(
            f"DART peer benchmark failed (exit {proc.returncode}): "
            f"{proc.stderr.strip().splitlines()[-1] if proc.stderr.strip() else ''}"
        )
    lines = [ln for ln in proc.stdout.splitlines() if ln.strip().startswith("{")]
    return json.loads(lines[-1])


def _dart_runs(devices: list[str]) -> list[tuple[str, str]]:
    """(device, dtype) of each DART peer run: the CPU in fp32; each CUDA device in fp32 and in fp16 (DART's own)."""
    runs = [("cpu", "fp32")] if "cpu" in devices else []
    return runs + [(d, dtype) for d in devices if d != "cpu" for dtype in ("fp32", "fp16")]


def _dart_ms(dart: dict, batch: int) -> float | None:
    for row in dart.get("results", dart.get("batches", [])):
        if int(row.get("batch", row.get("batch_size", -1))) == batch:
            return float(row.get("ms_per_batch_median", row.get("ms_per_batch", 0.0)))
    return None


def bench_rollout(req: RolloutBenchRequest) -> int:
    """Primitives/s and frames/s per model, device and batch size; DART's sampler side by side."""
    from latentrl.motion.checkpoint import load_motion_model

    if req.threads:
        torch.set_num_threads(req.threads)
    devices = default_devices(req.device)
    peak = matmul_peak_gflops()
    out = {"benchmark": "rollout", "hardware": hardware(), "matmul_peak_gflops": peak, "models": {}}
    print(
        f"hardware: {out['hardware']['cpu']} ({out['hardware']['torch_threads']} threads); "
        f"fp32 matmul peak {peak:.1f} GFLOP/s"
    )
    # every model loads before any timing starts: a bad name fails at once (exit 2), never after a half run
    loaded = {name: official_size_model() if name == "official" else load_motion_model(name) for name in req.models}
    for name, model in loaded.items():
        flops = analytic_flops_per_primitive(model)
        rows = []
        for device in devices:
            model = model.to(device)
            for batch in req.batches:
                row = {"device": device, **time_sampler(model, batch, device, req.repeats)}
                if device == "cpu":
                    row["gflops"] = flops * row["primitives_per_s"] / 1e9
                    row["fraction_of_matmul_peak"] = row["gflops"] / peak
                rows.append(row)
                print(
                    f"{name:>10} {device:>5} batch {batch:>4}: {row['ms_per_primitive']:8.2f} ms/primitive "
                    f"{row['primitives_per_s']:8.1f} primitives/s {row['frames_per_s']:9.1f} frames/s"
                )
            needs_ref = bool(req.amp) or (req.packed and device == "cpu")
            fp32_refs = {batch: _reference(model, batch, device) for batch in req.batches} if needs_ref else {}
            graph = req.cuda_graph and device.startswith("cuda")
            # (model, amp, packed, compiled, captured as a CUDA graph)
            compiled_kinds = [(True, False)] * req.compile + [(True, True)] * graph
            variants = [(model, None, False, c, g) for c, g in compiled_kinds]
            if req.packed and device == "cpu":
                packed = copy.deepcopy(model)
                packed.pack_for_cpu()
                variants += [(packed, None, True, False, False)]
                variants += [(packed, None, True, c, g) for c, g in compiled_kinds]
            # autocast last: with the compiled bf16 rows timed first (batches 1 and 16), compiled + packed fp32 at
            # batch 1 measured 115 ms in the same process, against 80 ms without them (one thread, 2026-11-26)
            for amp in req.amp or []:
                variants += [(model, amp, False, False, False)] + [(model, amp, False, c, g) for c, g in compiled_kinds]
            for variant, amp, is_packed, compiled, captured in variants:
                variant.amp_dtype = AMP_DTYPES[amp] if amp else None
                for batch in req.batches:
                    reference = fp32_refs[batch] if amp or is_packed else None
                    row = {"device": device, **({"amp": amp} if amp else {}), "compiled": compiled, "packed": is_packed,
                           **({"cuda_graph": True} if captured else {}),
                           **time_sampler(variant, batch, device, req.repeats, compiled=compiled, reference=reference,
                                          cuda_graph=captured)}
                    rows.append(row)
                    diffs = [f"max |compiled - eager| {row['max_abs_diff_vs_eager']:.1e}"] if compiled else []
                    if "max_abs_diff_vs_plain" in row:
                        diffs.append(f"max |{_variant_label(row)} - plain fp32| {row['max_abs_diff_vs_plain']:.1e}, "
                                     f"relative {row['rel_diff_vs_plain']:.1e}")
                    print(f"{name:>10} {device:>5} {_variant_label(row)} batch {batch:>4}: "
                          f"{row['ms_per_primitive']:8.2f} ms/primitive {row['primitives_per_s']:8.1f} primitives/s"
                          + (f" ({'; '.join(diffs)})" if diffs else ""))
                variant.amp_dtype = None
        out["models"][name] = {
            "flops_per_primitive": flops,
            "latent_shape": list(model.latent_shape),
            "source": model.info.get("source"),
            "results": rows,
        }
    ours = out["models"].get("official", {}).get("results", [])
    for device, peer_dtype in _dart_runs(devices):
        dart = run_dart_peer(req, req.batches, device=device, dtype=peer_dtype)
        if dart is None:
            break
        on_cpu, dev = device == "cpu", device.replace(":", "")
        tag = "" if on_cpu else f"_{dev}_{peer_dtype}"
        out["dart_peer" + tag] = dart
        ratios: dict[str, dict[str, float]] = {}
        for row in ours:
            ref = _dart_ms(dart, row["batch"])
            if row["device"] == device and ref:
                ratios.setdefault(_variant_label(row), {})[str(row["batch"])] = ref / row["ms_per_batch"]
        base = "speedup_vs_dart_official_cpu" if on_cpu else f"speedup_vs_dart_{peer_dtype}_official_{dev}"
        for label, by_batch in ratios.items():
            suffix = "" if label == "eager" else "_" + label.replace(" + ", "_").replace(" ", "_")
            out[base + suffix] = by_batch
            for b, r in by_batch.items():
                shown = "fp32" if label == "eager" else label if "autocast" in label else "fp32 " + label
                peer = "" if on_cpu else f" ({peer_dtype})"
                print(f"official size, {'CPU' if on_cpu else device} {shown}, batch {b}: {r:.2f}x "
                      f"DART's sampler{peer} speed (same run)")
    write_json(req.json, out)
    return 0
