"""Seconds per env step of one character with the scene filter on: the cost side of ``latentrl eval --avoid``.

    python tools/avoid_cost.py [--policy path_maze_default] [--paths maze] [--path 2] [--steps 0 8 16] [--horizon 2]

Runs the policy (mean action) on one path of the suite, one env, once per ``--steps`` value, and prints the mean
wall time of policy + filter + env step over the whole route, the share of steps at which the filter acted and
the mean time of those steps (a primitive is 0.267 s of motion: below that, one character keeps up in real
time). One torch thread.
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
from latentrl.optim.avoid import AvoidSettings, avoid
from latentrl.ppo import load_policy
from latentrl.resources import policy_file, suites_folder


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--policy", default="path_maze_default")
    ap.add_argument("--paths", default="maze")
    ap.add_argument("--path", type=int, default=2, help="index of the path in the suite (maze: 2 is maze_c)")
    ap.add_argument("--steps", type=int, nargs="+", default=[0, 8, 16])
    ap.add_argument("--horizon", type=int, default=2)
    ap.add_argument("--max-steps", type=int, default=160)
    args = ap.parse_args()
    torch.set_num_threads(1)
    file = str(policy_file(args.policy))
    model = load_motion_model("default")
    act = policy_fn(load_policy(file, "cpu").policy, deterministic=True)
    path = load_paths(suites_folder("paths") / f"{args.paths}.json")[args.path]
    settings = EvalSettings(episodes=1, max_steps=args.max_steps, deterministic=True, seed=0)
    settings.take_training_env(stored_env(file))
    for steps in args.steps:
        env = make_env(model, [path], 1, settings, observe_next=True)
        obs, _ = env.reset(seed=0)
        cfg, times, acted = AvoidSettings(steps=steps, horizon=args.horizon), [], []
        for _ in range(args.max_steps):
            t0 = time.perf_counter()
            with torch.no_grad():
                given = act(obs)
            action = avoid(env, given, cfg)
            obs, _, terminated, truncated, _ = env.step(action)
            times.append(time.perf_counter() - t0)
            acted.append(action is not given)
            if bool(terminated.any() or truncated.any()):
                break
        hit = [t for t, a in zip(times, acted) if a]
        print(f"--avoid {steps:3d} --avoid-horizon {args.horizon}: {1e3 * sum(times) / len(times):7.1f} ms per step "
              f"over {len(times)} steps, filter acted at {100 * len(hit) / len(times):4.1f} % of them"
              + (f" ({1e3 * sum(hit) / len(hit):.0f} ms each)" if hit else ""), flush=True)


if __name__ == "__main__":
    main()
