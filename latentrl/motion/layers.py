"""Transformer building blocks whose parameter names match ``torch.nn.TransformerEncoderLayer``.

DART's denoiser uses torch's layer and its VAE uses MLD's DETR-style copy; both store
``self_attn.in_proj_weight``, ``self_attn.in_proj_bias``, ``self_attn.out_proj.*``, ``linear1``,
``linear2``, ``norm1`` and ``norm2``. One implementation serves both so checkpoints load with
``strict=True``. We run batch-first internally ``(B, L, h)``: the sequences are 5-12 tokens long,
so the layout change is free and lets attention run as one batched matmul.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import nn

from latentrl.motion.packed import linear, pack_weight


class SelfAttention(nn.Module):
    """Multi-head self-attention with ``nn.MultiheadAttention``'s parameter names."""

    def __init__(self, h_dim: int, num_heads: int):
        super().__init__()
        if h_dim % num_heads:
            raise ValueError(f"h_dim {h_dim} is not divisible by num_heads {num_heads}")
        self.num_heads = num_heads
        self.in_proj_weight = nn.Parameter(torch.empty(3 * h_dim, h_dim))
        self.in_proj_bias = nn.Parameter(torch.zeros(3 * h_dim))
        self.out_proj = nn.Linear(h_dim, h_dim)
        nn.init.xavier_uniform_(self.in_proj_weight)
        nn.init.zeros_(self.out_proj.bias)
        self.pack_keys: tuple[int, int, int] | None = None  # packed qkv, q and kv weights (latentrl.motion.packed)

    def pack(self, rows: int) -> int:
        """Pack the joint and split input projections for oneDNN (:func:`latentrl.motion.packed.pack_linears`)."""
        if self.pack_keys is not None:
            return 0
        h = self.in_proj_weight.shape[1]
        w = self.in_proj_weight
        self.pack_keys = (pack_weight(w, rows), pack_weight(w[:h], rows), pack_weight(w[h:], rows))
        return 3

    def forward(self, x: torch.Tensor, query_last: int | None = None) -> torch.Tensor:
        """(B, L, h) -> (B, L, h); with ``query_last=k`` only the last k tokens attend (B, k, h)."""
        b, length, h = x.shape
        heads, hd = self.num_heads, h // self.num_heads
        keys = self.pack_keys or (None, None, None)
        if query_last is None:
            qkv = linear(x, self.in_proj_weight, self.in_proj_bias, keys[0])
            q, k, v = qkv.view(b, length, 3, heads, hd).permute(2, 0, 3, 1, 4)
        else:
            w_q, w_kv = self.in_proj_weight[:h], self.in_proj_weight[h:]
            b_q, b_kv = self.in_proj_bias[:h], self.in_proj_bias[h:]
            q = linear(x[:, -query_last:], w_q, b_q, keys[1]).view(b, query_last, heads, hd).transpose(1, 2)
            k, v = linear(x, w_kv, b_kv, keys[2]).view(b, length, 2, heads, hd).permute(2, 0, 3, 1, 4)
        out = _attention(q, k, v)  # (B, heads, Lq, hd)
        out = out.transpose(1, 2).reshape(b, q.shape[2], h)
        return self.out_proj(out)


def _attention(q: torch.Tensor, k: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Softmax attention for short sequences.

    For <= 16 tokens an explicit (Lq x Lk) score matrix is the cheapest kernel on CPU; longer
    sequences use PyTorch's fused scaled-dot-product attention.
    """
    if k.shape[-2] > 16 or q.is_cuda:
        return F.scaled_dot_product_attention(q, k, v)
    scores = (q * (1.0 / math.sqrt(q.shape[-1]))) @ k.transpose(-1, -2)
    return torch.softmax(scores, dim=-1) @ v


class TransformerLayer(nn.Module):
    """Post-norm (default) or pre-norm encoder layer: attention then a GELU/ReLU feed-forward."""

    def __init__(
        self,
        h_dim: int,
        num_heads: int,
        ff_size: int,
        dropout: float = 0.1,
        activation: str = "gelu",
        normalize_before: bool = False,
    ):
        super().__init__()
        if activation not in ("gelu", "relu"):
            raise ValueError(f"activation must be 'gelu' or 'relu', got {activation!r}")
        self.self_attn = SelfAttention(h_dim, num_heads)
        self.linear1 = nn.Linear(h_dim, ff_size)
        self.linear2 = nn.Linear(ff_size, h_dim)
        self.norm1 = nn.LayerNorm(h_dim)
        self.norm2 = nn.LayerNorm(h_dim)
        self.dropout = nn.Dropout(dropout)
        self.activation = F.gelu if activation == "gelu" else F.relu
        self.normalize_before = normalize_before

    def _ff(self, x: torch.Tensor) -> torch.Tensor:
        return self.dropout(self.linear2(self.dropout(self.activation(self.linear1(x)))))

    def forward(self, x: torch.Tensor, query_last: int | None = None) -> torch.Tensor:
        """(B, L, h) -> (B, L, h), or (B, k, h) for only the last ``query_last`` tokens."""
        if self.normalize_before:
            y = self.norm1(x)
            x = (x if query_last is None else x[:, -query_last:]) + self.dropout(self.self_attn(y, query_last))
            return x + self._ff(self.norm2(x))
        res = x if query_last is None else x[:, -query_last:]
        x = self.norm1(res + self.dropout(self.self_attn(x, query_last)))
        return self.norm2(x + self._ff(x))


class SinusoidalPositionalEncoding(nn.Module):
    """MDM/DART's fixed sinusoid table ``pe`` of shape (max_len, 1, h) (a saved buffer)."""

    def __init__(self, h_dim: int, max_len: int = 5000):
        super().__init__()
        position = torch.arange(0, max_len, dtype=torch.float32).unsqueeze(1)
        div_term = torch.exp(torch.arange(0, h_dim, 2).float() * (-math.log(10000.0) / h_dim))
        pe = torch.zeros(max_len, h_dim)
        pe[:, 0::2] = torch.sin(position * div_term)
        pe[:, 1::2] = torch.cos(position * div_term)
        self.register_buffer("pe", pe.unsqueeze(1))

    def rows(self, length: int) -> torch.Tensor:
        """(length, h) first rows, for adding to batch-first sequences."""
        return self.pe[:length, 0]


class LearnedPositionalEncoding(nn.Module):
    """MLD's learned 1-D position table ``pe`` of shape (max_len, 1, h)."""

    def __init__(self, h_dim: int, max_len: int = 500):
        super().__init__()
        self.pe = nn.Parameter(torch.empty(max_len, 1, h_dim))
        nn.init.uniform_(self.pe)

    def rows(self, length: int) -> torch.Tensor:
        """(length, h) first rows, for adding to batch-first sequences."""
        return self.pe[:length, 0]
