"""Primitive VAE (DART's ``AutoMldVae``, ``all_encoder`` architecture) with DART's parameter names.

Encoder input: ``[2 global motion tokens, H + F frame tokens]`` -> skip-connected transformer ->
the two global tokens give ``mu`` and ``log var`` of a ``(latent_size=1, D)`` latent.
Decoder input: ``[z, H history tokens, F zero queries]`` -> skip-connected transformer -> the
last F tokens -> ``final_layer`` -> F normalized frames. The zero queries do not pass through
``skel_embedding``. With ``rescale_latent`` the decoder sees ``z * latent_std`` (the denoiser
works in a unit-variance latent space; ``latent_mean`` is stored but never used, as in DART).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import torch
from torch import nn

from latentrl.motion.layers import LearnedPositionalEncoding, TransformerLayer


@dataclass
class VAEConfig:
    """Hyperparameters of :class:`PrimitiveVAE` (DART's ``VAEArgs`` field names)."""

    nfeats: int = 276
    """Features per frame."""
    latent_dim: tuple[int, int] = (1, 256)
    """(tokens, width) of the latent; DART uses one token."""
    h_dim: int = 256
    """Transformer width."""
    ff_size: int = 1024
    """Feed-forward width."""
    num_layers: int = 7
    """Layers per encoder/decoder stack (odd: in-blocks, a middle block, out-blocks)."""
    num_heads: int = 4
    dropout: float = 0.1
    activation: str = "gelu"
    normalize_before: bool = False
    """Pre-norm layers instead of DART's post-norm."""
    position_embedding: str = "learned"
    arch: str = "all_encoder"
    history_length: int = 2
    future_length: int = 8


class SkipTransformer(nn.Module):
    """U-Net-style stack: in-blocks push activations, out-blocks pop and merge them (2h -> h)."""

    def __init__(self, layer: TransformerLayer, num_layers: int, h_dim: int):
        super().__init__()
        if num_layers % 2 != 1:
            raise ValueError(f"num_layers must be odd for the skip transformer, got {num_layers}")
        blocks = (num_layers - 1) // 2
        self.input_blocks = nn.ModuleList(copy.deepcopy(layer) for _ in range(blocks))
        self.middle_block = copy.deepcopy(layer)
        self.output_blocks = nn.ModuleList(copy.deepcopy(layer) for _ in range(blocks))
        self.linear_blocks = nn.ModuleList(nn.Linear(2 * h_dim, h_dim) for _ in range(blocks))
        self.norm = nn.LayerNorm(h_dim)
        for p in self.parameters():
            if p.dim() > 1:
                nn.init.xavier_uniform_(p)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """(B, L, h) -> (B, L, h)."""
        skips = []
        for block in self.input_blocks:
            x = block(x)
            skips.append(x)
        x = self.middle_block(x)
        for block, merge in zip(self.output_blocks, self.linear_blocks):
            x = block(merge(torch.cat((x, skips.pop()), dim=-1)))
        return self.norm(x)


class PrimitiveVAE(nn.Module):
    """Motion-primitive VAE; all tensors are in normalized feature space."""

    def __init__(self, config: VAEConfig):
        super().__init__()
        if config.arch != "all_encoder":
            raise ValueError(f"only DART's 'all_encoder' VAE architecture is supported, got {config.arch!r}")
        if config.position_embedding != "learned":
            raise ValueError(f"only 'learned' position embeddings are supported, got {config.position_embedding!r}")
        self.config = config
        h = config.h_dim
        self.latent_size, self.latent_width = config.latent_dim
        self.query_pos_encoder = LearnedPositionalEncoding(h)
        self.query_pos_decoder = LearnedPositionalEncoding(h)
        layer = TransformerLayer(
            h, config.num_heads, config.ff_size, config.dropout, config.activation, config.normalize_before
        )
        self.encoder = SkipTransformer(layer, config.num_layers, h)
        self.encoder_latent_proj = nn.Linear(h, self.latent_width)
        self.decoder = SkipTransformer(layer, config.num_layers, h)
        self.decoder_latent_proj = nn.Linear(self.latent_width, h)
        self.global_motion_token = nn.Parameter(torch.randn(self.latent_size * 2, h))
        self.skel_embedding = nn.Linear(config.nfeats, h)
        self.final_layer = nn.Linear(h, config.nfeats)
        # float buffers (DART registers int64 ones and re-assigns floats after loading)
        self.register_buffer("latent_mean", torch.tensor(0.0))
        self.register_buffer("latent_std", torch.tensor(1.0))

    def encode(self, future: torch.Tensor, history: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Posterior of a primitive.

        Args:
            future: (B, F, 276) normalized future frames.
            history: (B, H, 276) normalized history frames.

        Returns:
            ``(mu, std)``, each (B, latent_size, D), unscaled latent space.
        """
        b = future.shape[0]
        frames = self.skel_embedding(torch.cat((history, future), dim=1))  # (B, H+F, h)
        tokens = self.global_motion_token.unsqueeze(0).expand(b, -1, -1)
        seq = torch.cat((tokens, frames), dim=1)
        seq = seq + self.query_pos_encoder.rows(seq.shape[1])
        dist = self.encoder_latent_proj(self.encoder(seq)[:, : 2 * self.latent_size])
        mu = dist[:, : self.latent_size]
        logvar = dist[:, self.latent_size :].clamp(-10.0, 10.0)
        return mu, logvar.exp().pow(0.5)

    def decode(
        self, z: torch.Tensor, history: torch.Tensor, nfuture: int = 8, scale_latent: bool = True
    ) -> torch.Tensor:
        """(B, latent_size, D) latent + (B, H, 276) normalized history -> (B, nfuture, 276) normalized."""
        b = history.shape[0]
        if scale_latent:
            z = z * self.latent_std
        z = self.decoder_latent_proj(z)
        queries = z.new_zeros(b, nfuture, z.shape[-1])
        seq = torch.cat((z, self.skel_embedding(history), queries), dim=1)
        seq = seq + self.query_pos_decoder.rows(seq.shape[1])
        return self.final_layer(self.decoder(seq)[:, -nfuture:])
