"""What following steps costs a scene env's step (docs/benchmarks.md, "Env step with an 8-object scene").

    python tools/follow_steps_cost.py

The reach env on the default model among 8 random obstacles per env, zero actions, 8 steps per round, 3 rounds
alternating ``MotionModel.follow_steps`` off and on (one thread); prints the best round's ms per step and the ratio.
"""

from __future__ import annotations

import time

import torch

from latentrl.envs.reach import ReachLocationEnv
from latentrl.scenes.random import RandomObstacles


def main() -> None:
    """One line per env count: ms per step with following off and on, and on / off."""
    torch.set_num_threads(1)
    for n in (64, 256):
        env = ReachLocationEnv(n, motion="default", scene=RandomObstacles(count=[8, 8]))
        env.reset(seed=0)
        action = torch.zeros(n, env.motion.latent_dim)
        best = {False: float("inf"), True: float("inf")}
        for _ in range(3):
            for follow in (False, True):
                env.motion.follow_steps = follow
                start = time.perf_counter()
                for _ in range(8):
                    env.step(action)
                best[follow] = min(best[follow], (time.perf_counter() - start) / 8)
        print(f"{n} envs: {best[False] * 1e3:.1f} ms per step without following steps, {best[True] * 1e3:.1f} ms "
              f"with; {best[True] / best[False]:.3f}x")


if __name__ == "__main__":
    main()
