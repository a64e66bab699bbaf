"""Seconds per env step of one ReachJoint character with its noise refined: the cost side of ``--refine STEPS``.

    python tools/refine_cost.py [--settings 0:3 3:3 4:2 8:3 16:3] [--steps-per-run 12] [--skate 0] [--pace 0.5]

Runs the shipped ``reach_joint_default`` (mean action) on ``pelvis_far``'s first entry, one env, for each
``STEPS:HORIZON`` pair, and prints the mean wall time of policy + refinement + env step over the steps after the
first two (a primitive is 0.267 s of motion: below that, refinement keeps up in real time). One torch thread.
Quality at the same settings: ``tools/refine_probe.py SUITE --policy policies/reach_joint_default.pt --steps S``.
"""

from __future__ import annotations

import argparse
import time

import torch

from latentrl.envs.reach_joint import load_joint_goals
from latentrl.evaluation import joint_goals
from latentrl.evaluation.config import EvalSettings
from latentrl.evaluation.runner import policy_fn
from latentrl.evaluation.trained import stored_env
from latentrl.motion.checkpoint import load_motion_model
from latentrl.motion.representation import FUTURE_LENGTH
from latentrl.motion.skeleton import FPS
from latentrl.optim.refine import RefineSettings, refine
from latentrl.ppo import load_policy
from latentrl.resources import policy_file, suites_folder


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--settings", nargs="+", default=["0:3", "3:3", "4:2", "8:3", "16:3"], metavar="STEPS:HORIZON")
    ap.add_argument("--steps-per-run", type=int, default=12)
    ap.add_argument("--skate", type=float, default=0.0, help="the refiner's skate weight (the shipped policy: 3)")
    ap.add_argument("--pace", type=float, default=0.5, help="the refiner's pace weight (the shipped policy: 2)")
    args = ap.parse_args()
    torch.set_num_threads(1)
    policy = str(policy_file("reach_joint_default"))
    entry = load_joint_goals(suites_folder("joint_goals") / "pelvis_far.json")[0]
    model = load_motion_model("default")
    settings = EvalSettings(episodes=1, max_steps=64, deterministic=True, seed=0)
    settings.take_training_env(stored_env(policy))
    act = policy_fn(load_policy(policy, "cpu").policy, deterministic=True)
    for pair in args.settings:
        steps, horizon = (int(v) for v in pair.split(":"))
        env = joint_goals.make_env(model, entry, 1, settings, max_steps=64)
        obs, _ = env.reset(seed=0)
        refined = RefineSettings(steps=steps, horizon=horizon, skate=args.skate, pace=args.pace)
        times = []
        for _ in range(args.steps_per_run):
            t0 = time.perf_counter()
            action = act(obs)
            if steps:
                action = refine(env, action, refined)
            obs, *_ = env.step(action)
            times.append(time.perf_counter() - t0)
        mean = sum(times[2:]) / len(times[2:])
        print(f"steps {steps} horizon {horizon}: {mean:.3f} s per env step "
              f"({mean / (FUTURE_LENGTH / FPS):.2f}x the 0.267 s of motion it makes)", flush=True)


if __name__ == "__main__":
    main()
