"""What routes cost: planning one route, and a step of training envs among random obstacles with and without them.

    python tools/route_cost.py [--scenes 16] [--envs 128] [--steps 32] [--clearance 0.5]

Plans a route (``latentrl.scenes.route.RouteMap``) in each of ``--scenes`` random-obstacle scenes (the shipped
obstacle config's: 3-8 boxes and pillars; goals 4 m ahead, spread 4 m across) and prints the mean time per plan and
per carrot query; then steps a ``ReachLocationEnv`` of ``--envs`` envs among those obstacles ``--steps`` times with
random actions, without and with ``route`` (same seed), and prints the seconds per step and the routes planned.
Timings are of this machine: compare the two lines of one run, not runs on different machines.
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import torch

from latentrl.envs.reach import ReachLocationEnv
from latentrl.motion.checkpoint import load_motion_model
from latentrl.scenes.random import RandomObstacles
from latentrl.scenes.route import RouteMap, RouteSettings

OBSTACLES = {"count": [3, 8], "size": [0.3, 1.0], "height": [0.5, 1.5], "distance": [1.0, 5.0], "angle_deg": 90,
             "cylinder_share": 0.5, "clearance": 0.5}
"""The random obstacles of configs/policies/reach_obstacles_default.yaml."""


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--scenes", type=int, default=16)
    ap.add_argument("--envs", type=int, default=128)
    ap.add_argument("--steps", type=int, default=32)
    ap.add_argument("--clearance", type=float, default=0.5)
    args = ap.parse_args()
    torch.set_num_threads(1)
    n = args.scenes
    goal = torch.zeros(n, 3)
    goal[:, 0], goal[:, 1] = torch.linspace(-2.0, 2.0, n), 4.0
    forward = torch.tensor([[0.0, 1.0, 0.0]]).repeat(n, 1)
    scenes = RandomObstacles.of(OBSTACLES).sample(torch.zeros(n, 3), forward, goal, torch.Generator().manual_seed(0),
                                                  0.0)
    settings = RouteSettings(clearance=args.clearance)
    t0 = time.perf_counter()
    maps = [RouteMap(scenes.index(slice(i, i + 1)), (0.0, 0.0), goal[i, :2].numpy(), settings) for i in range(n)]
    t1 = time.perf_counter()
    for m in maps:
        for y in np.linspace(0.0, 2.0, 10):
            m.carrot((0.0, y))
    t2 = time.perf_counter()
    print(f"plan: {(t1 - t0) / n * 1e3:.1f} ms per route ({n} scenes); carrot: {(t2 - t1) / (10 * n) * 1e3:.2f} ms "
          f"per query")
    model = load_motion_model("default")
    for route in (None, args.clearance):
        env = ReachLocationEnv(args.envs, motion=model, texts=["walk"], scene={"random_obstacles": OBSTACLES},
                               route=route, max_episode_steps=32, random_initial_steps=True)
        env.reset(seed=0)
        g = torch.Generator().manual_seed(0)
        t0 = time.perf_counter()
        for _ in range(args.steps):
            env.step(torch.randn(args.envs, model.latent_dim, generator=g))
        dt = (time.perf_counter() - t0) / args.steps
        planned = env.guide.plans if env.guide is not None else 0
        print(f"env step, {args.envs} envs, route {route}: {dt:.3f} s ({planned} routes planned in {args.steps} steps)")


if __name__ == "__main__":
    main()
