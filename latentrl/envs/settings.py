"""``StepSettings``: how one env step drives the motion model, the one object every reader of it shares.

A policy only works with the motion stepped as in its training, so these values travel with it: the
training config's ``env`` section holds them (``env.guidance_scale``, ``env.foot_lock``, ...), checkpoints
store that section, and the env, ``latentrl eval``, ``latentrl play`` and ``latentrl export onnx`` all
read them through :meth:`StepSettings.of` and check them with :meth:`StepSettings.validate`. A checkpoint
written before a field existed gets the field's default.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from latentrl.config import require
from latentrl.constants import ACTION_BOUND, GUIDANCE_SCALE, MAX_GUIDANCE
from latentrl.errors import ConfigError
from latentrl.motion.rollout import AMP_DTYPES, LOCK_MIN_WEIGHT, amp_problem, lock_min_weight_problem


@dataclass
class StepSettings:
    """The per-step settings of the motion: guidance, action bound, foot lock and autocast."""

    guidance_scale: float = GUIDANCE_SCALE
    """Classifier-free guidance of the sampler (DART 5)."""
    action_bound: float = ACTION_BOUND
    """Actions are clamped to +/- this before they become the sampler's noise (DART's 4)."""
    foot_lock: bool = False
    """Keep planted feet from sliding (docs/motion.md, "Foot lock")."""
    foot_lock_min_weight: float = LOCK_MIN_WEIGHT
    """With ``foot_lock``: the summed contact weight from which a foot is pinned fully."""
    amp: str | None = None
    """Autocast dtype of the sampler and decoder: 'bf16', 'fp16' or None (float32)."""

    def validate(self) -> None:
        """One ``ConfigError`` line naming the first field out of range."""
        require(math.isfinite(self.guidance_scale) and abs(self.guidance_scale) <= MAX_GUIDANCE, "guidance_scale",
                f"must be a finite number in [-{MAX_GUIDANCE:g}, {MAX_GUIDANCE:g}], got {self.guidance_scale}")
        require(self.action_bound > 0 and math.isfinite(self.action_bound), "action_bound",
                f"must be > 0, got {self.action_bound}")
        problem = lock_min_weight_problem(self.foot_lock_min_weight)
        require(problem is None, "foot_lock_min_weight", str(problem))
        problem = amp_problem(self.amp)
        require(problem is None, "amp", str(problem))

    def set_autocast(self, motion: Any) -> None:
        """Make ``motion`` sample in :attr:`amp` (its ``amp_dtype``; a model shared with other envs does so there too).

        None leaves the model's own setting (float32 unless changed).
        """
        if self.amp is not None:
            if not hasattr(motion, "amp_dtype"):
                raise ConfigError(f"amp: the motion model ({type(motion).__name__}) has no amp_dtype to set")
            motion.amp_dtype = AMP_DTYPES[self.amp]

    def step_kwargs(self) -> dict[str, Any]:
        """The env constructor's arguments of these settings."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(StepSettings)}

    def step_settings(self) -> StepSettings:
        """A plain :class:`StepSettings` of these values (from a subclass such as the evaluation's settings)."""
        return StepSettings(**self.step_kwargs())

    @classmethod
    def of(cls, source: Any) -> StepSettings:
        """The settings of an ``EnvConfig``, of a stored config's ``env`` mapping, or the defaults for None.

        Fields the source lacks (a checkpoint older than the field) take their defaults.
        """
        get = source.get if isinstance(source, Mapping) else lambda name, default: getattr(source, name, default)
        out = StepSettings()
        if source is not None:
            out = StepSettings(**{f.name: _typed(f.name, get(f.name, getattr(out, f.name)))
                                  for f in dataclasses.fields(StepSettings)})
        return out


def _typed(name: str, value: Any) -> Any:
    if name == "foot_lock":
        return bool(value)
    if name == "amp":
        return None if value is None else str(value)
    return float(value)
