"""Seconds per env step of one character with the scene filter on: the cost side of ``latentrl eval --avoid``.

    python tools/avoid_cost.py [--policy path_maze_default] [--paths maze] [--path 2] [--steps 0 8 16] [--horizon 2]
                               [--samples 0]

Runs the policy (mean action) on one path of the suite, one env, once per ``--steps`` value, and prints the mean
wall time of policy + filter + env step over the whole route, the share of steps at which the filter acted and
the mean time of those steps (a primitive is 0.267 s of motion: below that, one character keeps up in real
time). ``--samples K`` (``latentrl eval --avoid-samples``) tries K draws of the stochastic policy before the
optimizer, and also prints the share of acting steps that needed the optimizer. One torch thread.
"""

from __future__ import annotations

import argparse
import time

import torch

from latentrl.envs.path import load_paths
from latentrl.evaluation.config import EvalSettings
from latentrl.evaluation.runner import make_env, policy_fn
from latentrl.evaluation.trained import stored_env
from latentrl.motion.checkpoint import load_motion_model
from latentrl.optim import avoid as avoid_module
from latentrl.optim.avoid import AvoidSettings, avoid, draws
from latentrl.ppo import load_policy
from latentrl.resources import policy_file, suites_folder


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--policy", default="path_maze_default")
    ap.add_argument("--paths", default="maze")
    ap.add_argument("--path", type=int, default=2, help="index of the path in the suite (maze: 2 is maze_c)")
    ap.add_argument("--steps", type=int, nargs="+", default=[0, 8, 16])
    ap.add_argument("--horizon", type=int, default=2)
    ap.add_argument("--samples", type=int, nargs="+", default=[0])
    ap.add_argument("--max-steps", type=int, default=160)
    args = ap.parse_args()
    torch.set_num_threads(1)
    file = str(policy_file(args.policy))
    model = load_motion_model("default")
    policy = load_policy(file, "cpu").policy
    act, sample = policy_fn(policy, deterministic=True), policy_fn(policy, deterministic=False)
    path = load_paths(suites_folder("paths") / f"{args.paths}.json")[args.path]
    settings = EvalSettings(episodes=1, max_steps=args.max_steps, deterministic=True, seed=0)
    settings.take_training_env(stored_env(file))
    adam_steps = {"n": 0}
    original_adam = avoid_module.torch.optim.Adam

    def counting_adam(*a, **k):  # one Adam per step that needed the optimizer
        adam_steps["n"] += 1
        return original_adam(*a, **k)

    avoid_module.torch.optim.Adam = counting_adam
    for steps in args.steps:
        for samples in args.samples:
            torch.manual_seed(0)
            env = make_env(model, [path], 1, settings, observe_next=True)
            obs, _ = env.reset(seed=0)
            cfg, times, acted, optimized = AvoidSettings(steps=steps, horizon=args.horizon, samples=samples), [], [], []
            adam_steps["n"] = 0
            for _ in range(args.max_steps):
                t0 = time.perf_counter()
                with torch.no_grad():
                    given = act(obs)
                before = adam_steps["n"]
                action = avoid(env, given, cfg, draws(sample, obs))
                optimized.append(adam_steps["n"] > before)
                obs, _, terminated, truncated, _ = env.step(action)
                times.append(time.perf_counter() - t0)
                acted.append(action is not given)
                if bool(terminated.any() or truncated.any()):
                    break
            hit = [t for t, a in zip(times, acted) if a]
            drawn = [t for t, a, o in zip(times, acted, optimized) if a and not o]
            print(f"--avoid {steps:3d} --avoid-horizon {args.horizon} --avoid-samples {samples:3d}: "
                  f"{1e3 * sum(times) / len(times):7.1f} ms per step over {len(times)} steps, filter acted at "
                  f"{100 * len(hit) / len(times):4.1f} % of them"
                  + (f" ({1e3 * sum(hit) / len(hit):.0f} ms each, the optimizer at {adam_steps['n']} of them"
                     if hit else "")
                  + (f"; a step taken from the draws {1e3 * sum(drawn) / len(drawn):.0f} ms" if drawn else "")
                  + (")" if hit else ""), flush=True)


if __name__ == "__main__":
    main()
