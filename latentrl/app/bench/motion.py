"""``latentrl bench motion``: stability and text control of a motion model vs. its training data."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from latentrl.app.bench.common import write_json
from latentrl.constants import GUIDANCE_SCALE
from latentrl.timing import hardware


@dataclass
class MotionBenchRequest:
    """``latentrl bench motion`` flags."""

    motion: str = "default"
    seconds: float = 60.0
    batch: int = 8
    guidance: float = GUIDANCE_SCALE
    seed: int = 0
    json: str | None = None


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
                        guidance: float = GUIDANCE_SCALE) -> float:
    """How much the action (initial noise) can steer ``text``: 5-95 % spread of the yaw change, degrees.

    Every sequence starts from the same state (seed history 0 and two primitives with shared
    noise, so the gait is under way), then takes ``steps`` primitives with independent N(0, I)
    noise. A controller can only turn as far as the noise moves the heading, so a narrow spread
    means a policy cannot steer this prompt toward a goal, whatever the reward.
    """
    from latentrl.evaluation import metrics as M

    g = torch.Generator().manual_seed(seed)
    state = model.initial_state(batch, g, seed_index=torch.zeros(batch, dtype=torch.long))
    emb = model.encode_text([text] * batch)
    for _ in range(2):
        shared = torch.randn(1, *model.latent_shape, generator=g).expand(batch, *model.latent_shape)
        state = model.rollout_step(state, emb, shared.contiguous().to(model.device), guidance).state
    roll = model.rollout(text, steps, batch=batch, generator=g, guidance_scale=guidance, state=state)
    yaw = M.heading_change_rad(roll.joints_world[:, 1:]) * 180 / math.pi
    lo, hi = torch.quantile(yaw.float().cpu(), torch.tensor([0.05, 0.95])).tolist()
    return hi - lo


def bench_motion(args: MotionBenchRequest) -> int:
    """Rollout stability and text control of a motion model, against its training data."""
    from latentrl.evaluation import metrics as M
    from latentrl.motion.checkpoint import load_motion_model

    model = load_motion_model(args.motion)
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
        f"{'turn deg/s':>10} {'L-only':>6} {'R-only':>6} {'steer deg':>9}"
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
        }
        if ref and skill in ref["skills"]:
            row["data"] = ref["skills"][skill]
        out["probes"][text] = row
        print(
            f"{text:>18} {row['speed_m_s']:9.2f} {row['skate_cm_s']:10.2f} {row['floor_cm']:8.2f} "
            f"{row['pelvis_z_min']:6.2f}-{row['pelvis_z_max']:<6.2f} {row['turn_deg_s']:10.1f} "
            f"{row['left_only']:6.2f} {row['right_only']:6.2f} {row['steer_spread_deg']:9.1f}"
        )
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
    if ref and "walk" in ref["skills"]:
        data_walk = ref["skills"]["walk"]
        checks["walk skate within 1.5x of data"] = p["walk"]["skate_cm_s"] <= 1.5 * max(data_walk["skate_cm_s"], 0.1)
        checks["walk floor within 1.5x of data"] = p["walk"]["floor_cm"] <= 1.5 * max(data_walk["floor_cm"], 0.1)
        out["data_reference"] = {"pelvis_z_range": ref["pelvis_z_range"],
                                 "pelvis_over_feet_range": ref["pelvis_over_feet_range"], "walk": data_walk}
    train_s = model.info.get("train_seconds")
    if train_s is not None:
        out["train_seconds"] = train_s
        checks["training <= 20 min"] = train_s <= 1200
    out["checks"] = checks
    for name, ok in checks.items():
        print(f"[{'pass' if ok else 'FAIL'}] {name}")
    write_json(args.json, out)
    return 0
