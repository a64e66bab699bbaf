"""DART's actor-critic (``PolicyReachLocationMLP``) and a plain-MLP variant.

``architecture='dart'``::

    obs (B, D) ─ normalize ─┬─ goal   [a:b) ─ Linear+LeakyReLU ─┐
                            ├─ text   [b:c) ─ Linear+LeakyReLU ─┤ concat ─ embedding_encoder ─ emb (B, latent)
                            ├─ motion [c:d) ─ Linear+LeakyReLU ─┤          (Linear+LeakyReLU)
                            └─ scene  [d:e) ─ Linear+LeakyReLU ─┘
    emb ─ actor:  n_blocks x (x + act(L(act(L(x))))) ─ out_fc ─ action_scale * tanh ─ mean (B, A)
    emb ─ critic: n_blocks x (x + act(L(act(L(x))))) ─ out_fc ─ value (B,)
    actor_logstd (1, A), clamped to log_std_bounds: a ~ Normal(mean, exp(log_std)), not clamped.

The embedding is shared by actor and critic (both losses train it), as in DART. The observation is
split only through the layout dict the env publishes (``env.metadata["observation_layout"]``,
name -> [start, stop)); names map to encoder groups by :func:`group_layout`. Without a layout the
whole observation is one group, "obs".

``architecture='mlp'``: separate actor and critic MLPs (``mlp_hidden`` widths, LeakyReLU) on the
whole normalized observation, same mean/log-std head.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import torch
from torch import nn

from latentrl.errors import CheckpointError, ConfigError
from latentrl.ppo.config import PolicyConfig
from latentrl.ppo.normalizer import RunningNormalizer

KNOWN_GROUPS = ("text", "motion", "scene", "goal")
"""Encoder groups, in the priority that places a layout name mentioning several (``goal_text_embedding`` -> text)."""

_LOG_SQRT_2PI = 0.5 * math.log(2.0 * math.pi)


class PolicyOutput(NamedTuple):
    """The actor-critic's forward pass: action mean, log standard deviation and value."""
    mean: torch.Tensor
    """(B, A) action mean, ``action_scale * tanh(.)``."""
    log_std: torch.Tensor
    """(1, A) clamped state-independent log standard deviation."""
    value: torch.Tensor
    """(B,) state value."""


class PolicyStep(NamedTuple):
    """An action for the rollout, with the log-probability and value PPO stores beside it."""
    action: torch.Tensor
    """(B, A) sampled action (the mean when deterministic)."""
    log_prob: torch.Tensor
    """(B,) log-density of ``action`` under the current policy."""
    value: torch.Tensor
    """(B,) state value."""


class ActionEvaluation(NamedTuple):
    """Stored actions scored under the current policy: the inputs of the PPO loss."""
    log_prob: torch.Tensor
    """(B,) log-density of the given actions."""
    entropy: torch.Tensor
    """(B,) entropy of the action distribution."""
    value: torch.Tensor
    """(B,) state value."""


# --------------------------------------------------------------------------- layout
def group_of(name: str) -> str:
    """The encoder group of an observation field: the first of :data:`KNOWN_GROUPS` among its words, else itself."""
    tokens = re.split(r"[/_.\-]", name)
    for group in KNOWN_GROUPS:
        if group in tokens:
            return group
    return name


def group_layout(layout: Mapping[str, Any] | None, obs_dim: int) -> dict[str, list[tuple[int, int]]]:
    """Map the env's observation layout onto encoder groups, checking it tiles ``[0, obs_dim)``.

    A layout name joins the first of :data:`KNOWN_GROUPS` found among its ``_``/``/``-separated
    words (``goal_dir`` and ``goal_dist`` -> goal, ``goal_text_embedding`` -> text); any other name
    is its own group. Groups keep the order of their first appearance. Values are ``[start, stop)``
    pairs or ``slice`` objects. Returns group -> sorted, merged ranges.
    """
    if not layout:
        return {"obs": [(0, obs_dim)]}
    groups: dict[str, list[tuple[int, int]]] = {}
    covered = torch.zeros(obs_dim, dtype=torch.int32)
    for name, span in layout.items():
        start, stop = (span.start, span.stop) if isinstance(span, slice) else (int(span[0]), int(span[1]))
        if not 0 <= start < stop <= obs_dim:
            raise ConfigError(f"observation_layout['{name}'] = [{start}, {stop}) does not lie in [0, {obs_dim})")
        covered[start:stop] += 1
        groups.setdefault(group_of(name), []).append((start, stop))
    if not bool((covered == 1).all()):
        bad = int(torch.nonzero(covered != 1)[0])
        what = "not covered" if covered[bad] == 0 else "covered twice"
        raise ConfigError(f"observation_layout must tile [0, {obs_dim}) exactly; dim {bad} is {what}: {dict(layout)}")
    return {g: _merge(sorted(r)) for g, r in groups.items()}


def _merge(ranges: list[tuple[int, int]]) -> list[tuple[int, int]]:
    out = [ranges[0]]
    for start, stop in ranges[1:]:
        if start == out[-1][1]:
            out[-1] = (out[-1][0], stop)
        else:
            out.append((start, stop))
    return out


def plain_layout(layout: Mapping[str, Any] | None) -> dict[str, list[int]] | None:
    """The layout as name -> [start, stop] lists (what checkpoints and YAML store)."""
    if not layout:
        return None
    return {k: ([v.start, v.stop] if isinstance(v, slice) else [int(v[0]), int(v[1])]) for k, v in layout.items()}


# --------------------------------------------------------------------------- blocks
class MLP(nn.Module):
    """Linear + LeakyReLU after every layer (DART's ``MLP``; parameters under ``layers.<i>``)."""

    def __init__(self, dims: Sequence[int]):
        super().__init__()
        self.layers = nn.ModuleList(nn.Linear(i, o) for i, o in zip(dims[:-1], dims[1:]))
        self.act = nn.LeakyReLU()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Every layer followed by LeakyReLU."""
        for layer in self.layers:
            x = self.act(layer(x))
        return x


class ResidualBlock(MLP):
    """``x + MLP(x)`` with two width-preserving layers."""

    def __init__(self, dim: int):
        super().__init__([dim, dim, dim])

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """The input plus the two-layer MLP's output."""
        return x + super().forward(x)


class ResidualHead(nn.Module):
    """``n_blocks`` residual blocks then a linear ``out_fc`` (DART's ``MLPBlock`` + ``out_fc``)."""

    def __init__(self, dim: int, n_blocks: int, out_dim: int):
        super().__init__()
        self.layers = nn.ModuleList(ResidualBlock(dim) for _ in range(n_blocks))
        self.out_fc = nn.Linear(dim, out_dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """The residual blocks, then the linear output layer."""
        for block in self.layers:
            x = block(x)
        return self.out_fc(x)


class MLPHead(nn.Module):
    """Hidden LeakyReLU MLP then a linear ``out_fc`` (the 'mlp' architecture's actor or critic)."""

    def __init__(self, in_dim: int, hidden: Sequence[int], out_dim: int):
        super().__init__()
        self.body = MLP([in_dim, *hidden])
        self.out_fc = nn.Linear(hidden[-1] if hidden else in_dim, out_dim)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """The hidden MLP, then the linear output layer."""
        return self.out_fc(self.body(x))


class GroupEncoder(nn.Module):
    """Per-group ``<group>_encoder`` (Linear+LeakyReLU to ``latent_dim``), concatenated, then ``embedding_encoder``."""

    def __init__(self, groups: Mapping[str, list[tuple[int, int]]], latent_dim: int):
        super().__init__()
        self.groups = list(groups)
        self._spans = {g: r for g, r in groups.items()}
        for g, ranges in groups.items():
            self.add_module(f"{g}_encoder", MLP([sum(b - a for a, b in ranges), latent_dim]))
        self.embedding_encoder = MLP([latent_dim * len(groups), latent_dim])

    def _take(self, obs: torch.Tensor, group: str) -> torch.Tensor:
        ranges = self._spans[group]
        if len(ranges) == 1:
            return obs[..., ranges[0][0] : ranges[0][1]]
        return torch.cat([obs[..., a:b] for a, b in ranges], dim=-1)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        """Encode each observation group, concatenate the codes and embed them."""
        parts = [getattr(self, f"{g}_encoder")(self._take(obs, g)) for g in self.groups]
        return self.embedding_encoder(torch.cat(parts, dim=-1))


# --------------------------------------------------------------------------- distribution
def gaussian_log_prob(actions: torch.Tensor, mean: torch.Tensor, log_std: torch.Tensor) -> torch.Tensor:
    """Diagonal Gaussian log-density (B,) of actions (B, A).

    ``log N(a; mu, sigma) = sum_i -(a_i - mu_i)^2 / (2 sigma_i^2) - log sigma_i - log sqrt(2 pi)``.
    """
    z = (actions - mean) * torch.exp(-log_std)
    return (-0.5 * z.square() - log_std - _LOG_SQRT_2PI).sum(-1)


def gaussian_entropy(log_std: torch.Tensor, batch: int) -> torch.Tensor:
    """``sum_i 1/2 + log sqrt(2 pi) + log sigma_i`` repeated for ``batch`` rows; (B,)."""
    return (0.5 + _LOG_SQRT_2PI + log_std).sum(-1).expand(batch)


# --------------------------------------------------------------------------- actor-critic
class ActorCritic(nn.Module):
    """Gaussian actor and value critic over a flat observation; see the module docstring.

    Args:
        obs_dim: D, length of one observation.
        action_dim: A, length of one action (the motion model's latent size).
        cfg: network settings.
        layout: the env's observation layout (name -> [start, stop)), or None for one group.
    """

    def __init__(self, obs_dim: int, action_dim: int, cfg: PolicyConfig | None = None,
                 layout: Mapping[str, Any] | None = None):
        super().__init__()
        cfg = cfg or PolicyConfig()
        cfg.validate()
        self.cfg, self.obs_dim, self.action_dim = cfg, int(obs_dim), int(action_dim)
        self.layout = plain_layout(layout)
        self.obs_normalizer = RunningNormalizer(obs_dim, cfg.obs_norm_clip) if cfg.obs_norm else None
        if cfg.architecture == "dart":
            self.trunk = GroupEncoder(group_layout(layout, obs_dim), cfg.latent_dim)
            self.actor = ResidualHead(cfg.latent_dim, cfg.n_blocks, action_dim)
            self.critic = ResidualHead(cfg.latent_dim, cfg.n_blocks, 1)
        else:
            self.trunk = nn.Identity()
            self.actor = MLPHead(obs_dim, cfg.mlp_hidden, action_dim)
            self.critic = MLPHead(obs_dim, cfg.mlp_hidden, 1)
        self.actor_logstd = nn.Parameter(torch.full((1, action_dim), float(cfg.log_std_init)))
        if cfg.use_zero_init:
            self._zero_init_actor()

    def _zero_init_actor(self) -> None:
        """DART's ``use_zero_init``: every actor Linear gets bias 0 and weight x 0.01, so mean ~ 0 at start."""
        with torch.no_grad():
            for m in self.actor.modules():
                if isinstance(m, nn.Linear):
                    m.weight.mul_(0.01)
                    m.bias.zero_()

    # ------------------------------------------------------------------ pieces
    @property
    def log_std(self) -> torch.Tensor:
        """(1, A) log standard deviation clamped to ``cfg.log_std_bounds`` (DART clamps to [-1, 1])."""
        low, high = self.cfg.log_std_bounds
        return self.actor_logstd.clamp(low, high)

    def normalize(self, obs: torch.Tensor) -> torch.Tensor:
        """Apply the running normalizer (identity when ``obs_norm`` is off); never updates it."""
        return obs if self.obs_normalizer is None else self.obs_normalizer(obs)

    def update_normalizer(self, obs: torch.Tensor) -> None:
        """Fold observations (..., D) into the normalizer statistics (trainers only; no-op without one)."""
        if self.obs_normalizer is not None:
            self.obs_normalizer.update(obs)

    def forward(self, obs: torch.Tensor) -> PolicyOutput:
        """Mean (B, A), clamped log-std (1, A) and value (B,) for raw observations (B, D)."""
        emb = self.trunk(self.normalize(obs))
        mean = self.cfg.action_scale * torch.tanh(self.actor(emb))
        return PolicyOutput(mean, self.log_std, self.critic(emb).squeeze(-1))

    def value(self, obs: torch.Tensor) -> torch.Tensor:
        """State value (B,) of raw observations (B, D), skipping the actor."""
        return self.critic(self.trunk(self.normalize(obs))).squeeze(-1)

    # ------------------------------------------------------------------ PPO verbs
    def act(self, obs: torch.Tensor, deterministic: bool = False) -> PolicyStep:
        """Sample ``a = mean + std * eps`` (or take the mean) for raw observations (B, D)."""
        out = self(obs)
        if deterministic:
            action = out.mean
        else:
            action = out.mean + torch.exp(out.log_std) * torch.randn_like(out.mean)
        return PolicyStep(action, gaussian_log_prob(action, out.mean, out.log_std), out.value)

    def evaluate(self, obs: torch.Tensor, actions: torch.Tensor) -> ActionEvaluation:
        """Log-prob, entropy and value of stored ``actions`` (B, A) under the current parameters."""
        out = self(obs)
        return ActionEvaluation(gaussian_log_prob(actions, out.mean, out.log_std),
                                gaussian_entropy(out.log_std, obs.shape[0]), out.value)

    # ------------------------------------------------------------------ persistence
    def spec(self) -> dict:
        """Everything needed to rebuild this network: plain data for checkpoints."""
        from latentrl.config import to_dict

        return {"obs_dim": self.obs_dim, "action_dim": self.action_dim, "layout": self.layout,
                "config": to_dict(self.cfg)}

    @classmethod
    def from_spec(cls, spec: Mapping[str, Any]) -> ActorCritic:
        """Rebuild an (untrained) network from :meth:`spec` output."""
        cfg = dict(spec["config"])
        unknown = sorted(set(cfg) - set(PolicyConfig.__dataclass_fields__))
        if unknown:
            raise CheckpointError(f"policy_spec has fields this latentrl does not know: {unknown} "
                                  "(written by a newer version?)")
        cfg["log_std_bounds"] = tuple(cfg["log_std_bounds"])
        cfg["mlp_hidden"] = list(cfg["mlp_hidden"])
        return cls(spec["obs_dim"], spec["action_dim"], PolicyConfig(**cfg), spec.get("layout"))
