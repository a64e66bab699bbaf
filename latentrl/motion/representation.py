"""DART's 276-D motion frame: named slices, feature computation and mean/std normalization.

Frame layout (``PrimitiveUtility.motion_repr`` order in DART's ``utils/smpl_utils.py``):

=========  =========================  ==============================================
slice      name                       meaning
=========  =========================  ==============================================
0:3        transl                     root translation (SMPL ``transl``, *not* the pelvis)
3:135      poses_6d                   22 x 6D: global orientation, then 21 body joints
135:138    transl_delta               transl[t+1] - transl[t]
138:144    global_orient_delta_6d     R[t+1] R[t]^T in 6D
144:210    joints                     22 x 3 joint positions (metres)
210:276    joints_delta               J[t+1] - J[t]
=========  =========================  ==============================================

6D rotations are the first two rows of the matrix (pytorch3d's ``matrix_to_rotation_6d``).
The diffusion model works on normalized features ``(x - mean) / std``; the RL observation and
every world-space computation use unnormalized ones.
"""

from __future__ import annotations

from typing import NamedTuple

import torch

from latentrl.motion.rotations import matrix_to_rotation_6d
from latentrl.motion.skeleton import NUM_JOINTS

FEATURE_DIM = 276
HISTORY_LENGTH = 2
FUTURE_LENGTH = 8
PRIMITIVE_LENGTH = HISTORY_LENGTH + FUTURE_LENGTH

#: Named slices of a frame vector, in storage order.
SLICES: dict[str, slice] = {
    "transl": slice(0, 3),
    "poses_6d": slice(3, 135),
    "transl_delta": slice(135, 138),
    "global_orient_delta_6d": slice(138, 144),
    "joints": slice(144, 210),
    "joints_delta": slice(210, 276),
}
FEATURE_ORDER: tuple[str, ...] = tuple(SLICES)


class Frames(NamedTuple):
    """A frame tensor split into its named parts; every field keeps the leading dims ``(...)``."""

    transl: torch.Tensor  # (..., 3)
    poses_6d: torch.Tensor  # (..., 22, 6)
    transl_delta: torch.Tensor  # (..., 3)
    global_orient_delta_6d: torch.Tensor  # (..., 6)
    joints: torch.Tensor  # (..., 22, 3)
    joints_delta: torch.Tensor  # (..., 22, 3)


def split_frames(x: torch.Tensor) -> Frames:
    """(..., 276) -> :class:`Frames` (views where possible)."""
    if x.shape[-1] != FEATURE_DIM:
        raise ValueError(f"motion features must have {FEATURE_DIM} values per frame, got shape {tuple(x.shape)}")
    lead = x.shape[:-1]
    return Frames(
        transl=x[..., SLICES["transl"]],
        poses_6d=x[..., SLICES["poses_6d"]].reshape(*lead, NUM_JOINTS, 6),
        transl_delta=x[..., SLICES["transl_delta"]],
        global_orient_delta_6d=x[..., SLICES["global_orient_delta_6d"]],
        joints=x[..., SLICES["joints"]].reshape(*lead, NUM_JOINTS, 3),
        joints_delta=x[..., SLICES["joints_delta"]].reshape(*lead, NUM_JOINTS, 3),
    )


def join_frames(frames: Frames) -> torch.Tensor:
    """Inverse of :func:`split_frames`: :class:`Frames` -> (..., 276)."""
    lead = frames.transl.shape[:-1]
    return torch.cat(
        (
            frames.transl,
            frames.poses_6d.reshape(*lead, NUM_JOINTS * 6),
            frames.transl_delta,
            frames.global_orient_delta_6d,
            frames.joints.reshape(*lead, NUM_JOINTS * 3),
            frames.joints_delta.reshape(*lead, NUM_JOINTS * 3),
        ),
        dim=-1,
    )


def joints_of(x: torch.Tensor) -> torch.Tensor:
    """(..., 276) -> (..., 22, 3) joint positions, a cheap view used on hot paths."""
    return x[..., SLICES["joints"]].unflatten(-1, (NUM_JOINTS, 3))


def compute_features(transl: torch.Tensor, rotations: torch.Tensor, joints: torch.Tensor) -> torch.Tensor:
    """Frame features from a motion clip, as DART's dataset computes them.

    Args:
        transl: (..., T+1, 3) root translation, metres.
        rotations: (..., T+1, 22, 3, 3) rotation matrices, entry 0 the global orientation and
            entries 1..21 the parent-relative body joint rotations.
        joints: (..., T+1, 22, 3) joint positions, metres, same frame as ``transl``.

    Returns:
        (..., T, 276): one frame per input frame but the last, which only supplies the forward
        differences (DART loads H + F + 1 frames for the same reason).
    """
    glob = rotations[..., 0, :, :]
    orient_delta = glob[..., 1:, :, :] @ glob[..., :-1, :, :].transpose(-1, -2)
    frames = Frames(
        transl=transl[..., :-1, :],
        poses_6d=matrix_to_rotation_6d(rotations[..., :-1, :, :, :]),
        transl_delta=transl[..., 1:, :] - transl[..., :-1, :],
        global_orient_delta_6d=matrix_to_rotation_6d(orient_delta),
        joints=joints[..., :-1, :, :],
        joints_delta=joints[..., 1:, :, :] - joints[..., :-1, :, :],
    )
    return join_frames(frames)


class Normalizer:
    """Per-dimension mean/std normalization of 276-D frames (DART's ``normalize``/``denormalize``).

    ``mean`` and ``std`` are stored as (276,) float32 tensors and broadcast over any leading dims.
    """

    def __init__(self, mean: torch.Tensor, std: torch.Tensor):
        mean = torch.as_tensor(mean, dtype=torch.float32).reshape(-1)
        std = torch.as_tensor(std, dtype=torch.float32).reshape(-1)
        if mean.numel() != FEATURE_DIM or std.numel() != FEATURE_DIM:
            raise ValueError(f"mean/std must have {FEATURE_DIM} values, got {mean.numel()} and {std.numel()}")
        if not torch.isfinite(mean).all() or not torch.isfinite(std).all() or (std <= 0).any():
            raise ValueError("mean/std must be finite and std strictly positive")
        self.mean = mean
        self.std = std

    def to(self, device: torch.device | str) -> Normalizer:
        """Move the statistics to ``device`` (in place; returns self)."""
        self.mean = self.mean.to(device)
        self.std = self.std.to(device)
        return self

    def normalize(self, x: torch.Tensor) -> torch.Tensor:
        """(..., 276) unnormalized -> normalized."""
        return (x - self.mean) / self.std

    def denormalize(self, x: torch.Tensor) -> torch.Tensor:
        """(..., 276) normalized -> unnormalized."""
        return x * self.std + self.mean

    @classmethod
    def from_data(cls, frames: torch.Tensor, min_std: float = 1e-4) -> Normalizer:
        """Statistics of (N, 276) frames; ``min_std`` keeps constant dimensions from exploding."""
        frames = frames.reshape(-1, FEATURE_DIM).double()
        return cls(frames.mean(0).float(), frames.std(0).clamp(min=min_std).float())

    @classmethod
    def from_legacy_dict(cls, stats: dict) -> Normalizer:
        """DART's legacy ``mean_std.pkl`` form: ``{feature_name: {'mean': ..., 'std': ...}}``."""
        missing = [k for k in FEATURE_ORDER if k not in stats]
        if missing:
            raise ValueError(f"legacy mean/std dict lacks {missing}; expected keys {list(FEATURE_ORDER)}")
        mean = torch.cat([torch.as_tensor(stats[k]["mean"], dtype=torch.float32).reshape(-1) for k in FEATURE_ORDER])
        std = torch.cat([torch.as_tensor(stats[k]["std"], dtype=torch.float32).reshape(-1) for k in FEATURE_ORDER])
        return cls(mean, std)
