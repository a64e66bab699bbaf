"""Wall-clock helpers shared by benchmarks and evaluation: the hardware label and median timings.

Absolute timings on shared machines are noisy, so every figure carries :func:`hardware` and is
a median over repeats (:func:`median_time`), CUDA-synchronized on GPU.
"""

from __future__ import annotations

import os
import platform
import statistics
import time
from collections.abc import Callable

import torch


def hardware() -> dict:
    """CPU model, core count, torch build and GPU name: the label every figure carries."""
    cpu = platform.processor() or "unknown"
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.lower().startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    info = {
        "cpu": cpu,
        "cpu_count": os.cpu_count(),
        "torch_threads": torch.get_num_threads(),
        "torch": torch.__version__,
        "python": platform.python_version(),
    }
    if torch.cuda.is_available():
        info["gpu"] = torch.cuda.get_device_name(0)
    return info


def synchronizer(device: str) -> Callable[[], None]:
    """A call that waits for queued work on ``device`` (CUDA), or does nothing (CPU)."""
    return torch.cuda.synchronize if str(device).startswith("cuda") else (lambda: None)


def median_time(fn: Callable[[], object], repeats: int = 5, warmup: int = 2, device: str = "cpu") -> float:
    """Median wall time of ``fn`` in seconds (CUDA-synchronized on GPU)."""
    sync = synchronizer(device)
    for _ in range(warmup):
        fn()
    sync()
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        sync()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def mean_time(fn: Callable[[], object], calls: int, device: str = "cpu") -> float:
    """Seconds per call of ``fn`` over ``calls`` back-to-back calls, after one warm-up call."""
    sync = synchronizer(device)
    fn()
    sync()
    start = time.perf_counter()
    for _ in range(calls):
        fn()
    sync()
    return (time.perf_counter() - start) / calls


def matmul_peak_gflops(n: int = 2048, repeats: int = 7) -> float:
    """Median fp32 GFLOP/s of an n x n matmul on CPU (the reference for 'fraction of peak')."""
    a, b, c = torch.randn(n, n), torch.randn(n, n), torch.empty(n, n)
    t = median_time(lambda: torch.matmul(a, b, out=c), repeats=repeats, warmup=2)
    return 2.0 * n**3 / t / 1e9


def busy_machine_warning(threads: int, load: float | None = None, cpus: int | None = None) -> str | None:
    """A one-line warning when ``threads`` torch threads will not each get a core, else ``None``.

    Why: torch's CPU threads wait on each other at every operation, so a multi-threaded job that loses a
    core to another process stalls far more than its share. Measured on the 2-core VM (docs/benchmarks.md,
    "Threads under load"): a 2-thread training's rollout went from 7 s to 102 s per iteration while a
    test ran beside it, where single-threaded trainings sharing the machine kept their share.
    ``load`` is the 1-minute load average (default: the system's), which counts this process too (one
    runnable task is taken as ours), and ``cpus`` the core count.
    """
    if load is None:
        try:
            load = os.getloadavg()[0]
        except OSError:  # not available on this platform
            return None
    cpus = cpus or os.cpu_count() or 1
    if threads <= 1 or max(0.0, load - 1.0) + threads <= cpus + 0.5:
        return None
    return (f"the machine is busy (load {load:.1f} on {cpus} cores) and this job asks for {threads} torch threads; "
            f"threads that lose their core stall each other: set threads: 1 (or --set threads=1) to degrade gracefully")
