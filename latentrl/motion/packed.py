"""oneDNN-prepacked linear weights for frozen CPU inference at small batch.

Why: at batch 1 the sampler's linears see about 10 rows (2 guidance halves x 5 tokens). There MKL's fp32
GEMM, which eager PyTorch and inductor's frozen-weight path both use, streams the official model's weights
at ~6 GB/s on our 2-core EPYC; oneDNN with the weights reordered once for that row count reaches ~11 GB/s
(docs/benchmarks.md, "Prepacked weights"). :func:`pack_linears` swaps every ``nn.Linear`` of a module for
:class:`PackedLinear` and packs the attention projections; the state dict is unchanged.

The packed copies are made once: pack a **frozen** model (the motion model is never trained after loading),
on the CPU in float32. The op is defined through ``torch.library`` (schema, CPU kernel, fake kernel), so
``torch.compile`` treats it as one opaque call and fuses everything around it. It has no backward: inputs that
need a gradient take ``F.linear``.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from latentrl.errors import LatentRLError

_PACKED: list[torch.Tensor] = []
"""Packed weights by key (the key is a plain int, so a compiled graph holds it as a constant)."""


# A plain ``torch.library.Library`` op, not ``torch.library.custom_op``: the latter's Python wrapper costs
# ~17 us per call (35 vs 18 us for a tiny matmul, one thread; oneDNN alone 15), ~7 ms per batch-1 primitive of ~390
# linears. A FRAGMENT, so other code may add ops to the namespace; reloading this module is not supported (the op
# and the packed weights it reads are defined once per process).
_LIB = torch.library.Library("latentrl", "FRAGMENT")
_LIB.define("packed_linear(Tensor x, Tensor weight, Tensor bias, int key) -> Tensor")


def _packed_linear_cpu(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor, key: int) -> torch.Tensor:
    """``F.linear(x, weight, bias)`` through the oneDNN weight packed under ``key``."""
    # oneDNN's op takes any leading dims and strides itself (tests/motion/test_packed.py): no reshape here
    return torch.ops.mkldnn._linear_pointwise(x, _PACKED[key], bias, "none", [], "")


_LIB.impl("packed_linear", _packed_linear_cpu, "CPU")


@torch.library.register_fake("latentrl::packed_linear")
def _packed_linear_fake(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor, key: int) -> torch.Tensor:
    return x.new_empty(*x.shape[:-1], weight.shape[0])


packed_linear = torch.ops.latentrl.packed_linear.default


def linear(x: torch.Tensor, weight: torch.Tensor, bias: torch.Tensor | None, key: int | None) -> torch.Tensor:
    """``F.linear``, or the packed op when ``key`` names a packed copy of ``weight`` and ``x`` is CPU float32.

    Anything else takes ``F.linear``: a cast or moved model, CPU autocast (even switched on after packing), and
    any input, weight or bias that needs a gradient (the op has no backward). The checks read only metadata.
    """
    if (key is None or x.dtype != torch.float32 or x.device.type != "cpu" or torch.is_autocast_enabled("cpu")
            or x.requires_grad or weight.requires_grad or (bias is not None and bias.requires_grad)):
        return F.linear(x, weight, bias)
    return packed_linear(x, weight, bias, key)


def pack_weight(weight: torch.Tensor, rows: int) -> int:
    """Reorder ``weight`` (out, in) for oneDNN at ``rows`` input rows; returns its key."""
    _PACKED.append(torch.ops.mkldnn._reorder_linear_weight(weight.detach(), int(rows)))
    return len(_PACKED) - 1


class PackedLinear(nn.Linear):
    """``nn.Linear`` whose forward uses a packed copy of its (frozen) weight; same parameters and state dict."""

    pack_key: int

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """The linear layer through the prepacked oneDNN weight (same result as ``nn.Linear``)."""
        return linear(x, self.weight, self.bias, self.pack_key)


def pack_linears(module: nn.Module, rows: int = 10) -> int:
    """Pack every linear layer of a frozen CPU float32 ``module`` for ``rows`` input rows; returns how many.

    ``rows`` only picks oneDNN's weight layout (other row counts still compute the right result): 10 is a
    batch-1 sampler step. Modules that project with raw weights (``SelfAttention``) pack them through their
    ``pack`` method. Layers already packed are left alone (and not counted). Linears without a bias stay as
    they are. The packed copies do not follow later weight changes (``load_state_dict``, training).
    """
    problem = _pack_problem(module)
    if problem:
        raise LatentRLError(f"cannot pack the model's linear layers: {problem}")
    count = 0
    for sub in module.modules():
        if type(sub) is nn.Linear and sub.bias is not None:
            sub.__class__ = PackedLinear
            sub.pack_key = pack_weight(sub.weight, rows)
            count += 1
        elif hasattr(sub, "pack") and not isinstance(sub, PackedLinear):
            count += sub.pack(rows)
    return count


def _pack_problem(module: nn.Module) -> str | None:
    """Why ``module`` cannot be packed, or None."""
    if not torch.backends.mkldnn.is_available():
        return "this torch build has no oneDNN (mkldnn)"
    if getattr(module, "amp_dtype", None) is not None:
        return f"the model samples under autocast ({module.amp_dtype}); packing is for float32 sampling"
    for p in module.parameters():
        if p.device.type != "cpu" or p.dtype != torch.float32:
            return f"packing is for CPU float32 weights, found {p.dtype} on {p.device}"
    return None
