"""Probe closed-loop refinement (latentrl.optim.refine) on a joint-goal suite, with or without a policy.

    python tools/refine_probe.py SUITE [--policy FILE] [--steps 12] [--horizon 3] [--skate 0] [--pace 0.5]
                                 [--land 0] [--episodes 8] [--entries 0,5] [--detail]

SUITE is a joint-goal file or a shipped suite name (pelvis_near, pelvis_far, stepping_stones, hands_walk).
Without --policy every step starts from zero noise (the foot lock on, as the shipped policies train), which
separates what the refiner does from what the policy adds; ``latentrl eval POLICY --refine`` is the product
path. Prints one line of mean metrics per entry (deterministic actions, seed 0).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from latentrl.envs.reach_joint import load_joint_goals
from latentrl.evaluation import joint_goals
from latentrl.evaluation.config import EvalSettings
from latentrl.evaluation.runner import policy_fn
from latentrl.evaluation.trained import stored_env
from latentrl.motion.checkpoint import load_motion_model
from latentrl.optim.refine import RefineSettings, refining
from latentrl.ppo import load_policy
from latentrl.resources import suites_folder

KEYS = ("err_near_cm", "err_far_cm", "footstep_err_cm", "steps_reached", "reached", "success", "skate_cm_s")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("suite")
    ap.add_argument("--policy", help="a ReachJoint policy file (default: zero noise every step)")
    ap.add_argument("--steps", type=int, default=12, help="refinement steps per env step (0: none)")
    ap.add_argument("--horizon", type=int, default=3)
    ap.add_argument("--skate", type=float, default=0.0)
    ap.add_argument("--pace", type=float, default=0.5)
    ap.add_argument("--land", type=int, default=0, help="frames a footstep's foot is held down (RefineSettings.land)")
    ap.add_argument("--episodes", type=int, default=8)
    ap.add_argument("--detail", action="store_true", help="per goal: touchdown error and misses")
    ap.add_argument("--entries", help="comma-separated entry indices (default: all)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    file = args.suite if args.suite.endswith(".json") else suites_folder("joint_goals") / f"{args.suite}.json"
    entries = load_joint_goals(file)
    model = load_motion_model("default")
    settings = EvalSettings(episodes=args.episodes, max_steps=128, deterministic=True, seed=0)
    if args.policy:
        settings.take_training_env(stored_env(args.policy))
        act = policy_fn(load_policy(args.policy, "cpu").policy, deterministic=True)
    else:
        settings.foot_lock = True
        act = lambda obs: torch.zeros(obs.shape[0], model.latent_dim)  # noqa: E731
    refine = RefineSettings(steps=args.steps, horizon=args.horizon, skate=args.skate, pace=args.pace,
                            land=args.land)
    refine.check()
    wrap = None if args.steps == 0 else (lambda env, a: refining(env, a, refine))
    only = None if args.entries is None else {int(i) for i in args.entries.split(",")}
    for i, entry in enumerate(entries):
        if only is not None and i not in only:
            continue
        t0 = time.perf_counter()
        result = joint_goals.run_entry(act, model, entry, settings, wrap=wrap, index=i)
        means = {}
        for key in KEYS:
            values = [ep.metrics.get(key) for ep in result.episodes]
            values = [v for v in values if v is not None and v == v]
            if values:
                means[key] = round(float(np.mean(values)), 2)
        print(i, means, f"{time.perf_counter() - t0:.0f} s", flush=True)
        if args.detail:  # per goal: mean touchdown error (cm) and footsteps missed (beyond the radius or none)
            per = [ep.detail.get("touchdown_err_cm") or [] for ep in result.episodes]
            for g in range(max(map(len, per), default=0)):
                errs = [p[g] for p in per if g < len(p)]
                got = [e for e in errs if e is not None]
                at = [ep.detail["error_cm"][g] for ep in result.episodes]
                miss = [(None if e is None else round(e, 1), None if a is None else round(a, 1))
                        for e, a in zip(errs, at) if e is None or e > 10]
                print(f"  goal {g}: {np.mean(got) if got else float('nan'):.2f} cm, "
                      f"missed {len(miss)} of {len(errs)} (touchdown, goal-time error): {miss}", flush=True)


if __name__ == "__main__":
    main()
