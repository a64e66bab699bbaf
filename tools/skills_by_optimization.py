"""The motion bench's sit and reach checks with the noise chosen by optimization instead of drawn.

    python tools/skills_by_optimization.py MODEL [--skill sit|reach] [--seats 8] [--steps 100] [--samples 1]
                                           [--collision 0.1] [--floor 1] [--out FILE.json]

``latentrl bench motion`` rolls out ``sit down`` from the standing seed with N(0, I) noise and checks the pelvis
on a seat the data would put behind the body (``skill_checks.seat_behind``), heights evenly spread over
0.2-0.6 m: the model does not know the seat's height, so it sits at one by chance. DART sits by optimizing the
noise toward the seat (its scene demos); this does the same with ``latentrl.optim``: per seat one constraint
problem, ``sit down`` for the check's seconds, the pelvis over the seat point at the seated height
(``SEATED_PELVIS_ABOVE_SEAT_M`` above the top) on the last ``hold`` frames, the seat as the problem's scene
(collision weight ``--collision``; the floor regularizer ``--floor``, 1 as ``latentrl optimize``'s: the feet stay on
the floor in front of the seat). Prints the
check's share seated, the mean height and xy errors, both for the raw samples (the bench's protocol, the same
seats) and the optimized motions.

``--skill reach``: the bench's 16 hand targets (either hand; forward, up, down, to the side; 0.7 and 0.85 of the
arm's length from the shoulder, ``skill_checks.reach_target``), ``reach with the left/right hand`` for the check's
2 s, the wrist at its target at the middle frame; the check's measure (the hand's closest frame within 10 cm)
for the optimized motion against the bench's best of 64 drawn samples. MODEL: a motion model file that knows
these prompts (v5 and earlier do not). One torch thread.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import torch

from latentrl.app.bench.motion import SEAT_HEIGHTS_M, SKILL_SECONDS, _standing_rollout
from latentrl.constants import GUIDANCE_SCALE
from latentrl.evaluation import skill_checks as S
from latentrl.motion.checkpoint import load_motion_model
from latentrl.motion.representation import FUTURE_LENGTH
from latentrl.motion.skeleton import FPS, PELVIS
from latentrl.optim.problems import parse_problem
from latentrl.optim.solver import OptimizeSettings, optimize
from latentrl.safe_io import atomic_write_text


def primitives_of(seconds: float) -> int:
    """Primitives of a ``seconds``-long check, as the bench's rollout counts them."""
    return max(1, round(seconds * FPS / FUTURE_LENGTH))


def drawn(model, text: str, seconds: float, batch: int) -> torch.Tensor:
    """(B, T, 22, 3) the bench's own rollouts of ``text`` from the standing seed (seed 0, N(0, I) noise)."""
    return _standing_rollout(model, text, seconds, batch, 0, GUIDANCE_SCALE)


def problem(seat: torch.Tensor, primitives: int, hold: int, collision: float, name: str) -> dict:
    """One constraint problem (``latentrl.constraints/1``) sitting on ``seat`` (x, y, height, facing)."""
    x, y, h, facing = (float(v) for v in seat)
    target = [x, y, h + S.SEATED_PELVIS_ABOVE_SEAT_M]
    frames = primitives * FUTURE_LENGTH
    return {"name": name, "start": {"seed": 0}, "text": "sit down", "primitives": primitives,
            "scene": {"format": "latentrl.scene/1",
                      "objects": [{"type": "seat", "center": [x, y], "size": [0.5, 0.5], "seat_height": h,
                                   "yaw_deg": math.degrees(facing)}]},
            "scene_weights": {"collision": collision, "contact": 0.0},
            "constraints": [{"type": "trajectory", "frames": [frames - hold, frames - 1], "joint": "pelvis",
                             "positions": [target] * hold}]}


def reach_problem(target: torch.Tensor, hand: int, primitives: int, name: str) -> dict:
    """One constraint problem putting wrist ``hand`` (0 left, 1 right) on ``target`` at the middle frame."""
    frames = primitives * FUTURE_LENGTH
    return {"name": name, "start": {"seed": 0}, "text": f"reach with the {('left', 'right')[hand]} hand",
            "primitives": primitives,
            "constraints": [{"type": "joint", "frame": frames // 2, "joint": ("left_wrist", "right_wrist")[hand],
                             "position": [float(v) for v in target]}]}


def reach(model, args) -> dict:
    """The reach check, drawn (best of ``REACH_SAMPLES``) and optimized, per target."""
    from latentrl.app.bench.motion import REACH_FRACTIONS, REACH_SAMPLES
    from latentrl.datasets.locomotion.skills import REACH_DIRECTIONS

    primitives = primitives_of(SKILL_SECONDS["reach"])
    samples = {hand: drawn(model, f"reach with the {('left', 'right')[hand]} hand", SKILL_SECONDS["reach"],
                           REACH_SAMPLES) for hand in (0, 1)}
    jobs = [(hand, d, f) for hand in (0, 1) for d in REACH_DIRECTIONS for f in REACH_FRACTIONS]
    targets = [S.reach_target(samples[hand][0, 1], hand, d, f) for hand, d, f in jobs]  # as the bench places them
    problems = [parse_problem(reach_problem(t, hand, primitives, f"{('left', 'right')[hand]}_{d}_{f}"), "reach", i)
                for i, ((hand, d, f), t) in enumerate(zip(jobs, targets))]
    settings = OptimizeSettings(steps=args.steps, samples=args.samples, batch=len(problems))
    t0 = time.perf_counter()
    results = optimize(model, problems, settings)
    seconds = time.perf_counter() - t0
    rows = []
    for (hand, d, f), t, r in zip(jobs, targets, results):
        best = float(S.reach_check(samples[hand], t.expand(REACH_SAMPLES, 3), hand)["distance_m"].min())
        got = float(S.reach_check(torch.as_tensor(r.joints), t, hand)["distance_m"])
        rows.append({"hand": ("left", "right")[hand], "direction": d, "fraction": f,
                     "drawn_best_cm": round(100 * best, 2), "optimized_cm": round(100 * got, 2)})
        print(f"{rows[-1]['hand']:5} {d:7} {f:.2f}: best of {REACH_SAMPLES} drawn {100 * best:5.1f} cm | "
              f"optimized {100 * got:5.1f} cm", flush=True)
    tol = 100 * S.REACH_TOL_M
    return {"skill": "reach", "model": args.model, "targets": len(rows), "primitives": primitives,
            "steps": args.steps, "samples": args.samples, "seconds": round(seconds, 1),
            "drawn_reached": sum(r["drawn_best_cm"] <= tol for r in rows) / len(rows),
            "optimized_reached": sum(r["optimized_cm"] <= tol for r in rows) / len(rows),
            "optimized_mean_cm": round(sum(r["optimized_cm"] for r in rows) / len(rows), 2), "rows": rows}


def sit(model, args) -> dict:
    """The sit check on ``args.seats`` seats, drawn (the bench's rollouts) and optimized, per seat."""
    primitives = primitives_of(args.seconds)
    raw = drawn(model, "sit down", args.seconds, args.seats)
    heights = torch.linspace(*SEAT_HEIGHTS_M, args.seats)
    seats = torch.stack([S.seat_behind(raw[i, 1], float(h)) for i, h in enumerate(heights)])  # as the bench does
    raw_check = S.sit_check(raw, seats, args.hold)
    problems = [parse_problem(problem(seats[i], primitives, args.hold, args.collision, f"seat_{i}"), "sit", i)
                for i in range(args.seats)]
    settings = OptimizeSettings(steps=args.steps, samples=args.samples, batch=args.seats,
                                weights={"floor": args.floor, "skate": 1.0, "jerk": 0.0, "prior": 0.1})
    t0 = time.perf_counter()
    results = optimize(model, problems, settings)
    seconds = time.perf_counter() - t0
    joints = torch.stack([torch.as_tensor(r.joints) for r in results])
    check = S.sit_check(joints, seats, args.hold)
    rows = []
    for i, r in enumerate(results):
        rows.append({"seat_height_m": round(float(heights[i]), 3),
                     "raw": {"seated": bool(raw_check["seated"][i]),
                             "height_err_cm": round(100 * float(raw_check["height_err_m"][i]), 2),
                             "xy_err_cm": round(100 * float(raw_check["xy_err_m"][i]), 2)},
                     "optimized": {"seated": bool(check["seated"][i]),
                                   "height_err_cm": round(100 * float(check["height_err_m"][i]), 2),
                                   "xy_err_cm": round(100 * float(check["xy_err_m"][i]), 2),
                                   "pelvis_end_z_m": round(float(joints[i, -1, PELVIS, 2]), 3),
                                   **{k: v for k, v in r.metrics.items() if isinstance(v, float)}}})
        print(f"seat {float(heights[i]):.2f} m: raw seated {rows[-1]['raw']['seated']!s:5} "
              f"(height err {rows[-1]['raw']['height_err_cm']:5.1f} cm) | optimized seated "
              f"{rows[-1]['optimized']['seated']!s:5} (height err {rows[-1]['optimized']['height_err_cm']:5.1f} cm, "
              f"xy {rows[-1]['optimized']['xy_err_cm']:4.1f} cm)", flush=True)
    return {"skill": "sit", "model": args.model, "seats": args.seats, "primitives": primitives, "steps": args.steps,
            "samples": args.samples, "collision": args.collision, "floor": args.floor, "seconds": round(seconds, 1),
            "raw_seated": float(raw_check["seated"].float().mean()),
            "raw_height_err_cm": round(100 * float(raw_check["height_err_m"].mean()), 2),
            "optimized_seated": float(check["seated"].float().mean()),
            "optimized_height_err_cm": round(100 * float(check["height_err_m"].mean()), 2),
            "optimized_xy_err_cm": round(100 * float(check["xy_err_m"].mean()), 2), "rows": rows}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("model")
    ap.add_argument("--skill", choices=("sit", "reach"), default="sit")
    ap.add_argument("--seats", type=int, default=8)
    ap.add_argument("--steps", type=int, default=100)
    ap.add_argument("--samples", type=int, default=1)
    ap.add_argument("--seconds", type=float, default=SKILL_SECONDS["sit"])
    ap.add_argument("--hold", type=int, default=15)
    ap.add_argument("--collision", type=float, default=0.1)
    ap.add_argument("--floor", type=float, default=1.0)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    torch.set_num_threads(1)
    model = load_motion_model(args.model)
    summary = (reach if args.skill == "reach" else sit)(model, args)
    print(json.dumps({k: v for k, v in summary.items() if k != "rows"}), flush=True)
    if args.out:
        atomic_write_text(args.out, json.dumps(summary, indent=1))


if __name__ == "__main__":
    main()
