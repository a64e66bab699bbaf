"""``latentrl bench rollout``: primitives/s of the motion model, side by side with DART's own sampler."""

from __future__ import annotations

import copy
import json
import os
import statistics
import subprocess
import sys
import types
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import torch

from latentrl.app.bench.common import (
    check_amp,
    check_bench_memory,
    default_devices,
    official_size_model,
    write_json,
)
from latentrl.constants import GUIDANCE_SCALE
from latentrl.errors import LatentRLError
from latentrl.motion.rollout import AMP_DTYPES
from latentrl.timing import hardware, matmul_peak_gflops, median_time

DEFAULT_ROUNDS = 5
"""Rounds of (ours, DART's) timings when DART's sampler runs beside ours."""


@dataclass
class RolloutBenchRequest:
    """``latentrl bench rollout`` flags."""

    batches: list[int] = field(default_factory=lambda: [1, 16, 256])
    models: list[str] = field(default_factory=lambda: ["official", "default"])
    device: list[str] | None = None
    repeats: int = 5
    rounds: int = DEFAULT_ROUNDS
    """With a peer: ours then DART's, this many times over; ratios are the median over rounds."""
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


def _fresh_function(fn: Callable, name: str) -> Callable:
    """``fn`` with a code object of its own, so that dynamo's cache (kept per code object) holds only its graphs.

    Each compiled variant keeps its graph for every round; without this, variants of one model (plain, packed)
    would share one cache and could pick each other's graph (frozen weights are constants in it).
    """
    code = fn.__code__.replace(co_name=name)
    return types.FunctionType(code, fn.__globals__, name, fn.__defaults__, fn.__closure__)


def prepare_sampler(model, batch: int, device: str, compiled: bool = False, reference: torch.Tensor | None = None,
                    cuda_graph: bool = False) -> tuple[Callable[[], object], dict]:
    """A no-argument call of one primitive-batch of :meth:`MotionModel.sample_primitive` (DART's CFG, DDIM 10).

    ``compiled``: the whole primitive (10 guided denoiser passes and the decode) as one
    ``torch.compile(fullgraph=True)`` graph with inductor's weight freezing (constant weights let it
    prepack them for oneDNN); it compiles here, untimed, and the returned facts get the largest
    difference from the eager sampler's output. ``cuda_graph`` (CUDA, with ``compiled``): that graph is also
    captured and replayed as a CUDA graph (``mode="reduce-overhead"``; each call marked as a new step, so a
    replay may overwrite the previous output). ``reference``: the plain sampler's output on the same inputs
    (:func:`_reference`); the facts then get the (largest, relative L2) difference from it.
    The call can be timed again and again (one round each) without compiling again.
    """
    hist, text, noise = _sampler_inputs(model, batch, device, seed=0)

    def sample(h, t, n):
        return model.sample_primitive(h, t, n, guidance_scale=GUIDANCE_SCALE).future

    extra = {}
    with torch.no_grad():
        if compiled:
            import torch._inductor.config as inductor_config

            model.prepare_compile()
            own = _fresh_function(sample, f"sample_b{batch}_{id(model):x}_{'graph' if cuda_graph else 'plain'}")
            with inductor_config.patch(freezing=True):
                graph = torch.compile(own, fullgraph=True, dynamic=False,
                                      mode="reduce-overhead" if cuda_graph else "default")

                def fn(h, t, n):
                    if cuda_graph:
                        torch.compiler.cudagraph_mark_step_begin()
                    return graph(h, t, n)

                out = fn(hist, text, noise).float().clone()
            extra["max_abs_diff_vs_eager"] = float((out - sample(hist, text, noise)).abs().max())
        else:
            fn = sample
            out = sample(hist, text, noise).float()
    if reference is not None:
        extra["max_abs_diff_vs_plain"] = float((out - reference).abs().max())
        extra["rel_diff_vs_plain"] = float((out - reference).norm() / reference.norm())

    def call():
        with torch.no_grad():
            return fn(hist, text, noise)

    return call, extra


def speed_row(batch: int, seconds: float) -> dict:
    """The speed fields of a row: ms per batch and per primitive, primitives/s and frames/s (8 per primitive)."""
    return {
        "batch": batch,
        "ms_per_batch": seconds * 1e3,
        "ms_per_primitive": seconds * 1e3 / batch,
        "primitives_per_s": batch / seconds,
        "frames_per_s": 8 * batch / seconds,
    }


def time_sampler(model, batch: int, device: str, repeats: int, compiled: bool = False,
                 reference: torch.Tensor | None = None, cuda_graph: bool = False) -> dict:
    """One row: :func:`prepare_sampler`, then the median of ``repeats`` timed calls."""
    call, extra = prepare_sampler(model, batch, device, compiled, reference, cuda_graph)
    return {**speed_row(batch, median_time(call, repeats=repeats, device=device)), **extra}


def interleave(rounds: int, ours: Callable[[int], None], peer: Callable[[int], bool]) -> list[str]:
    """Run ``ours(r)`` then ``peer(r)`` for r = 0 .. rounds - 1 (A/B/A/B ...); the order of the calls made.

    Load that changes during the run then falls on both sides of every ratio instead of on one side.
    ``peer`` returns False when there is no peer: the remaining rounds are not run (a lone sampler needs one).
    """
    order = []
    for r in range(rounds):
        ours(r)
        order.append(f"ours {r}")
        if not peer(r):
            break
        order.append(f"peer {r}")
    return order


def ratio_spread(peer_ms: list[float], ours_ms: list[float]) -> dict:
    """Per-round speed ratios (peer time / our time, same round) and their median, min, max and quartiles."""
    if not peer_ms or len(peer_ms) != len(ours_ms):
        raise ValueError(f"need one time per round on both sides, got {len(peer_ms)} and {len(ours_ms)}")
    ratios = [p / o for p, o in zip(peer_ms, ours_ms)]
    q1, _, q3 = statistics.quantiles(ratios, n=4, method="inclusive") if len(ratios) > 1 else (ratios[0],) * 3
    return {"median": statistics.median(ratios), "min": min(ratios), "max": max(ratios), "q1": q1, "q3": q3,
            "rounds": ratios}


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
                  dtype: str = "fp32", first: bool = True) -> dict | None:
    """Run shared/tools/dart_peer_bench.py (DART's own sampler) in its own Python environment.

    ``device`` and ``dtype`` ('fp32', or 'fp16': fp16 autocast, DART's own GPU mode) are passed on for CUDA.
    It times ``req.repeats`` runs per batch, as ours; after the ``first`` round its matmul-peak probe is cut
    short (that figure is kept from the first round only).
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
    cmd = [python, str(script), "--batches", *map(str, batches), "--reps", str(req.repeats)]
    if not first:
        cmd += ["--matmul-n", "256", "--matmul-reps", "2"]
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
    """Primitives/s and frames/s per model, device and batch size; DART's sampler interleaved with ours."""
    from latentrl.memory import SAMPLE_BYTES
    from latentrl.motion.checkpoint import load_motion_model

    devices = default_devices(req.device)
    check_amp(req.amp, devices)
    check_bench_memory(max(req.batches), SAMPLE_BYTES, "--batches", "a sampler batch")
    if req.threads:
        torch.set_num_threads(req.threads)
    if req.compile:  # refuse before any timing when torch cannot compile here
        from latentrl.preflight import check_compile

        for device in devices:
            check_compile(device, "--compile", "leave out --compile")
    peak = matmul_peak_gflops()
    out = {"benchmark": "rollout", "hardware": hardware(), "matmul_peak_gflops": peak, "models": {}}
    hw = f"{out['hardware']['cpu']}, {out['hardware']['torch_threads']} torch threads" + (
        f", {out['hardware']['gpu']}" if "gpu" in out["hardware"] else "")
    print(f"hardware: {hw}; fp32 matmul peak {peak:.1f} GFLOP/s")
    # every model loads before any timing starts: a bad name fails at once (exit 2), never after a half run
    loaded = {name: official_size_model() if name == "official" else load_motion_model(name) for name in req.models}
    timers: list[dict] = []
    if req.compile:
        torch._dynamo.reset()

    def first_round() -> None:
        """Prepare every row (compiling where asked) and time it once, in the order the rows print."""
        for name, model in loaded.items():
            out["models"][name] = {
                "flops_per_primitive": analytic_flops_per_primitive(model),
                "latent_shape": list(model.latent_shape),
                "source": model.info.get("source"),
                "results": [],
            }
            for device in devices:
                model = model.to(device)
                for batch in req.batches:
                    call, extra = prepare_sampler(model, batch, device)
                    add_row(name, model, None, call, {"device": device, "batch": batch, **extra})
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
                # autocast last: with the compiled bf16 rows timed first (batches 1 and 16), compiled + packed fp32
                # at batch 1 measured 115 ms in the same process, against 80 ms without them (one thread, 2026-11-26)
                for amp in req.amp or []:
                    variants += [(model, amp, False, False, False)]
                    variants += [(model, amp, False, c, g) for c, g in compiled_kinds]
                for variant, amp, is_packed, compiled, captured in variants:
                    variant.amp_dtype = AMP_DTYPES[amp] if amp else None
                    for batch in req.batches:
                        reference = fp32_refs[batch] if amp or is_packed else None
                        call, extra = prepare_sampler(variant, batch, device, compiled=compiled, reference=reference,
                                                      cuda_graph=captured)
                        row = {"device": device, "batch": batch, **({"amp": amp} if amp else {}), "compiled": compiled,
                               "packed": is_packed, **({"cuda_graph": True} if captured else {}), **extra}
                        add_row(name, variant, amp, call, row)
                    variant.amp_dtype = None

    def add_row(name: str, model, amp: str | None, call, row: dict) -> None:
        timer = {"name": name, "model": model, "amp": amp, "call": call, "row": row, "seconds": []}
        timers.append(timer)
        time_once(timer, warmup=2)
        out["models"][name]["results"].append(row)
        base = _eager_of(timer)
        versus = f" {base['seconds'][0] / timer['seconds'][0]:.2f}x eager (same run)" if base is not timer else ""
        diffs = [f"max |compiled - eager| {row['max_abs_diff_vs_eager']:.1e}"] if row.get("compiled") else []
        if "max_abs_diff_vs_plain" in row:
            diffs.append(f"max |{_variant_label(row)} - plain fp32| {row['max_abs_diff_vs_plain']:.1e}, "
                         f"relative {row['rel_diff_vs_plain']:.1e}")
        ms = timer["seconds"][0] * 1e3
        print(f"{name:>10} {row['device']:>5} {_variant_label(row)} batch {row['batch']:>4}: "
              f"{ms / row['batch']:8.2f} ms/primitive {row['batch'] / ms * 1e3:8.1f} primitives/s{versus}"
              + (f" ({'; '.join(diffs)})" if diffs else ""))

    def time_once(timer: dict, warmup: int) -> None:
        timer["model"].amp_dtype = AMP_DTYPES[timer["amp"]] if timer["amp"] else None
        try:
            timer["seconds"].append(median_time(timer["call"], repeats=req.repeats, warmup=warmup,
                                                device=timer["row"]["device"]))
        finally:
            timer["model"].amp_dtype = None

    def _eager_of(timer: dict) -> dict:
        """The plain eager row of the same model, device and batch (timed just before the variants)."""
        return next(t for t in timers if t["name"] == timer["name"] and _variant_label(t["row"]) == "eager"
                    and t["row"]["device"] == timer["row"]["device"] and t["row"]["batch"] == timer["row"]["batch"])

    def ours(r: int) -> None:
        if r == 0:
            first_round()
            return
        for timer in timers:
            time_once(timer, warmup=1)
        print(f"round {r + 1}: ours timed ({len(timers)} rows)", file=sys.stderr)

    peers: dict[tuple[str, str], list[dict]] = {}

    def peer(r: int) -> bool:
        for device, peer_dtype in _dart_runs(devices):
            dart = run_dart_peer(req, req.batches, device=device, dtype=peer_dtype, first=r == 0)
            if dart is None:
                return False
            peers.setdefault((device, peer_dtype), []).append(dart)
        return bool(peers)

    out["order"] = interleave(req.rounds, ours, peer)
    rounds = sum(o.startswith("ours") for o in out["order"])
    out["rounds"] = rounds
    for timer in timers:
        row = timer["row"]
        row.update(speed_row(row["batch"], statistics.median(timer["seconds"])))
        row["ms_per_batch_rounds"] = [s * 1e3 for s in timer["seconds"]]
        base = _eager_of(timer)
        if base is not timer:
            row["speedup_vs_eager"] = ratio_spread(base["seconds"], timer["seconds"])["median"]
        if row["device"] == "cpu":
            row["gflops"] = out["models"][timer["name"]]["flops_per_primitive"] * row["primitives_per_s"] / 1e9
            row["fraction_of_matmul_peak"] = row["gflops"] / peak
    if rounds > 1:
        print(f"{rounds} rounds; each row's figure is the median over rounds")
    ours_rows = out["models"].get("official", {}).get("results", [])
    for (device, peer_dtype), reports in peers.items():
        _peer_ratios(out, ours_rows, device, peer_dtype, reports, hw)
    if req.compile:
        torch._dynamo.reset()
    write_json(req.json, out)
    return 0


def _peer_ratios(out: dict, ours_rows: list[dict], device: str, peer_dtype: str, reports: list[dict],
                 hw: str) -> None:
    """Same-round speed ratios of each official-size row against DART's sampler: median and spread, printed."""
    on_cpu, dev = device == "cpu", device.replace(":", "")
    tag = "" if on_cpu else f"_{dev}_{peer_dtype}"
    first = dict(reports[0])
    first["ms_per_batch_rounds"] = {}
    base = "speedup_vs_dart_official_cpu" if on_cpu else f"speedup_vs_dart_{peer_dtype}_official_{dev}"
    peer = "DART's sampler" + ("" if on_cpu else f" ({peer_dtype})")
    print(f"\nofficial size against {peer}, {'CPU' if on_cpu else device} ({hw}), {len(reports)} interleaved "
          f"round(s) (ours, DART's, ours, ...); ratio = DART's time / ours in the same round:")
    print(f"  {'variant':<36} {'batch':>5} {'ours ms':>9} {'DART ms':>9} {'ratio':>7}  {'min-max':>13}  IQR")
    for row in ours_rows:
        if row["device"] != device:
            continue
        peer_ms = [_dart_ms(rep, row["batch"]) for rep in reports]
        if any(ms is None for ms in peer_ms):
            continue
        first["ms_per_batch_rounds"][str(row["batch"])] = peer_ms
        label = _variant_label(row)
        stats = ratio_spread(peer_ms, row["ms_per_batch_rounds"])
        suffix = "" if label == "eager" else "_" + label.replace(" + ", "_").replace(" ", "_")
        out.setdefault(base + suffix, {})[str(row["batch"])] = stats["median"]
        out.setdefault(base + suffix + "_spread", {})[str(row["batch"])] = stats
        shown = "fp32" if label == "eager" else label if "autocast" in label else "fp32 " + label
        print(f"  {shown:<36} {row['batch']:>5} {row['ms_per_batch']:9.1f} {statistics.median(peer_ms):9.1f} "
              f"{stats['median']:6.2f}x  {stats['min']:5.2f}-{stats['max']:5.2f}x  "
              f"{stats['q1']:.2f}-{stats['q3']:.2f}x")
    out["dart_peer" + tag] = first
