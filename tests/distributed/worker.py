"""One rank of the distributed PPO tests, run by torchrun: ``worker.py MODE RUN_DIR``.

MODE: ``fresh`` (a new run), ``resume`` (continue RUN_DIR), ``fail`` (rank 1's env raises during the
second iteration), ``skew`` (rank 1 alone gets a real SIGINT during the second iteration, as when a signal
reaches the ranks in different iterations). Every rank that finishes writes ``RUN_DIR/rank<r>.pt``: its weights,
buffers and counters (``interrupted``: the iteration it stopped at after a Ctrl-C, else None).
"""

from __future__ import annotations

import os
import signal
import sys
from pathlib import Path

import torch

from latentrl.monitor import EvalReport
from latentrl.ppo import distributed
from latentrl.ppo.run import register_trainer, train
from latentrl.ppo.trainer import NativeTrainer
from tests.ppo.conftest import tiny_policy, tiny_ppo
from tests.ppo.envs import ReachVecEnv

FAIL_MESSAGE = "injected env failure on rank 1"


class FailingEnv(ReachVecEnv):
    """Raises on rank 1 at its 12th step (inside the second 8-step rollout)."""

    calls = 0

    def step(self, actions):
        self.calls += 1
        if distributed.current().rank == 1 and self.calls == 12:
            raise RuntimeError(FAIL_MESSAGE)
        return super().step(actions)


class SignalledEnv(ReachVecEnv):
    """Sends rank 1 (only) a SIGINT at its 12th step (inside the second 8-step rollout)."""

    calls = 0

    def step(self, actions):
        self.calls += 1
        if distributed.current().rank == 1 and self.calls == 12:
            os.kill(os.getpid(), signal.SIGINT)
        return super().step(actions)


class ProbeTrainer(NativeTrainer):
    """The native trainer, remembered so that each rank can report its own weights."""

    built: list[NativeTrainer] = []

    def build(self, policy_cfg, layout) -> None:
        super().build(policy_cfg, layout)
        ProbeTrainer.built.append(self)


def main(mode: str, run_dir: Path) -> None:
    collective = distributed.init("cpu")
    torch.set_num_threads(1)
    register_trainer("probe", lambda env: ProbeTrainer)
    env = {"fail": FailingEnv, "skew": SignalledEnv}.get(mode, ReachVecEnv)(num_envs=4, max_episode_steps=4)
    # 4 envs x 8 steps = 32 per rank; on 2 ranks 2 iterations of 64 (skew: room for 8, checkpoints only on a stop)
    ppo = (tiny_ppo(total_steps=512, eval_every=1, checkpoint_every=0) if mode == "skew"
           else tiny_ppo(total_steps=128, eval_every=1))
    hook = (lambda policy: EvalReport({"probe": 1.0})) if collective.is_main else None  # as app/train.py does
    interrupted = None
    try:
        result = train(env, run_dir, ppo, tiny_policy(obs_norm=True), trainer="probe", resume=mode == "resume",
                       evaluate=hook, progress=False)
    except KeyboardInterrupt:
        result, interrupted = None, ProbeTrainer.built[-1].iteration
    trainer = ProbeTrainer.built[-1]
    torch.save({"state": {k: v.clone() for k, v in trainer.policy.state_dict().items()},
                "env_steps": trainer.env_steps, "iterations": trainer.iteration,
                "rollout": tuple(result.rollout) if result else None, "world_size": collective.world_size,
                "interrupted": interrupted}, run_dir / f"rank{collective.rank}.pt")
    if collective.world_size > 1:
        distributed.end_process(0)  # as latentrl train's ranks end
    distributed.shutdown()


if __name__ == "__main__":
    main(sys.argv[1], Path(sys.argv[2]))
