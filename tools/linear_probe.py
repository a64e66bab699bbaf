"""Why batch 1 is slow on a CPU: the official denoiser's linear weights at 10 input rows, three ways.

Times the 32 weight matrices of DART's official-size denoiser (8 layers: in_proj 1536x512, out_proj 512x512,
linear1 1024x512, linear2 512x1024; 64 MB fp32) on 10 rows (a batch-1 sampler step with guidance) with
MKL's ``F.linear``, MKL-packed weights (what inductor's frozen fp32 path uses) and oneDNN weights reordered for
10 rows (what ``MotionModel.pack_for_cpu`` uses), next to a plain 64 MB read. Usage:

    python tools/linear_probe.py [--threads 1] [--rows 10] [--layouts 1 8 10 16 32 64]

``--layouts`` also times oneDNN with the weights reordered for other row counts (the input stays ``--rows``).
"""

import argparse

import torch
import torch.nn.functional as F

from latentrl.timing import median_time


def median_ms(fn) -> float:
    return median_time(fn, repeats=9) * 1e3


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--rows", type=int, default=10)
    ap.add_argument("--layouts", type=int, nargs="*", default=[], help="also oneDNN layouts for these row counts")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    shapes = [(1536, 512), (512, 512), (1024, 512), (512, 1024)] * 8
    weights = [torch.randn(o, i) * 0.02 for o, i in shapes]
    biases = [torch.zeros(o) for o, _ in shapes]
    x = {i: torch.randn(args.rows, i) for i in (512, 1024)}
    mb = sum(w.numel() for w in weights) * 4 / 2**20
    gflop = sum(w.numel() for w in weights) * 2 * args.rows / 1e9
    big = torch.randn(int(mb * 2**20 / 4))
    print(f"{args.threads} thread(s), {args.rows} rows, {mb:.0f} MB of weights")
    print(f"  plain read of {mb:.0f} MB: {median_ms(big.sum):.2f} ms")
    mkl = [torch.ops.mkl._mkl_reorder_linear_weight(w, args.rows) for w in weights]
    onednn = [torch.ops.mkldnn._reorder_linear_weight(w, args.rows) for w in weights]
    ways = {
        "F.linear (MKL)": lambda: [F.linear(x[w.shape[1]], w, b) for w, b in zip(weights, biases)],
        "MKL packed": lambda: [torch.ops.mkl._mkl_linear(x[w.shape[1]], p, w, b, args.rows)
                               for p, w, b in zip(mkl, weights, biases)],
        "oneDNN packed": lambda: [torch.ops.mkldnn._linear_pointwise(x[w.shape[1]], p, b, "none", [], "")
                                  for p, w, b in zip(onednn, weights, biases)],
    }
    for layout in args.layouts:
        packed = [torch.ops.mkldnn._reorder_linear_weight(w, layout) for w in weights]
        ways[f"oneDNN {layout}-row layout"] = lambda packed=packed: [
            torch.ops.mkldnn._linear_pointwise(x[w.shape[1]], p, b, "none", [], "")
            for p, w, b in zip(packed, weights, biases)]
    for name, fn in ways.items():
        ms = median_ms(fn)
        rate, traffic = gflop / ms * 1e3, mb / 1024 / ms * 1e3
        print(f"  {name:>22}: {ms:6.2f} ms  {rate:6.1f} GFLOP/s  {traffic:5.1f} GB/s of weights")


if __name__ == "__main__":
    main()
