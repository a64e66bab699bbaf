"""Latent denoisers (DART's ``DenoiserTransformer`` and ``DenoiserMLP``) with DART's parameter names.

A denoiser maps a noisy latent ``x_t`` (B, 1, D), the diffusion step, the normalized history
(B, 2, 276) and a text embedding (B, E) to a prediction of the clean latent ``x_0``: directly
(DART's) or through ``v`` (``DenoiserConfig.prediction``; the only place it needs the noise schedule,
handed over by :meth:`Denoiser.attach_schedule`). Guidance and the sampling loops are
:mod:`latentrl.motion.diffusion`'s.

Transformer tokens, in order: ``[time, text, history_0, history_1, noisy latent]``, each embedded
to ``h_dim`` by its own Linear, plus sinusoidal positions 0..4 on **all** tokens; the last token
goes through ``output_process``. The unconditional pass zeroes the text embedding *before*
``embed_text`` (so its token is ``embed_text.bias``).

Sampling calls :meth:`condition` once per primitive (history and text tokens do not change over
the 10 steps) and :meth:`denoise` once per step; the time token is shared by the whole batch.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from latentrl.motion.layers import SinusoidalPositionalEncoding, TransformerLayer


@dataclass
class DenoiserConfig:
    """Hyperparameters (DART's ``DenoiserTransformerArgs`` / ``DenoiserMLPArgs`` names)."""

    model_type: str = "transformer"
    """'transformer' (DART's release) or 'mlp'."""
    h_dim: int = 512
    ff_size: int = 1024
    """Transformer feed-forward width."""
    num_layers: int = 8
    """Transformer layers."""
    num_heads: int = 4
    n_blocks: int = 2
    """Residual blocks of the MLP variant."""
    dropout: float = 0.1
    activation: str = "gelu"
    clip_dim: int = 512
    """Text-embedding width (512 for DART's CLIP; 384 for our MiniLM/hashed encoders)."""
    history_shape: tuple[int, int] = (2, 276)
    noise_shape: tuple[int, int] = (1, 256)
    """Latent shape (tokens, width) = the VAE's ``latent_dim``."""
    cond_mask_prob: float = 0.1
    """Probability of dropping the text during training (classifier-free guidance)."""
    prediction: str = "x0"
    """What the network outputs: 'x0' (DART) or 'v' (``sqrt(acp) eps - sqrt(1 - acp) x0``, turned into x0
    by :meth:`Denoiser.denoise`). Why 'v': at low noise an x0 network must copy ``x_t`` through every layer,
    and a small one fails to, so its samples collapse toward the conditional mean (docs/motion.md)."""

#: The denoiser outputs :class:`DenoiserConfig` knows.
PREDICTIONS = ("x0", "v")


class TimestepEmbedder(nn.Module):
    """Linear-SiLU-Linear on the sinusoid row of the step index (shares the position table)."""

    def __init__(self, h_dim: int, sequence_pos_encoder: SinusoidalPositionalEncoding):
        super().__init__()
        self.sequence_pos_encoder = sequence_pos_encoder
        self.time_embed = nn.Sequential(nn.Linear(h_dim, h_dim), nn.SiLU(), nn.Linear(h_dim, h_dim))

    def forward(self, timesteps: torch.Tensor) -> torch.Tensor:
        """(B,) int64 or () -> (B, h) or (h,)."""
        # a gather, not an integer index: a device tensor of steps needs no host read (compile, CUDA graphs)
        rows = self.sequence_pos_encoder.pe[:, 0].index_select(0, timesteps.reshape(-1))
        return self.time_embed(rows.reshape(*timesteps.shape, -1))


class Denoiser(nn.Module):
    """Common interface: ``forward`` for training, ``condition`` + ``denoise`` for sampling."""

    config: DenoiserConfig

    def attach_schedule(self, base_alphas_cumprod) -> None:
        """Give a v-predicting denoiser the cumulative alphas of the base process, by original step index.

        Non-persistent buffers: the schedule belongs to the diffusion config, saved beside the weights.
        An x0 denoiser keeps them too but never reads them.
        """
        acp = torch.as_tensor(base_alphas_cumprod, dtype=torch.float32)
        self.register_buffer("v_signal", acp.sqrt(), persistent=False)
        self.register_buffer("v_noise", (1.0 - acp).sqrt(), persistent=False)

    def denoise(self, x_t: torch.Tensor, timesteps: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        """x_t (B, n, D) + step (B,) or () + :meth:`condition` tokens -> x0 prediction (B, n, D)."""
        return self.x0_from_output(x_t, timesteps, self.predict(x_t, timesteps, cond))

    def x0_from_output(self, x_t: torch.Tensor, timesteps: torch.Tensor, out: torch.Tensor) -> torch.Tensor:
        """The network's output read as x0: itself, or ``sqrt(acp) x_t - sqrt(1 - acp) v``."""
        if self.config.prediction == "x0":
            return out
        if getattr(self, "v_signal", None) is None:
            raise RuntimeError("a v-predicting denoiser needs attach_schedule(...) before it denoises")
        steps = timesteps.reshape(-1)  # gathered, not read as an integer (compile, CUDA graphs)
        a = self.v_signal.index_select(0, steps).reshape(-1, 1, 1).to(out.dtype)
        s = self.v_noise.index_select(0, steps).reshape(-1, 1, 1).to(out.dtype)
        return a * x_t - s * out

    def mask_text(self, text: torch.Tensor, generator: torch.Generator | None = None) -> torch.Tensor:
        """Training-time text dropout for classifier-free guidance (rows zeroed with ``cond_mask_prob``)."""
        if not self.training or self.config.cond_mask_prob <= 0:
            return text
        keep = torch.rand(text.shape[0], 1, device=text.device, generator=generator) >= self.config.cond_mask_prob
        return text * keep

    def forward(
        self, x_t: torch.Tensor, timesteps: torch.Tensor, history: torch.Tensor, text: torch.Tensor
    ) -> torch.Tensor:
        """Predict x0 (B, 1, D).

        x_t (B, 1, D); timesteps (B,) int64 original step indices; history (B, 2, 276) normalized;
        text (B, E), already masked, or zeroed for the unconditional pass.
        """
        return self.denoise(x_t, timesteps, self.condition(history, text))


class DenoiserTransformer(Denoiser):
    """DART's transformer denoiser: timestep, text and history tokens, then the noisy latent tokens it reads out."""
    def __init__(self, config: DenoiserConfig):
        super().__init__()
        self.config = config
        h = config.h_dim
        self.sequence_pos_encoder = SinusoidalPositionalEncoding(h)
        self.embed_timestep = TimestepEmbedder(h, self.sequence_pos_encoder)
        self.embed_text = nn.Linear(config.clip_dim, h)
        self.embed_history = nn.Linear(config.history_shape[-1], h)
        self.embed_noise = nn.Linear(config.noise_shape[-1], h)
        layer_args = (h, config.num_heads, config.ff_size, config.dropout, config.activation)
        self.seqTransEncoder = _LayerStack([TransformerLayer(*layer_args) for _ in range(config.num_layers)])
        self.output_process = nn.Linear(h, config.noise_shape[-1])

    def condition(self, history: torch.Tensor, text: torch.Tensor) -> torch.Tensor:
        """(B, 2, 276) normalized history + (B, E) text -> (B, 1 + H, h) text and history tokens with positions."""
        tokens = torch.cat((self.embed_text(text).unsqueeze(1), self.embed_history(history)), dim=1)
        return tokens + self.sequence_pos_encoder.rows(1 + tokens.shape[1])[1:]

    def predict(self, x_t: torch.Tensor, timesteps: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        """The network's raw output (x0 or v, ``config.prediction``), (B, n, D)."""
        b, n = x_t.shape[:2]
        pe = self.sequence_pos_encoder.rows(2 + cond.shape[1] + n - 1)
        time_tok = (self.embed_timestep(timesteps) + pe[0]).reshape(-1, 1, cond.shape[-1]).expand(b, 1, -1)
        noise_tok = self.embed_noise(x_t) + pe[1 + cond.shape[1] :]
        x = torch.cat((time_tok, cond, noise_tok), dim=1)
        x = self.seqTransEncoder(x, query_last=n)
        return self.output_process(x)


class _LayerStack(nn.Module):
    """``nn.TransformerEncoder``-compatible container (``layers.{i}``).

    The last layer only computes the tokens that are read out.
    """

    def __init__(self, layers: list[TransformerLayer]):
        super().__init__()
        self.layers = nn.ModuleList(layers)

    def forward(self, x: torch.Tensor, query_last: int) -> torch.Tensor:
        for layer in self.layers[:-1]:
            x = layer(x)
        return self.layers[-1](x, query_last=query_last)


class _MLP(nn.Module):
    """DART's ``MLP``: Linear layers each followed by the activation (keys ``layers.{i}``)."""

    def __init__(self, dims: list[int], activation: nn.Module):
        super().__init__()
        self.layers = nn.ModuleList(nn.Linear(a, b) for a, b in zip(dims[:-1], dims[1:]))
        self.activation = activation

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        for layer in self.layers:
            x = self.activation(layer(x))
        return x


class _ResidualMLP(nn.Module):
    """DART's ``MLPBlock``: residual two-layer blocks then ``out_fc``."""

    def __init__(self, h_dim: int, out_dim: int, n_blocks: int, activation: nn.Module):
        super().__init__()
        self.layers = nn.ModuleList(_MLP([h_dim, h_dim, h_dim], activation) for _ in range(n_blocks))
        self.out_fc = nn.Linear(h_dim, out_dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        for layer in self.layers:
            x = layer(x) + x
        return self.out_fc(x)


_ACTIVATIONS = {"gelu": nn.GELU, "relu": nn.ReLU, "tanh": nn.Tanh, "lrelu": nn.LeakyReLU}


class DenoiserMLP(Denoiser):
    """MLP denoiser: ``input_project(cat(time, text, history, x_t))`` then residual blocks."""

    def __init__(self, config: DenoiserConfig):
        super().__init__()
        self.config = config
        h = config.h_dim
        self.sequence_pos_encoder = SinusoidalPositionalEncoding(h)
        self.embed_timestep = TimestepEmbedder(h, self.sequence_pos_encoder)
        self.history_dim = config.history_shape[0] * config.history_shape[1]
        self.noise_dim = config.noise_shape[0] * config.noise_shape[1]
        self.input_project = nn.Linear(h + config.clip_dim + self.history_dim + self.noise_dim, h)
        if config.activation not in _ACTIVATIONS:
            raise ValueError(f"activation must be one of {sorted(_ACTIVATIONS)}, got {config.activation!r}")
        self.mlp = _ResidualMLP(h, self.noise_dim, config.n_blocks, _ACTIVATIONS[config.activation]())

    def condition(self, history: torch.Tensor, text: torch.Tensor) -> torch.Tensor:
        """Text and history part of ``input_project`` (plus its bias), computed once: (B, h)."""
        h, e = self.config.h_dim, self.config.clip_dim
        w = self.input_project.weight
        hist = history.reshape(history.shape[0], self.history_dim)
        return text @ w[:, h : h + e].T + hist @ w[:, h + e : h + e + self.history_dim].T + self.input_project.bias

    def predict(self, x_t: torch.Tensor, timesteps: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
        """The network's raw output (x0 or v, ``config.prediction``), (B, n, D), from one MLP pass."""
        b = x_t.shape[0]
        h = self.config.h_dim
        w = self.input_project.weight
        time = self.embed_timestep(timesteps).reshape(-1, h)
        x = cond + time @ w[:, :h].T + x_t.reshape(b, self.noise_dim) @ w[:, -self.noise_dim :].T
        return self.mlp(x).reshape(b, *self.config.noise_shape)


def build_denoiser(config: DenoiserConfig) -> Denoiser:
    """The denoiser class named by ``config.model_type``."""
    if config.prediction not in PREDICTIONS:
        raise ValueError(f"prediction must be one of {list(PREDICTIONS)}, got {config.prediction!r}")
    if config.model_type == "transformer":
        return DenoiserTransformer(config)
    if config.model_type == "mlp":
        return DenoiserMLP(config)
    raise ValueError(f"denoiser model_type must be 'transformer' or 'mlp', got {config.model_type!r}")
