"""Env steps/s of ``compile: true`` with and without inductor's weight freezing, in fp32 and bf16 autocast (CPU).

Why: ``bench rollout`` compiles the bare sampler with frozen weights (inductor then prepacks them for oneDNN,
and in bf16 casts them once), while the env's ``compile: true`` does not freeze. This measures what freezing
would change for the env's whole step. Every variant runs in this one process, in the order printed.

    python tools/env_compile_probe.py --model official --num-envs 1 --steps 5 --threads 2 --skip "eager bf16"
"""

from __future__ import annotations

import argparse
import json
import time

import torch

VARIANTS = (  # label, compile, amp, freezing
    ("eager fp32", False, None, False),
    ("compiled fp32", True, None, False),
    ("compiled+frozen fp32", True, None, True),
    ("eager bf16", False, "bf16", False),
    ("compiled bf16", True, "bf16", False),
    ("compiled+frozen bf16", True, "bf16", True),
)


def env_rate(model, num_envs: int, compile: bool, amp: str | None, freezing: bool, steps: int) -> tuple[float, float]:
    """(env steps/s, seconds of the first step) of one ReachLocation env; the first step compiles, untimed."""
    import latentrl.envs.base as base
    from latentrl.envs.reach import ReachLocationEnv
    from latentrl.timing import mean_time

    before, original = model.amp_dtype, base.compile_step_core
    torch._dynamo.reset()
    if compile and freezing:
        base.compile_step_core = lambda core, device: torch.compile(core, fullgraph=True, dynamic=False,
                                                                    options={"freezing": True})
    try:
        env = ReachLocationEnv(num_envs, motion=model, device="cpu", compile=compile, amp=amp)
        env.reset(seed=0)
        actions = torch.randn(num_envs, model.latent_dim, generator=torch.Generator().manual_seed(0))
        start = time.perf_counter()
        if compile:
            env.step(actions)
        first = time.perf_counter() - start
        return num_envs / mean_time(lambda: env.step(actions), steps, "cpu"), first
    finally:
        base.compile_step_core = original
        model.amp_dtype = before


def main() -> None:
    from latentrl.app.bench.env import bench_model

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--model", default="default", help="'default', 'official' (random weights) or a path")
    parser.add_argument("--num-envs", type=int, default=1)
    parser.add_argument("--steps", type=int, default=10, help="timed steps per variant")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--skip", nargs="*", default=[], help="variant labels to leave out")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    model = bench_model(args.model)
    rates = {}
    for label, compile, amp, freezing in VARIANTS:
        if label in args.skip:
            continue
        rate, first = env_rate(model, args.num_envs, compile, amp, freezing, args.steps)
        rates[label] = rate
        print(f"{args.model} N={args.num_envs} {label:>22}: {rate:9.1f} env steps/s (first step {first:.0f} s)",
              flush=True)
    print(json.dumps(rates))


if __name__ == "__main__":
    main()
