"""``MotionPrior``: what the envs (and the evaluation) need of a frozen motion model.

A latent-action env samples one motion primitive per step from noise it is handed, so it needs
only the calls below. :class:`~latentrl.motion.MotionModel` (DART's VAE + latent diffusion) is the
one implementation; another architecture fits the envs by providing the same members, without
the envs changing.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Protocol, runtime_checkable

import torch

from latentrl.errors import ConfigError
from latentrl.motion.rollout import RolloutState, StepResult, Terrain


@runtime_checkable
class MotionPrior(Protocol):
    """A text-conditioned generator of 8-frame motion primitives whose input noise is the RL action."""

    seed_history: torch.Tensor | None
    """(K, 2, 276) canonical seed histories episodes start from (None: the model cannot start episodes)."""
    pelvis_delta: torch.Tensor | None
    """(3,) rest pelvis offset used to place features in the world."""
    mean: torch.Tensor | None
    """(276,) mean of the motion data's features, or None; with :attr:`std`, the envs' divergence check
    ends an episode whose history leaves the data's range (:mod:`latentrl.envs.divergence`)."""
    std: torch.Tensor | None
    """(276,) standard deviation of the motion data's features, or None (see :attr:`mean`)."""

    @property
    def device(self) -> torch.device:
        """Where the prior computes."""
        ...

    @property
    def latent_shape(self) -> tuple[int, int]:
        """Shape of one primitive's noise (the action, flattened, has ``latent_dim`` values)."""
        ...

    @property
    def latent_dim(self) -> int:
        """D, the number of values of one action: the product of :attr:`latent_shape`."""
        ...

    def to(self, device: str | torch.device) -> MotionPrior:
        """The prior on ``device`` (in place for torch modules)."""
        ...

    def encode_text(self, texts: Sequence[str]) -> torch.Tensor:
        """(len(texts), E) text embeddings."""
        ...

    def initial_state(self, batch: int, generator: torch.Generator | None = None,
                      seed_index: torch.Tensor | None = None) -> RolloutState:
        """Start states of ``batch`` rollouts (a seed history each, the world at the origin)."""
        ...

    def prepare_compile(self) -> None:
        """Build every tensor the model would cache lazily while sampling, now.

        Why: a ``torch.compile``-d env step guards on such caches; one filled inside the graph would
        recompile the whole step on the next call. A model without caches does nothing.
        """
        ...

    def rollout_step(self, state: RolloutState, text_embedding: torch.Tensor, noise: torch.Tensor,
                     guidance_scale: float | torch.Tensor = ..., sampler: str = "ddim",
                     generator: torch.Generator | None = None, foot_lock: bool | None = None,
                     lock_min_weight: float = ..., terrain: Terrain | None = None) -> StepResult:
        """One primitive from ``noise`` (B, *latent_shape) for every rollout, placed in the world.

        ``foot_lock``: keep planted feet from sliding (None: the model's default, off); ``lock_min_weight``:
        the contact weight from which the lock pins a foot fully; ``terrain``: anything with a batched
        ``height(xy) -> z`` to place the motion on (envs pass it only with a scene, so a prior may omit it).
        """
        ...


def load_prior(motion: str | os.PathLike | MotionPrior, device: str | torch.device) -> MotionPrior:
    """A prior that can start episodes: a loaded one moved to ``device``, or a model file or name loaded there.

    Refuses one without ``seed_history`` or ``pelvis_delta`` (episodes start from its seeds).
    """
    from latentrl.motion.checkpoint import load_motion_model  # torch-heavy: only when a file or name is given

    if isinstance(motion, (str, os.PathLike)):
        model = load_motion_model(motion, device=device)
    else:
        model = motion.to(device)
    if model.seed_history is None or model.pelvis_delta is None:
        raise ConfigError("motion: the model has no seed history/pelvis_delta, so episodes cannot start; "
                          "load it with seed_history=... (docs/motion.md)")
    return model
