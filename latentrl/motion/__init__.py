"""The frozen DART motion model: representation, networks, diffusion, rollout and checkpoints."""

from latentrl.motion.checkpoint import load_motion_model, save_motion_model
from latentrl.motion.rollout import MotionModel, PrimitiveSample, Rollout, RolloutState, StepResult

__all__ = [
    "MotionModel",
    "PrimitiveSample",
    "Rollout",
    "RolloutState",
    "StepResult",
    "load_motion_model",
    "save_motion_model",
]
