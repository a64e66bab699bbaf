"""Seed histories: the two canonical frames every episode and rollout starts from.

DART builds its reset seed from ``data/stand.pkl`` through the SMPL-X body model, which latentrl
cannot ship. A model loaded from an official DART download therefore gets its seed, in order, from:

1. ``seed_history=`` / ``env.seed_history`` (a file, see :func:`load_seed_file`);
2. ``<layout root>/seed_history.npz`` beside the download;
3. **the mean pose of the model's own normalizer** (:func:`mean_pose_seed`, the default).

The mean pose needs nothing but the ``mean_std_h2_f8.pkl`` every DART download carries. DART's
mean is taken over canonical primitives of its training motion, which is mostly standing and
walking, so the mean frame is a neutral upright pose facing +y. The averaged 6D rotations are made
orthonormal again, the frame is repeated so every velocity is zero, the result is canonicalized
(pelvis at the origin, hips along x), and the env puts its lowest joint on the floor at reset.
``pelvis_delta`` (the rest pelvis offset, ``pelvis = transl + pelvis_delta``) is a constant of
the body, so the difference of the means, ``mean(joints[0]) - mean(transl)``, is exactly it.
"""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np
import torch

from latentrl.errors import CheckpointError
from latentrl.motion.canonical import canonicalize
from latentrl.motion.representation import FEATURE_DIM, HISTORY_LENGTH, NUM_JOINTS, SLICES, compute_features
from latentrl.motion.rotations import rotation_6d_to_matrix

SEED_KEYS = ("seed_history", "history")
"""Arrays of a seed ``.npz`` read as (K, 2, 276) canonical, unnormalized histories."""


def mean_pose_seed(mean: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """``(seed (1, 2, 276), pelvis_delta (3,))``: the motionless mean pose of a (276,) feature mean."""
    mean = torch.as_tensor(mean, dtype=torch.float32).reshape(-1, FEATURE_DIM)[0].cpu()
    joints = mean[SLICES["joints"]].reshape(NUM_JOINTS, 3)
    transl = mean[SLICES["transl"]]
    pelvis_delta = joints[0] - transl
    rotations = rotation_6d_to_matrix(mean[SLICES["poses_6d"]].reshape(NUM_JOINTS, 6))
    frames = HISTORY_LENGTH + 1  # one more for the forward differences, which come out zero
    feats = compute_features(transl.expand(frames, 3), rotations.expand(frames, NUM_JOINTS, 3, 3),
                             joints.expand(frames, NUM_JOINTS, 3))
    if not bool(torch.isfinite(feats).all()):
        raise CheckpointError("the model's mean/std gives no usable mean pose; pass a seed history "
                              "(env.seed_history / --seed-history, docs/motion.md)")
    seed, _, _ = canonicalize(feats[None], pelvis_delta)
    return seed, pelvis_delta


def load_seed_file(path: str | Path) -> torch.Tensor:
    """(K, 2, 276) canonical seed histories from a ``.npz``.

    Accepted contents: ``seed_history`` or ``history`` of shape (K, 2, 276) or (2, 276), canonical
    and unnormalized; or a motion ``.npz`` as latentrl writes it (``features`` (T, 276) in world
    coordinates, T >= 2), whose first two frames become one seed.
    """
    path = Path(path).expanduser()
    if not path.is_file():
        raise CheckpointError(f"seed history file not found: {path}")
    try:
        with np.load(path, allow_pickle=False) as z:
            key = next((k for k in SEED_KEYS if k in z), None)
            if key is not None:
                return _checked(torch.from_numpy(np.asarray(z[key], dtype=np.float32)), path)
            if "features" in z:
                return _from_world(torch.from_numpy(np.asarray(z["features"], dtype=np.float32)), path)
            names = ", ".join(z.files) or "none"
    except (ValueError, OSError, EOFError, KeyError, TypeError, zipfile.BadZipFile) as exc:  # pickles, junk
        raise CheckpointError(f"{path}: not a readable seed-history .npz (numeric arrays only): "
                              f"{str(exc)[:160]}") from None
    raise CheckpointError(f"{path}: no 'seed_history' (K, 2, 276) or 'features' (T, 276) array (found: {names})")


def _checked(arr: torch.Tensor, path: Path) -> torch.Tensor:
    if arr.dim() == 2:
        arr = arr[None]
    if arr.dim() != 3 or tuple(arr.shape[1:]) != (HISTORY_LENGTH, FEATURE_DIM) or arr.shape[0] < 1:
        raise CheckpointError(f"{path}: seed history must be (K, {HISTORY_LENGTH}, {FEATURE_DIM}), "
                              f"got {tuple(arr.shape)}")
    if not bool(torch.isfinite(arr).all()):  # a NaN seed makes every rollout NaN
        bad = int((~torch.isfinite(arr)).flatten(1).any(1).sum())
        raise CheckpointError(f"{path}: seed history holds NaN or inf in {bad} of {len(arr)} seeds; "
                              "expected finite (K, 2, 276) canonical features")
    return arr


def _from_world(features: torch.Tensor, path: Path) -> torch.Tensor:
    if features.dim() != 2 or features.shape[1] != FEATURE_DIM or features.shape[0] < HISTORY_LENGTH:
        raise CheckpointError(f"{path}: 'features' must be (T >= {HISTORY_LENGTH}, {FEATURE_DIM}), "
                              f"got {tuple(features.shape)}")
    first = features[None, :HISTORY_LENGTH]
    pelvis_delta = first[0, 0, SLICES["joints"]][:3] - first[0, 0, SLICES["transl"]]
    seed, _, _ = canonicalize(first, pelvis_delta)
    return _checked(seed, path)
