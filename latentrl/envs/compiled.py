"""How an env's step core is compiled (``compile=True``): one graph on the CPU, a captured CUDA graph on CUDA.

Why two modes: on a CPU the win is fusing the step's many small tensor ops (``torch.compile(fullgraph=True)``);
on a GPU the step is launch-bound, so the graph is also captured and replayed as a CUDA graph
(``mode="reduce-overhead"``). The step core is written for that: no host syncs and no tensor built from
Python data inside it (tests/envs/test_compiled_step.py), static shapes (``dynamic=False``).

A replayed CUDA graph writes its outputs into the same memory every step, so the captured step marks each
call as a new step and returns copies: the env keeps its state and hands its results to a trainer that
stores them.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch.utils._pytree import tree_map_only


def compile_mode(device: torch.device | str) -> str:
    """``torch.compile`` mode for a step core on ``device``: CUDA-graph capture on CUDA, fused kernels elsewhere."""
    return "reduce-overhead" if torch.device(device).type == "cuda" else "default"


def compile_step_core(core: Callable, device: torch.device | str) -> Callable:
    """``core`` as one ``torch.compile`` graph for ``device`` (see the module docstring)."""
    mode = compile_mode(device)
    compiled = torch.compile(core, fullgraph=True, dynamic=False, mode=mode)
    if mode == "default":
        return compiled

    def captured(*args):
        torch.compiler.cudagraph_mark_step_begin()
        return tree_map_only(torch.Tensor, torch.clone, compiled(*args))

    return captured
