"""``latentrl bench ...``: speed and quality figures, measured side by side, written to JSON.

Absolute timings on shared machines are noisy, so every benchmark reports ratios measured in
the same run next to absolute figures labelled with the hardware (:func:`hardware`).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import statistics
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import torch

from latentrl.errors import LatentRLError


# --------------------------------------------------------------------------- shared helpers
def hardware() -> dict:
    """CPU model, core count, torch build and GPU name: the label every figure carries."""
    cpu = platform.processor() or "unknown"
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    info = {
        "cpu": cpu,
        "cpu_count": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "torch": torch.__version__,
        "python": platform.python_version(),
    }
    if torch.cuda.is_available():
        info["gpu"] = torch.cuda.get_device_name(0)
    return info


def median_time(fn: Callable[[], object], repeats: int = 5, warmup: int = 2, device: str = "cpu") -> float:
    """Median wall time of ``fn`` in seconds (CUDA-synchronized on GPU)."""
    sync = torch.cuda.synchronize if device.startswith("cuda") else (lambda: None)
    for _ in range(warmup):
        fn()
    sync()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        sync()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def matmul_peak_gflops(n: int = 2048, repeats: int = 7) -> float:
    """Median fp32 GFLOP/s of an n x n matmul on CPU (the reference for 'fraction of peak')."""
    a, b, c = torch.randn(n, n), torch.randn(n, n), torch.empty(n, n)
    t = median_time(lambda: torch.matmul(a, b, out=c), repeats=repeats, warmup=2)
    return 2.0 * n**3 / t / 1e9


def write_json(path: str | None, data: dict) -> None:
    if path:
        from latentrl.safe_io import atomic_write_text

        atomic_write_text(path, json.dumps(data, indent=2) + "\n")
        print(f"wrote {path}")


def default_devices(requested: list[str] | None) -> list[str]:
    if requested:
        for d in requested:
            if d.startswith("cuda") and not torch.cuda.is_available():
                raise LatentRLError(f"device '{d}' requested but CUDA is not available on this machine")
        return requested
    return ["cpu"] + (["cuda"] if torch.cuda.is_available() else [])


# --------------------------------------------------------------------------- rollout
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


def time_sampler(model, batch: int, device: str, repeats: int) -> dict:
    """Ms per primitive-batch of :meth:`MotionModel.sample_primitive` with CFG 5 (DDIM 10)."""
    g = torch.Generator().manual_seed(0)
    hist = torch.randn(batch, 2, 276, generator=g).to(device) * 0.1
    text = torch.randn(batch, model.text_dim, generator=g).to(device)
    noise = torch.randn(batch, *model.latent_shape, generator=g).to(device)
    sec = median_time(
        lambda: model.sample_primitive(hist, text, noise, guidance_scale=5.0), repeats=repeats, device=device
    )
    return {
        "batch": batch,
        "ms_per_batch": sec * 1e3,
        "ms_per_primitive": sec * 1e3 / batch,
        "primitives_per_s": batch / sec,
        "frames_per_s": 8 * batch / sec,
    }


def run_dart_peer(args: argparse.Namespace, batches: list[int]) -> dict | None:
    """Run shared/tools/dart_peer_bench.py (DART's own sampler) in its own Python environment."""
    src = args.dart_src or os.environ.get("DART_SRC")
    if not src:
        return None
    script = (
        Path(args.dart_bench)
        if args.dart_bench
        else Path(__file__).resolve().parents[2] / "shared/tools/dart_peer_bench.py"
    )
    if not script.is_file():
        raise LatentRLError(f"DART peer benchmark not found at {script}; pass --dart-bench PATH")
    stubs = os.environ.get("DART_STUBS", str(script.parent / "dart_stubs"))
    python = args.dart_python or os.environ.get("DART_PYTHON") or sys.executable
    cmd = [python, str(script), "--batches", *map(str, batches)]
    if args.threads:
        cmd += ["--threads", str(args.threads)]
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


def _dart_ms(dart: dict, batch: int) -> float | None:
    for row in dart.get("results", dart.get("batches", [])):
        if int(row.get("batch", row.get("batch_size", -1))) == batch:
            return float(row.get("ms_per_batch_median", row.get("ms_per_batch", 0.0)))
    return None


def bench_rollout(args: argparse.Namespace) -> int:
    """Primitives/s and frames/s per model, device and batch size; DART's sampler side by side."""
    from latentrl.motion.checkpoint import load_motion_model

    if args.threads:
        torch.set_num_threads(args.threads)
    devices = default_devices(args.device)
    peak = matmul_peak_gflops()
    out = {"benchmark": "rollout", "hardware": hardware(), "matmul_peak_gflops": peak, "models": {}}
    print(
        f"hardware: {out['hardware']['cpu']} ({out['hardware']['torch_threads']} threads); "
        f"fp32 matmul peak {peak:.1f} GFLOP/s"
    )
    for name in args.models:
        try:
            model = official_size_model() if name == "official" else load_motion_model(name)
        except LatentRLError as exc:
            print(f"skipping model '{name}': {exc}", file=sys.stderr)
            continue
        flops = analytic_flops_per_primitive(model)
        rows = []
        for device in devices:
            model = model.to(device)
            for batch in args.batches:
                row = {"device": device, **time_sampler(model, batch, device, args.repeats)}
                if device == "cpu":
                    row["gflops"] = flops * row["primitives_per_s"] / 1e9
                    row["fraction_of_matmul_peak"] = row["gflops"] / peak
                rows.append(row)
                print(
                    f"{name:>10} {device:>5} batch {batch:>4}: {row['ms_per_primitive']:8.2f} ms/primitive "
                    f"{row['primitives_per_s']:8.1f} primitives/s {row['frames_per_s']:9.1f} frames/s"
                )
            for amp in args.amp or []:
                model.amp_dtype = {"bf16": torch.bfloat16, "fp16": torch.float16}[amp]
                for batch in args.batches:
                    row = {"device": device, "amp": amp, **time_sampler(model, batch, device, args.repeats)}
                    rows.append(row)
                    print(f"{name:>10} {device:>5} {amp} batch {batch:>4}: {row['ms_per_primitive']:8.2f} "
                          f"ms/primitive {row['primitives_per_s']:8.1f} primitives/s")
                model.amp_dtype = None
        out["models"][name] = {
            "flops_per_primitive": flops,
            "latent_shape": list(model.latent_shape),
            "source": model.info.get("source"),
            "results": rows,
        }
    dart = run_dart_peer(args, args.batches)
    if dart is not None:
        out["dart_peer"] = dart
        ours = out["models"].get("official", {}).get("results", [])
        ratios = {}
        for row in ours:
            ref = _dart_ms(dart, row["batch"])
            if row["device"] == "cpu" and "amp" not in row and ref:
                ratios[str(row["batch"])] = ref / row["ms_per_batch"]
        out["speedup_vs_dart_official_cpu"] = ratios
        for b, r in ratios.items():
            print(f"official size, CPU fp32, batch {b}: {r:.2f}x DART's sampler speed (same run)")
    write_json(args.json, out)
    return 0


# --------------------------------------------------------------------------- motion quality
#: Prompts probed by ``bench motion`` and the training skill whose data they are compared with.
MOTION_PROBES = {
    "walk": "walk",
    "run": "run",
    "stand still": "stand",
    "hop on left leg": "hop_left",
    "hop on right leg": "hop_right",
    "turn left": "turn_left",
    "turn right": "turn_right",
    "jump forward": "jump_forward",
    "walk backwards": "walk_backward",
    "sidestep left": "sidestep_left",
    "sidestep right": "sidestep_right",
}


def _data_reference(model) -> dict | None:
    """Per-skill statistics of the model's own training data (regenerated from its config)."""
    cfg = (model.info.get("config") or {}).get("data") or {}
    if cfg.get("source") != "locomotion":
        return None
    from latentrl.datasets.locomotion import LocomotionConfig, dataset_statistics, generate_sequences

    loco = cfg.get("locomotion") or {}
    fields = {k: tuple(v) if isinstance(v, list) else v for k, v in loco.items()}
    seqs = generate_sequences(LocomotionConfig(**fields))
    pelvis_z = [float(s["joints"][:, 0, 2].min()) for s in seqs] + [float(s["joints"][:, 0, 2].max()) for s in seqs]
    body = [_pelvis_over_feet(torch.as_tensor(s["joints"])) for s in seqs]
    stats = dataset_statistics(seqs)
    stats["pelvis_z_range"] = [min(pelvis_z), max(pelvis_z)]
    stats["pelvis_over_feet_range"] = [float(min(b.min() for b in body)), float(max(b.max() for b in body))]
    return stats


def _pelvis_over_feet(joints: torch.Tensor) -> torch.Tensor:
    """(..., T, 22, 3) -> (..., T) pelvis height above the lower foot joint, metres.

    The body's own height, independent of where the floor drifted to.
    """
    from latentrl.motion.skeleton import FOOT_JOINTS

    return joints[..., 0, 2] - joints[..., list(FOOT_JOINTS), 2].amin(dim=-1)


def steering_spread_deg(model, text: str, batch: int = 64, steps: int = 4, seed: int = 0,
                        guidance: float = 5.0, action_box: float | None = None) -> float:
    """How much the action (initial noise) can steer ``text``: 5-95 % spread of the yaw change, degrees.

    Every sequence starts from the same state (seed history 0 and two primitives with shared
    noise, so the gait is under way), then takes ``steps`` primitives with independent N(0, I)
    noise. A controller can only turn as far as the noise moves the heading, so a narrow spread
    means a policy cannot steer this prompt toward a goal, whatever the reward. With ``action_box``
    the noise is uniform in +-``action_box`` per value instead (a policy's whole action range).
    """
    from latentrl.evaluation import metrics as M

    g = torch.Generator().manual_seed(seed)
    state = model.initial_state(batch, g, seed_index=torch.zeros(batch, dtype=torch.long))
    emb = model.encode_text([text] * batch)
    for _ in range(2):
        shared = torch.randn(1, *model.latent_shape, generator=g).expand(batch, *model.latent_shape)
        state = model.rollout_step(state, emb, shared.contiguous().to(model.device), guidance).state
    noise = None
    if action_box is not None:
        noise = (torch.rand(steps, batch, *model.latent_shape, generator=g) * 2 - 1) * action_box
    roll = model.rollout(text, steps, batch=batch, noise=noise, generator=g, guidance_scale=guidance, state=state)
    yaw = M.heading_change_rad(roll.joints_world[:, 1:]) * 180 / math.pi
    lo, hi = torch.quantile(yaw.float().cpu(), torch.tensor([0.05, 0.95])).tolist()
    return hi - lo


#: The skill-switch probe: (prompt, seconds) in order; each switch should show within 1 s.
SWITCH_TIMELINE = (("walk", 4.0), ("run", 4.0), ("hop on left leg", 4.0), ("walk", 4.0))
_SWITCH_WINDOW = 15  # frames (0.5 s) over which a skill's signature must hold


def _skill_signature(text: str, joints: torch.Tensor) -> torch.Tensor:
    """(B, W, 22, 3) windows -> (B,) True where the window moves like ``text`` (run, hop, walk)."""
    from latentrl.evaluation import metrics as M

    speed = M.pelvis_speed_m_s(joints)
    shares = M.foot_contact_shares(joints)
    if text == "run":
        return speed > 2.0
    if text == "hop on left leg":
        return (shares["left_only"] >= 0.5) & (shares["right_only"] <= 0.1)
    return (speed > 0.5) & (speed < 2.0) & (shares["left_only"] >= 0.15) & (shares["right_only"] >= 0.15)


def skill_switch_seconds(model, batch: int = 8, seed: int = 0, guidance: float = 5.0) -> dict:
    """Roll ``SWITCH_TIMELINE`` out; per switch, seconds until the new skill's signature holds.

    Latency is from the text change to the start of the first 0.5 s window that moves like the new
    text (run: speed > 2 m/s; hop on left leg: left foot alone >= 50 % of frames, right alone <= 10 %;
    walk: 0.5-2 m/s with each foot alone >= 15 %); ``inf`` where it never does. Also the lowest joint's
    worst depth below the floor over the whole timeline.
    """
    from latentrl.evaluation import metrics as M

    texts, starts = [], []
    for text, seconds in SWITCH_TIMELINE:
        starts.append(len(texts))
        texts += [text] * max(1, round(seconds * 30 / 8))
    g = torch.Generator().manual_seed(seed)
    roll = model.rollout(texts, len(texts), batch=batch, generator=g, guidance_scale=guidance)
    j = roll.joints_world[:, 2:]
    out = {"switches": []}
    for k in range(1, len(SWITCH_TIMELINE)):
        text, first = SWITCH_TIMELINE[k][0], starts[k] * 8
        last = (starts[k + 1] * 8 if k + 1 < len(starts) else j.shape[1]) - _SWITCH_WINDOW
        latency = torch.full((batch,), math.inf)
        for f in range(last, first - 1, -1):  # backwards: the earliest matching window wins
            hit = _skill_signature(text, j[:, f:f + _SWITCH_WINDOW])
            latency = torch.where(hit, torch.tensor((f - first) / 30), latency)
        out["switches"].append({
            "to": text,
            "median_s": float(latency.median()),
            "within_1s": float((latency <= 1.0).float().mean()),
        })
    out["deepest_below_floor_cm"] = float((-j[..., 2].amin(dim=-1)).clamp(min=0).max()) * 100
    out["penetration_cm"] = float(M.lowest_joint_penetration_cm(j).mean())
    return out


#: Steering-spread floors (degrees over 32 frames) of the default-model targets.
STEER_FLOOR_DEG = {"walk": 35.0, "run": 30.0, "hop on left leg": 25.0, "hop on right leg": 25.0}
#: Floor-distance ceilings (cm) and skate ceilings (cm/s) of the default-model targets.
FLOOR_MAX_CM = {"walk": 3.0, "run": 3.0, "stand still": 3.0, "hop on left leg": 5.0, "hop on right leg": 5.0,
                "jump forward": 5.0}
SKATE_MAX_CM_S = {"walk": 2.0, "run": 3.0, "hop on left leg": 3.0, "hop on right leg": 3.0}


def motion_targets(p: dict, switch: dict, ref: dict | None) -> dict[str, bool]:
    """The default motion model's targets (docs/benchmarks.md) as named pass/fail checks."""
    checks = {}
    for text, floor in STEER_FLOOR_DEG.items():
        checks[f"steer {text} >= {floor:g} deg"] = p[text]["steer_spread_deg"] >= floor
    if ref:
        low = [t for t, r in p.items() if (r.get("data") or {}).get("steer_spread_deg")
               and r["steer_spread_deg"] < 0.6 * r["data"]["steer_spread_deg"]]
        checks["steer >= 60% of the data's for every prompt" + (f" (short: {', '.join(low)})" if low else "")] = not low
    for text, cap in FLOOR_MAX_CM.items():
        checks[f"floor {text} <= {cap:g} cm"] = p[text]["floor_cm"] <= cap
    checks["penetration <= 1 cm for every prompt"] = all(r["penetration_cm"] <= 1.0 for r in p.values())
    for text, cap in SKATE_MAX_CM_S.items():
        checks[f"skate {text} <= {cap:g} cm/s"] = p[text]["skate_cm_s"] <= cap
    checks["hop on left leg: left foot alone >= 60%"] = p["hop on left leg"]["left_only"] >= 0.6
    checks["hop on right leg: right foot alone >= 60%"] = p["hop on right leg"]["right_only"] >= 0.6
    checks["walk 1.0-1.6 m/s"] = 1.0 <= p["walk"]["speed_m_s"] <= 1.6
    checks["run >= 2.5 m/s"] = p["run"]["speed_m_s"] >= 2.5
    checks["walk backwards moves backwards"] = p["walk backwards"]["forward_m_s"] < -0.2
    checks["sidestep left moves left"] = (p["sidestep left"]["rightward_m_s"] < -0.1
                                          and abs(p["sidestep left"]["forward_m_s"]) < 0.1)
    checks["sidestep right moves right"] = (p["sidestep right"]["rightward_m_s"] > 0.1
                                            and abs(p["sidestep right"]["forward_m_s"]) < 0.1)
    checks["walk -> run -> hop -> walk: each switch within 1 s in >= 75% of rollouts, on the floor"] = (
        all(x["within_1s"] >= 0.75 for x in switch["switches"]) and switch["deepest_below_floor_cm"] <= 1.0)
    return checks


def bench_motion(args: argparse.Namespace) -> int:
    """Rollout stability and text control of a motion model, against its training data."""
    from latentrl.evaluation import metrics as M
    from latentrl.motion.checkpoint import load_motion_model

    model = load_motion_model(args.motion)
    if getattr(args, "no_floor_snap", False):
        model.floor_snap = None
    steps = max(1, round(args.seconds * 30 / 8))
    ref = _data_reference(model)
    out = {
        "benchmark": "motion",
        "hardware": hardware(),
        "motion": model.info.get("source"),
        "sha256": model.info.get("sha256"),
        "seconds": args.seconds,
        "batch": args.batch,
        "probes": {},
    }
    print(
        f"{'prompt':>18} {'speed m/s':>9} {'skate cm/s':>10} {'floor cm':>8} {'pelvis z':>13} "
        f"{'turn deg/s':>10} {'L-only':>6} {'R-only':>6} {'steer deg':>9} {'box4':>5} {'pen cm':>6} "
        f"{'fwd':>5} {'right':>5}"
    )
    for text, skill in MOTION_PROBES.items():
        g = torch.Generator().manual_seed(args.seed)
        roll = model.rollout(text, steps, batch=args.batch, generator=g, guidance_scale=args.guidance)
        j = roll.joints_world[:, 2:]  # generated frames only
        finite = bool(torch.isfinite(j).all())
        shares = M.foot_contact_shares(j)
        row = {
            "skill": skill,
            "finite": finite,
            "speed_m_s": float(M.pelvis_speed_m_s(j).mean()),
            "skate_cm_s": float(M.foot_skate_cm_s(j).mean()),
            "floor_cm": float(M.foot_floor_distance_cm(j).mean()),
            "pelvis_z_min": float(j[..., 0, 2].min()),
            "pelvis_z_max": float(j[..., 0, 2].max()),
            "pelvis_over_feet_min": float(_pelvis_over_feet(j).min()),
            "pelvis_over_feet_max": float(_pelvis_over_feet(j).max()),
            "turn_deg_s": float(M.heading_change_rad(j).mean()) * 180 / 3.14159265 / (j.shape[1] / 30),
            "left_only": float(shares["left_only"].mean()),
            "right_only": float(shares["right_only"].mean()),
            "steer_spread_deg": steering_spread_deg(model, text, seed=args.seed, guidance=args.guidance),
            "steer_spread_box4_deg": steering_spread_deg(model, text, seed=args.seed, guidance=args.guidance,
                                                         action_box=4.0),
            "penetration_cm": float(M.lowest_joint_penetration_cm(j).mean()),
        }
        fwd, side = M.body_frame_velocity_m_s(j)
        row["forward_m_s"], row["rightward_m_s"] = float(fwd.mean()), float(side.mean())
        if ref and skill in ref["skills"]:
            row["data"] = ref["skills"][skill]
        out["probes"][text] = row
        print(
            f"{text:>18} {row['speed_m_s']:9.2f} {row['skate_cm_s']:10.2f} {row['floor_cm']:8.2f} "
            f"{row['pelvis_z_min']:6.2f}-{row['pelvis_z_max']:<6.2f} {row['turn_deg_s']:10.1f} "
            f"{row['left_only']:6.2f} {row['right_only']:6.2f} {row['steer_spread_deg']:9.1f} "
            f"{row['steer_spread_box4_deg']:5.1f} {row['penetration_cm']:6.2f} {row['forward_m_s']:5.2f} "
            f"{row['rightward_m_s']:5.2f}", flush=True
        )
    out["skill_switch"] = sw = skill_switch_seconds(model, batch=args.batch, seed=args.seed, guidance=args.guidance)
    print("skill switch:", ", ".join(f"->{x['to']} {x['median_s']:.2f}s ({x['within_1s']:.0%} <= 1 s)"
                                     for x in sw["switches"]),
          f"deepest below floor {sw['deepest_below_floor_cm']:.1f} cm")
    p = out["probes"]
    checks = {
        "stable: finite, body height (pelvis over lower foot) in data range +-10 cm": all(
            r["finite"] for r in p.values())
        and (ref is None or all(ref["pelvis_over_feet_range"][0] - 0.1 <= r["pelvis_over_feet_min"]
                                and r["pelvis_over_feet_max"] <= ref["pelvis_over_feet_range"][1] + 0.1
                                for r in p.values())),
        "no vertical drift: world pelvis height in data range +-10 cm": ref is None or all(
            ref["pelvis_z_range"][0] - 0.1 <= r["pelvis_z_min"] and r["pelvis_z_max"] <= ref["pelvis_z_range"][1] + 0.1
            for r in p.values()),
        "run faster than walk": p["run"]["speed_m_s"] > p["walk"]["speed_m_s"],
        "stand still < 0.1 m/s": p["stand still"]["speed_m_s"] < 0.1,
        "hop on left leg: left-foot-only contact dominates": p["hop on left leg"]["left_only"]
        > max(p["hop on left leg"]["right_only"], p["walk"]["left_only"]),
        "hop on right leg: right-foot-only contact dominates": p["hop on right leg"]["right_only"]
        > max(p["hop on right leg"]["left_only"], p["walk"]["right_only"]),
        "turn left curves left": p["turn left"]["turn_deg_s"] > 5,
        "turn right curves right": p["turn right"]["turn_deg_s"] < -5,
    }
    checks.update(motion_targets(p, out["skill_switch"], ref))
    if ref:
        out["data_reference"] = {"pelvis_z_range": ref["pelvis_z_range"],
                                 "pelvis_over_feet_range": ref["pelvis_over_feet_range"], "skills": ref["skills"]}
    train_s = model.info.get("train_seconds")
    if train_s is not None:
        out["train_seconds"] = train_s
        checks["training <= 2 h"] = train_s <= 7200
    out["checks"] = checks
    for name, ok in checks.items():
        print(f"[{'pass' if ok else 'FAIL'}] {name}")
    write_json(args.json, out)
    return 0


# --------------------------------------------------------------------------- training
def _iteration_summary(times) -> dict:
    """Median per-iteration collection/update seconds, skipping the first (warm-up) iteration."""
    rows = list(times)[1:] or list(times)
    coll = statistics.median(t.collection_s for t in rows)
    upd = statistics.median(t.update_s for t in rows)
    return {"iterations_timed": len(rows), "collection_s": coll, "update_s": upd, "iteration_s": coll + upd,
            "update_share": upd / (coll + upd)}


def bench_train(args: argparse.Namespace) -> int:
    """Time to eval success on the quick config, and native vs SB3 iteration time side by side."""
    import tempfile

    from latentrl.config import load_config
    from latentrl.experiment import QUICK_CONFIG, TrainConfig, run_training

    if args.threads:
        torch.set_num_threads(args.threads)
    base = Path(args.config) if args.config else QUICK_CONFIG
    out = {"benchmark": "train", "hardware": hardware(), "config": str(base)}
    work = Path(args.run_dir) if args.run_dir else Path(tempfile.mkdtemp(prefix="latentrl-bench-train-"))
    if not args.skip_success:
        cfg = load_config(TrainConfig, base, list(args.set or []))
        cfg.eval.success_target = args.target
        cfg.ppo.eval_every = args.eval_every
        if args.max_steps:
            cfg.ppo.total_steps = args.max_steps
        print(f"training {base.name} until eval success >= {args.target} (at most {cfg.ppo.total_steps} env steps)")
        t0 = time.perf_counter()
        res = run_training(cfg, work / "to_success", progress=not args.no_progress)
        wall = time.perf_counter() - t0
        metrics = res.eval.metrics if res.eval is not None else {}
        out["to_success"] = {"target": args.target, "reached": bool(res.stopped_early), "wall_s": wall,
                             "train_s": res.elapsed_s, "env_steps": res.env_steps, "iterations": res.iterations,
                             "last_eval": metrics, **_iteration_summary(res.times)}
        print(f"{'reached' if res.stopped_early else 'did NOT reach'} eval success {args.target} after "
              f"{res.env_steps} env steps, {wall:.0f} s wall (last eval: {metrics})")
    side = {}
    for trainer in ("native", "sb3"):
        cfg = load_config(TrainConfig, base, list(args.set or []))
        cfg.ppo.eval_every = 0
        cfg.ppo.checkpoint_every = 10**6
        plan = cfg.ppo.plan(cfg.env.num_envs)
        cfg.ppo.total_steps = plan.batch_size * args.iterations
        res = run_training(cfg, work / f"side_by_side_{trainer}", trainer=trainer, progress=False)
        side[trainer] = _iteration_summary(res.times)
        s = side[trainer]
        print(f"{trainer:>6}: {s['iteration_s']:.2f} s/iteration (collection {s['collection_s']:.2f} s, "
              f"update {s['update_s']:.2f} s, update share {s['update_share']:.0%})")
    side["native_over_sb3"] = side["native"]["iteration_s"] / side["sb3"]["iteration_s"]
    out["native_vs_sb3"] = side
    print(f"native / SB3 per-iteration time: {side['native_over_sb3']:.2f} (target <= 0.6)")
    write_json(args.json, out)
    return 0
