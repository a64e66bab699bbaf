"""The frozen DART motion model: representation, networks, diffusion, rollout and checkpoints.

The runtime only: training lives in :mod:`latentrl.motion_training`. Envs depend on :class:`MotionPrior`.
"""

from latentrl.motion.checkpoint import load_motion_model, save_motion_model
from latentrl.motion.prior import MotionPrior
from latentrl.motion.rollout import MotionModel, PrimitiveSample, Rollout, RolloutState, StepResult

__all__ = [
    "MotionModel",
    "MotionPrior",
    "PrimitiveSample",
    "Rollout",
    "RolloutState",
    "StepResult",
    "load_motion_model",
    "save_motion_model",
]
