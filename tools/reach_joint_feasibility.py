"""How close can the latent noise bring the pelvis to ReachJoint's near goals at all (docs/joint_goals.md)?

Two probes, so that a policy's error can be read against what the latent noise can reach:

- ``near``: from the states of a ReachJointEnv whose random goals are all near (within one step), try K random
  noises for the next primitive (the first is zero) and report, by lead time, the zero-noise, median and best
  error at the goal frame. The states come from stepping the env with random noise, so runs of near goals are
  not followed; read the first goals of runs (``--near-run 1 1``) for the path sampler.
- ``suite``: optimize the whole noise sequence of each entry of a joint-goal suite (``latentrl optimize``'s
  solver, pelvis xy at each goal frame, from seed histories), then replay the noises through ReachJointEnv with
  and without the foot lock and score them as the env does.

    python tools/reach_joint_feasibility.py near --samples 256 --near-run 1 1
    python tools/reach_joint_feasibility.py suite --suite pelvis_near --seeds 0 --steps 200
"""

from __future__ import annotations

import argparse
import json
import math
import tempfile
import time
from pathlib import Path

import numpy as np
import torch


def _repeat(state, row: int, k: int):
    from latentrl.motion.rollout import RolloutState

    idx = torch.full((k,), row, dtype=torch.long)
    return RolloutState(state.history[idx], state.world.index(idx), state.airborne_flags()[idx])


def near(args: argparse.Namespace) -> None:
    """Best of K noises for the next primitive, against the env's own near goals."""
    from latentrl.envs.reach_joint import ReachJointEnv, joint_error

    gen = torch.Generator().manual_seed(args.seed)
    runs = {} if args.near_run is None else {"near_run": tuple(args.near_run)}  # None: the sampler's default
    env = ReachJointEnv(args.envs, motion=args.motion, texts=("walk",), foot_lock=True, near_share=1.0,
                        planar=("pelvis",), max_episode_steps=64, **runs)
    env.reset(seed=args.seed)
    emb = env.text_table.embeddings[env._text_idx[:1]]
    rows = []
    t0 = time.perf_counter()
    with torch.no_grad():
        for _ in range(args.rounds):
            state, goal, now = env._state, env.current_goal(), env._now_frame()
            for i in range(env.num_envs):
                z = torch.randn(args.samples, env.motion.latent_dim, generator=gen).clamp(-4, 4)
                z[0] = 0.0
                out = env.motion.rollout_step(_repeat(state, i, args.samples), emb.expand(args.samples, -1),
                                              z.view(args.samples, *env.motion.latent_shape), env.guidance_scale,
                                              foot_lock=True, lock_min_weight=env.foot_lock_min_weight)
                lead = int(goal["frame"][i] - now[i])
                at = out.joints_world[:, lead - 1, goal["joint"][i]]
                err = joint_error(at, goal["target"][i].expand(args.samples, 3), goal["planar"][i].expand(args.samples))
                rows.append((lead, float(err[0]), float(err.median()), float(err.min())))
            env.step(torch.randn(env.num_envs, env.motion.latent_dim, generator=gen) * 0.8)
    a = np.asarray(rows)
    print(f"{len(a)} near goals, {args.samples} noises each, near_run {args.near_run}, "
          f"{time.perf_counter() - t0:.0f} s")
    print("lead (frames) | goals | zero noise | median | best | best within 0.1 m")
    for lo, hi in ((1, 2), (3, 5), (6, 8), (1, 8)):
        m = (a[:, 0] >= lo) & (a[:, 0] <= hi)
        print(f"{lo}-{hi} | {int(m.sum())} | {a[m, 1].mean() * 100:.1f} cm | {a[m, 2].mean() * 100:.1f} cm | "
              f"{a[m, 3].mean() * 100:.1f} cm | {np.mean(a[m, 3] < 0.1):.2f}")


def suite(args: argparse.Namespace) -> None:
    """Offline optimum of a suite's entries, replayed through the env with and without the foot lock."""
    from latentrl.envs.reach_joint import ReachJointEnv, goal_frame, load_joint_goals
    from latentrl.motion.checkpoint import load_motion_model
    from latentrl.optim import OptimizeSettings, load_suite, optimize
    from latentrl.resources import task_file

    entries = load_joint_goals(task_file(args.suite, "joint_goals") or args.suite)
    problems = []
    for e, entry in enumerate(entries):
        frames = [goal_frame(g.time) for g in entry.goals]
        for s in args.seeds:  # env frame m is the optimizer's frame m - 1 (its frame 0 is the first generated)
            problems.append({"name": f"e{e}_s{s}", "start": {"seed": s}, "text": entry.text,
                             "primitives": math.ceil(frames[-1] / 8),
                             "constraints": [{"type": "joint", "frame": f - 1, "joint": "pelvis", "axes": "xy",
                                              "position": [g.target[0], g.target[1], 0.0]}
                                             for g, f in zip(entry.goals, frames)]})
    model = load_motion_model(args.motion)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "suite.json"
        path.write_text(json.dumps({"format": "latentrl.constraints/1", "problems": problems}))
        t0 = time.perf_counter()
        results = optimize(model, load_suite(path), OptimizeSettings(steps=args.steps, batch=16, seed=args.seed))
    print(f"{len(results)} problems, {args.steps} steps, {time.perf_counter() - t0:.0f} s")
    print("problem | optimizer (cm) | replayed, no foot lock (cm) | replayed, foot lock (cm)")
    for r in results:
        e, s = (int(v) for v in r.problem.name[1:].split("_s"))
        replayed = []
        for lock in (False, True):
            env = ReachJointEnv(1, motion=model, goals=[entries[e]], foot_lock=lock, autoreset_mode="Disabled",
                                max_episode_steps=len(r.noise))
            env.reset(seed=0)
            env._state = model.initial_state(1, seed_index=torch.tensor([s]))
            for k in range(len(r.noise)):
                env.step(torch.as_tensor(r.noise[k:k + 1]))
            record, _ = env.goal_record()
            replayed.append(float(np.nanmean(record.numpy())) * 100)
        print(f"{r.problem.name} | {r.metrics['goal_error_cm']:.2f} | {replayed[0]:.2f} | {replayed[1]:.1f}")


def main(argv: list[str] | None = None) -> None:
    """Command line: ``near`` or ``suite`` (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("probe", choices=("near", "suite"))
    parser.add_argument("--motion", default="default")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--samples", type=int, default=256, help="near: noises tried per goal")
    parser.add_argument("--envs", type=int, default=16, help="near: envs (states) per round")
    parser.add_argument("--rounds", type=int, default=6, help="near: steps of states")
    parser.add_argument("--near-run", type=int, nargs=2, default=None, help="near: env.reach_joint.near_run")
    parser.add_argument("--suite", default="pelvis_near", help="suite: a joint-goal suite or file")
    parser.add_argument("--seeds", type=int, nargs="+", default=[0], help="suite: seed histories")
    parser.add_argument("--steps", type=int, default=200, help="suite: optimizer steps")
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    (near if args.probe == "near" else suite)(args)


if __name__ == "__main__":
    main()
