"""The quick config's env step in float32 and under bf16 autocast, interleaved in one process.

Why: the Quickstart turns bf16 on only where it pays; on a shared machine only a same-run, interleaved ratio
says whether it does (docs/benchmarks.md, "Quickstart").

    python tools/quick_amp_probe.py --threads 1 --num-envs 64 --rounds 5 --steps 8
"""

from __future__ import annotations

import argparse
import statistics
import time


def main(argv: list[str] | None = None) -> int:
    """Time ``--rounds`` A/B rounds of ``--steps`` env steps each; print the medians and each round's ratio."""
    import torch

    from latentrl.app.train import load_motion, load_train_config
    from latentrl.envs.config import build

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--num-envs", type=int, default=64)
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--steps", type=int, default=8)
    args = parser.parse_args(argv)
    torch.set_num_threads(args.threads)
    envs = {}
    for amp in ("fp32", "bf16"):
        overrides = [f"env.num_envs={args.num_envs}"] + (["env.amp=bf16"] if amp == "bf16" else [])
        cfg = load_train_config("quick", overrides)
        envs[amp] = build(cfg.env, "cpu", motion=load_motion(cfg.env, "cpu"))
        envs[amp].reset(seed=0)
    dim = envs["fp32"].action_space.shape[-1]
    seconds = {name: [] for name in envs}
    for _ in range(args.rounds):
        for name, env in envs.items():
            action = torch.randn(args.num_envs, dim)
            start = time.perf_counter()
            for _ in range(args.steps):
                env.step(action)
            seconds[name].append((time.perf_counter() - start) / args.steps)
    for name, values in seconds.items():
        print(f"{name}: median {statistics.median(values) * 1e3:.1f} ms per step of {args.num_envs} envs")
    ratios = [a / b for a, b in zip(seconds["fp32"], seconds["bf16"])]
    print(f"bf16 speed / fp32: median {statistics.median(ratios):.2f}x, rounds "
          + ", ".join(f"{r:.2f}" for r in ratios))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
