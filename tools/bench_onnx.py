"""Time the exported controller: export time, file size, onnxruntime vs torch per controller step.

    python tools/bench_onnx.py [--policy policies/reach_walk_default.pt] [--batch 1] [--threads 1] [--json F]

One controller step = observation, policy mean, 10 guided DDIM steps, VAE decode and world update
(what one call of the exported graph computes). Both sides run on the CPU with ``--threads`` threads;
figures are medians of ``--repeats`` calls after 3 warm-up calls.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import torch

from latentrl.export.onnx import (
    controller_metadata,
    export_onnx,
    load_controller,
    max_difference,
    onnx_session,
    run_session,
)
from latentrl.timing import hardware, median_time


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default=str(Path(__file__).resolve().parents[1] / "policies/reach_walk_default.pt"))
    parser.add_argument("--text", default="walk")
    parser.add_argument("--batch", type=int, default=1)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--json")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    step, info = load_controller(args.policy, batch=args.batch, text=args.text)
    example = step.example_inputs()
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        path = export_onnx(step, Path(tmp) / "controller.onnx", example, metadata=controller_metadata(step, info))
        export_s = time.perf_counter() - t0
        size = path.stat().st_size
        session = onnx_session(path, threads=args.threads)
        diff = max_difference(step, session, example)

        def torch_step():
            with torch.no_grad():
                step(*example)

        torch_s = median_time(torch_step, repeats=args.repeats, warmup=3)
        onnx_s = median_time(lambda: run_session(session, example, step.input_names), repeats=args.repeats, warmup=3)
    result = {"policy": Path(args.policy).name, "batch": args.batch, "threads": args.threads, "export_s": export_s,
              "file_bytes": size, "torch_ms_per_step": 1e3 * torch_s, "onnxruntime_ms_per_step": 1e3 * onnx_s,
              "max_abs_diff": diff, "hardware": hardware()}
    print(json.dumps(result, indent=1))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))


if __name__ == "__main__":
    main()
