"""``latentrl bench motion``: stability and text control of a motion model vs. its training data."""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from latentrl.app.bench.common import write_json
from latentrl.constants import GUIDANCE_SCALE
from latentrl.motion.representation import FUTURE_LENGTH, HISTORY_LENGTH
from latentrl.motion.skeleton import FPS
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
    no_floor_snap: bool = False
    snap_ramp: bool = False
    foot_lock: bool = False
    no_skills: bool = False


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
    stats["transitions"] = _data_transitions(seqs)
    stats["pelvis_z_range"] = [min(pelvis_z), max(pelvis_z)]
    stats["pelvis_over_feet_range"] = [float(min(b.min() for b in body)), float(max(b.max() for b in body))]
    return stats


def _data_transitions(seqs: list[dict]) -> dict:
    """The data's transition figures: mean jerk (AUJ's reference), PJ/AUJ at its text splits, seam ratios.

    The seam ratios cut each sequence on the rollout's grid (2 frames, then 8 per primitive). The data has no
    primitives: its pelvis scores about 1, what a model without pops scores; its planted feet hardly move at all
    (hundredths of a millimetre a frame), so its step ratio is the noise of two near-zero means.
    """
    from latentrl.evaluation import metrics as M

    clips = torch.cat([M.transition_clips(torch.as_tensor(s["joints"], dtype=torch.float32)[None],
                                          [int(x) for x in s["seg_start"][1:]]) for s in seqs])
    reference = float(M.transition_jerk_curve(clips).mean())
    frames = min(len(s["joints"]) for s in seqs)  # pooled over every sequence, cut to the shortest
    seams = M.seam_ratios(torch.stack([torch.as_tensor(s["joints"][:frames], dtype=torch.float32) for s in seqs]))
    return {"jerk_reference": reference, "text_pj": M.peak_jerk(clips),
            "text_auj": M.area_under_jerk(clips, reference), "text_splits": int(clips.shape[0]),
            "step_boundary_cm": seams["step_boundary_cm"], "step_inside_cm": seams["step_inside_cm"],
            "step_ratio": seams["step_ratio"], "pelvis_acc_ratio": seams["pelvis_acc_ratio"]}


def transition_figures(joints: torch.Tensor, splits: list[int], jerk_reference: float | None) -> dict:
    """PJ and AUJ (None without a data reference) over the 30-frame clips centred on ``splits`` of (B, T, 22, 3)."""
    from latentrl.evaluation import metrics as M

    clips = M.transition_clips(joints, splits)
    if clips.shape[0] == 0:
        return {"pj": None, "auj": None, "clips": 0}
    return {"pj": M.peak_jerk(clips),
            "auj": None if jerk_reference is None else M.area_under_jerk(clips, jerk_reference),
            "clips": int(clips.shape[0])}


def _pelvis_over_feet(joints: torch.Tensor) -> torch.Tensor:
    """(..., T, 22, 3) -> (..., T) pelvis height above the lower foot joint, metres.

    The body's own height, independent of where the floor drifted to.
    """
    from latentrl.motion.skeleton import FOOT_JOINTS

    return joints[..., 0, 2] - joints[..., list(FOOT_JOINTS), 2].amin(dim=-1)


def steering_spread_deg(model, text: str, batch: int = 64, steps: int = 4, seed: int = 0,
                        guidance: float = GUIDANCE_SCALE, action_box: float | None = None) -> float:
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


def skill_switch_seconds(model, batch: int = 8, seed: int = 0, guidance: float = GUIDANCE_SCALE,
                         jerk_reference: float | None = None) -> dict:
    """Roll ``SWITCH_TIMELINE`` out; per switch, seconds until the new skill's signature holds.

    Latency is from the text change to the start of the first 0.5 s window that moves like the new
    text (run: speed > 2 m/s; hop on left leg: left foot alone >= 50 % of frames, right alone <= 10 %;
    walk: 0.5-2 m/s with each foot alone >= 15 %); ``inf`` where it never does. Also the lowest joint's
    worst depth below the floor over the whole timeline, and DART's PJ/AUJ over the text changes
    (``text_transitions``; AUJ against ``jerk_reference``, the data's mean transition jerk).
    """
    from latentrl.evaluation import metrics as M

    texts, starts = [], []
    for text, seconds in SWITCH_TIMELINE:
        starts.append(len(texts))
        texts += [text] * max(1, round(seconds * FPS / FUTURE_LENGTH))
    g = torch.Generator().manual_seed(seed)
    roll = model.rollout(texts, len(texts), batch=batch, generator=g, guidance_scale=guidance)
    j = roll.joints_world[:, 2:]
    out = {"switches": []}
    for k in range(1, len(SWITCH_TIMELINE)):
        text, first = SWITCH_TIMELINE[k][0], starts[k] * FUTURE_LENGTH
        last = (starts[k + 1] * FUTURE_LENGTH if k + 1 < len(starts) else j.shape[1]) - _SWITCH_WINDOW
        latency = torch.full((batch,), math.inf)
        for f in range(last, first - 1, -1):  # backwards: the earliest matching window wins
            hit = _skill_signature(text, j[:, f:f + _SWITCH_WINDOW])
            latency = torch.where(hit, torch.tensor((f - first) / FPS), latency)
        out["switches"].append({
            "to": text,
            "median_s": float(latency.median()),
            "within_1s": float((latency <= 1.0).float().mean()),
        })
    splits = [HISTORY_LENGTH + start * FUTURE_LENGTH for start in starts[1:]]
    out["text_transitions"] = transition_figures(roll.joints_world, splits, jerk_reference)
    out["deepest_below_floor_cm"] = float((-j[..., 2].amin(dim=-1)).clamp(min=0).max()) * 100
    out["penetration_cm"] = float(M.lowest_joint_penetration_cm(j).mean())
    return out


#: Steering-spread floors (degrees over 32 frames) of the default-model targets.
STEER_FLOOR_DEG = {"walk": 35.0, "run": 30.0, "hop on left leg": 25.0, "hop on right leg": 25.0}
#: Floor-distance ceilings (cm) and skate ceilings (cm/s) of the default-model targets.
FLOOR_MAX_CM = {"walk": 3.0, "run": 3.0, "stand still": 3.0, "hop on left leg": 5.0, "hop on right leg": 5.0,
                "jump forward": 5.0}
SKATE_MAX_CM_S = {"walk": 2.0, "run": 3.0, "hop on left leg": 3.0, "hop on right leg": 3.0}
#: Ceiling of the boundary/inside ratios of the planted-foot step and the pelvis acceleration (no pops).
SEAM_RATIO_MAX = 1.5


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
    for key, what in (("step_ratio", "planted-foot step"), ("pelvis_acc_ratio", "pelvis acceleration")):
        high = [t for t, r in p.items() if not r["seams"][key] <= SEAM_RATIO_MAX]  # NaN (no planted foot) fails too
        checks[f"{what} at primitive boundaries <= {SEAM_RATIO_MAX:g}x elsewhere, every prompt"
               + (f" (over: {', '.join(high)})" if high else "")] = not high
    checks["walk -> run -> hop -> walk: each switch within 1 s in >= 75% of rollouts, on the floor"] = (
        all(x["within_1s"] >= 0.75 for x in switch["switches"]) and switch["deepest_below_floor_cm"] <= 1.0)
    return checks


# --------------------------------------------------------------------------- scene skills
#: Skill checks: name -> prompt(s) rolled out from the standing seed (each runs only where the model knows them).
SKILL_PROMPTS = {
    "crouch": ("crouch",),
    "sit": ("sit down",),
    "stairs": ("walk up stairs", "walk down stairs"),
    "reach": ("reach with the left hand", "reach with the right hand"),
    "wave": ("wave",),
}
SKILL_SECONDS = {"crouch": 2.0, "sit": 2.5, "stairs": 5.0, "reach": 2.0, "wave": 3.0}
"""Rollout length per skill: the data's posture changes take 0.6-1.4 s, then a 0.5 s hold; six steps of stairs."""
SEAT_HEIGHTS_M = (0.2, 0.6)
"""Seat heights of the sit check: spread evenly over the data's range, one per rollout."""
REACH_FRACTIONS = (0.7, 0.85)
"""Reach targets at these shares of the arm's length (the data draws 0.6-0.95), each hand and direction."""
REACH_SAMPLES = 64
"""Noises tried per reach target; the best one counts (the target is met by noise choice)."""
SKILL_SHARE_MIN = {"sit": 0.95, "reach": 0.90, "wave": 0.90}
"""Least share of rollouts (targets for reach) that must pass."""
NOT_IN_MODEL = "prompt not in the model"


def prompt_known(model, text: str) -> bool:
    """Whether ``text`` is in the model's prompt table (a fallback encoder's guess does not count)."""
    from latentrl.motion.text import normalize_prompt

    table = getattr(model.text_encoder, "table", None)
    return table is not None and normalize_prompt(text) in table


def _standing_rollout(model, text: str, seconds: float, batch: int, seed: int, guidance: float):
    """``text`` rolled out from seed history 0 (a standing frame) for every row: (B, T, 22, 3) world joints."""
    g = torch.Generator().manual_seed(seed)
    state = model.initial_state(batch, g, seed_index=torch.zeros(batch, dtype=torch.long))
    steps = max(1, round(seconds * FPS / FUTURE_LENGTH))
    return model.rollout(text, steps, batch=batch, generator=g, guidance_scale=guidance, state=state).joints_world


def skill_figures(model, batch: int = 8, seed: int = 0, guidance: float = GUIDANCE_SCALE,
                  reach_samples: int = REACH_SAMPLES) -> dict[str, dict]:
    """The scene skills' checks (``evaluation/skill_checks.py``) on rollouts from the standing seed.

    One row per skill of ``SKILL_PROMPTS``: its figures and ``ok`` against the target, or ``status``
    ``NOT_IN_MODEL`` (no ``ok``) where the model's prompt table lacks one of its prompts. Scenes are placed
    from the seed's standing frame the way the data places them. Stairs roll out with the floor snap and the
    foot lock off (neither knows the terrain).
    """
    from latentrl.datasets.locomotion.skills import REACH_DIRECTIONS
    from latentrl.evaluation import skill_checks as S

    rows: dict[str, dict] = {}
    for name, prompts in SKILL_PROMPTS.items():
        missing = [p for p in prompts if not prompt_known(model, p)]
        if missing:
            rows[name] = {"prompts": list(prompts), "status": NOT_IN_MODEL, "missing": missing}
            continue
        seconds = SKILL_SECONDS[name]
        row: dict = {"prompts": list(prompts)}
        if name == "crouch":
            j = _standing_rollout(model, "crouch", seconds, batch, seed, guidance)
            depth = S.crouch_depth(j)  # the first (seed) frame is the standing height
            row.update(depth_m=float(depth.mean()), depth_min_m=float(depth.min()))
            row["ok"] = row["depth_m"] >= S.CROUCH_MIN_DROP_M
        elif name == "sit":
            j = _standing_rollout(model, "sit down", seconds, batch, seed, guidance)
            heights = torch.linspace(*SEAT_HEIGHTS_M, batch) if batch > 1 else torch.tensor([0.4])
            seats = torch.stack([S.seat_behind(j[i, 1], float(h)) for i, h in enumerate(heights)])
            res = S.sit_check(j, seats)
            row.update(seated=float(res["seated"].float().mean()), height_err_m=float(res["height_err_m"].mean()),
                       xy_err_m=float(res["xy_err_m"].mean()), seat_heights_m=[float(h) for h in heights])
            row["ok"] = row["seated"] >= SKILL_SHARE_MIN["sit"]
        elif name == "stairs":
            snap, lock = model.floor_snap, model.foot_lock
            model.floor_snap, model.foot_lock = None, False
            try:
                for prompt, up in zip(prompts, (True, False)):
                    j = _standing_rollout(model, prompt, seconds, batch, seed, guidance)
                    res = [S.stair_check(j[i, 2:], S.stairs_ahead(j[i, 1], up=up)) for i in range(batch)]
                    key = "up" if up else "down"
                    row[key] = {"penetration_m": sum(float(r["penetration_m"]) for r in res) / batch,
                                "float_m": sum(float(r["float_m"]) for r in res) / batch,
                                "planted": int(sum(int(r["planted"]) for r in res))}
            finally:
                model.floor_snap, model.foot_lock = snap, lock
            row["ok"] = all(row[k]["penetration_m"] <= S.STAIR_PENETRATION_TOL_M
                            and row[k]["float_m"] <= S.STAIR_FLOAT_TOL_M and row[k]["planted"] > 0
                            for k in ("up", "down"))
        elif name == "reach":
            best = []
            for hand, prompt in enumerate(prompts):
                j = _standing_rollout(model, prompt, seconds, reach_samples, seed, guidance)
                for direction in REACH_DIRECTIONS:
                    for fraction in REACH_FRACTIONS:
                        target = S.reach_target(j[0, 1], hand, direction, fraction)
                        best.append(float(S.reach_check(j, target.expand(reach_samples, 3), hand)["distance_m"].min()))
            row.update(targets=len(best), samples=reach_samples, best_distance_m=best,
                       reached=sum(d <= S.REACH_TOL_M for d in best) / len(best))
            row["ok"] = row["reached"] >= SKILL_SHARE_MIN["reach"]
        elif name == "wave":
            j = _standing_rollout(model, "wave", seconds, batch, seed, guidance)[:, 2:]
            res = [S.wave_check(j, hand) for hand in (0, 1)]
            right = res[1]["raised"] > res[0]["raised"]  # the hand raised longer is the waving one
            raised = torch.where(right, res[1]["raised"], res[0]["raised"])
            swings = torch.where(right, res[1]["swings_hz"], res[0]["swings_hz"])
            lo, hi = S.WAVE_SWING_HZ
            waving = (raised >= S.WAVE_MIN_RAISED) & (swings >= lo) & (swings <= hi)
            row.update(raised=float(raised.mean()), swings_hz=float(swings.mean()), waving=float(waving.float().mean()))
            row["ok"] = row["waving"] >= SKILL_SHARE_MIN["wave"]
        rows[name] = row
    return rows


def _skill_summary(name: str, row: dict) -> str:
    """One line of a skill row's figures (or why it did not run)."""
    if "status" in row:
        return f"{row['status']} ({', '.join(repr(p) for p in row['missing'])})"
    if name == "crouch":
        return f"pelvis drop {row['depth_m'] * 100:.1f} cm (lowest {row['depth_min_m'] * 100:.1f})"
    if name == "sit":
        return (f"seated {row['seated']:.0%}, pelvis height error {row['height_err_m'] * 100:.1f} cm, "
                f"xy {row['xy_err_m'] * 100:.1f} cm")
    if name == "stairs":
        return ", ".join(f"{k}: penetration {row[k]['penetration_m'] * 100:.2f} cm, "
                         f"float {row[k]['float_m'] * 100:.2f} cm ({row[k]['planted']} planted foot-frames)"
                         for k in ("up", "down"))
    if name == "reach":
        return f"{row['reached']:.0%} of {row['targets']} targets within 10 cm (best of {row['samples']})"
    return f"waving {row['waving']:.0%}, hand up {row['raised']:.0%}, {row['swings_hz']:.1f} swings/s"


#: Check names of the skill rows (their targets, as in docs/benchmarks.md).
SKILL_CHECK_NAMES = {
    "crouch": "crouch: pelvis drop >= 25 cm",
    "sit": "sit: pelvis on a 0.2-0.6 m seat (+-5 cm height, +-10 cm xy) in >= 95% of rollouts",
    "stairs": "stairs up and down: planted-foot penetration <= 1 cm, float <= 3 cm",
    "reach": "reach: hand within 10 cm of >= 90% of targets (best of 64 noises)",
    "wave": "wave: hand up >= 20%, 1-3.5 swings/s in >= 90% of rollouts",
}


def skill_checks(rows: dict[str, dict]) -> dict[str, bool]:
    """Pass/fail of the skill rows that ran; a row whose prompt the model lacks is neither."""
    return {SKILL_CHECK_NAMES[name]: bool(row["ok"]) for name, row in rows.items() if "ok" in row}


def _fmt(x: float | None, digits: int = 3) -> str:
    return "-" if x is None else f"{x:.{digits}f}"


def _print_seams(probes: dict, ref: dict | None) -> None:
    """The primitive-boundary table: planted-foot step and pelvis acceleration ratios, PJ and AUJ."""
    print(f"{'prompt':>18} {'step at/in cm':>13} {'ratio':>5} {'pelvis acc':>10} {'PJ':>6} {'AUJ':>6}")
    for text, r in probes.items():
        s, t = r["seams"], r["primitive_transitions"]
        print(f"{text:>18} {s['step_boundary_cm']:6.2f}/{s['step_inside_cm']:<6.2f} {s['step_ratio']:5.2f} "
              f"{s['pelvis_acc_ratio']:10.2f} {_fmt(t['pj']):>6} {_fmt(t['auj']):>6}")
    if ref:
        d = ref["transitions"]
        steps = f"{d['step_boundary_cm']:.3f}/{d['step_inside_cm']:.3f}"
        print(f"{'data':>18} {steps:>13} {d['step_ratio']:5.2f} {d['pelvis_acc_ratio']:10.2f} {d['text_pj']:6.3f} "
              f"{d['text_auj']:6.3f}  (text splits; mean jerk {d['jerk_reference']:.4f} m/frame^3)", flush=True)


def bench_motion(args: MotionBenchRequest) -> int:
    """Rollout stability and text control of a motion model, against its training data."""
    from latentrl.evaluation import metrics as M
    from latentrl.motion.checkpoint import load_motion_model

    model = load_motion_model(args.motion)
    if args.no_floor_snap:
        model.floor_snap = None
    model.floor_snap_ramp = bool(args.snap_ramp)
    model.foot_lock = bool(args.foot_lock)
    steps = max(1, round(args.seconds * FPS / FUTURE_LENGTH))
    ref = _data_reference(model)
    out = {
        "benchmark": "motion",
        "hardware": hardware(),
        "motion": model.info.get("source"),
        "sha256": model.info.get("sha256"),
        "seconds": args.seconds,
        "batch": args.batch,
        "floor_snap": model.floor_snap,
        "snap_ramp": model.floor_snap_ramp,
        "foot_lock": model.foot_lock,
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
            "turn_deg_s": float(M.heading_change_rad(j).mean()) * 180 / math.pi / (j.shape[1] / FPS),
            "left_only": float(shares["left_only"].mean()),
            "right_only": float(shares["right_only"].mean()),
            "steer_spread_deg": steering_spread_deg(model, text, seed=args.seed, guidance=args.guidance),
            "steer_spread_box4_deg": steering_spread_deg(model, text, seed=args.seed, guidance=args.guidance,
                                                         action_box=4.0),
            "penetration_cm": float(M.lowest_joint_penetration_cm(j).mean()),
        }
        fwd, side = M.body_frame_velocity_m_s(j)
        row["forward_m_s"], row["rightward_m_s"] = float(fwd.mean()), float(side.mean())
        full = roll.joints_world  # seed frames included: the first decoded frame crosses a boundary too
        row["seams"] = M.seam_ratios(full)
        row["primitive_transitions"] = transition_figures(
            full, M.primitive_seams(full.shape[1]), ref["transitions"]["jerk_reference"] if ref else None)
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
    _print_seams(out["probes"], ref)
    jerk_reference = ref["transitions"]["jerk_reference"] if ref else None
    out["skill_switch"] = sw = skill_switch_seconds(model, batch=args.batch, seed=args.seed, guidance=args.guidance,
                                                    jerk_reference=jerk_reference)
    tt = sw["text_transitions"]
    print("skill switch:", ", ".join(f"->{x['to']} {x['median_s']:.2f}s ({x['within_1s']:.0%} <= 1 s)"
                                     for x in sw["switches"]),
          f"deepest below floor {sw['deepest_below_floor_cm']:.1f} cm; text transitions PJ {_fmt(tt['pj'])} "
          f"AUJ {_fmt(tt['auj'])}")
    p = out["probes"]
    if not args.no_skills:
        out["skills"] = skill_figures(model, batch=args.batch, seed=args.seed, guidance=args.guidance)
        for name, row in out["skills"].items():
            print(f"skill {name}: {_skill_summary(name, row)}", flush=True)
    checks = {
        "stable: finite, body height (pelvis over lower foot) in data range +-10 cm": all(
            r["finite"] for r in p.values())
        and (ref is None or all(ref["pelvis_over_feet_range"][0] - 0.1 <= r["pelvis_over_feet_min"]
                                and r["pelvis_over_feet_max"] <= ref["pelvis_over_feet_range"][1] + 0.1
                                for r in p.values())),
        "no vertical drift: world pelvis height in data range +-10 cm": ref is None or all(
            ref["pelvis_z_range"][0] - 0.1 <= r["pelvis_z_min"]
            and r["pelvis_z_max"] <= ref["pelvis_z_range"][1] + 0.1 for r in p.values()),
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
    checks.update(skill_checks(out.get("skills", {})))
    if ref:
        out["data_reference"] = {"pelvis_z_range": ref["pelvis_z_range"],
                                 "pelvis_over_feet_range": ref["pelvis_over_feet_range"], "skills": ref["skills"],
                                 "transitions": ref["transitions"]}
    train_s = model.info.get("train_seconds")
    if train_s is not None:
        out["train_seconds"] = train_s
        checks["training <= 2 h"] = train_s <= 7200
    out["checks"] = checks
    for name, ok in checks.items():
        print(f"[{'pass' if ok else 'FAIL'}] {name}")
    for name, row in out.get("skills", {}).items():
        if "status" in row:
            print(f"[ -- ] {SKILL_CHECK_NAMES[name]}: {row['status']}")
    write_json(args.json, out)
    return 0
