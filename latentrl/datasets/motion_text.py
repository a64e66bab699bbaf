"""The on-disk motion-text format: a folder of ``.npz`` sequences plus an optional ``meta.json``.

Each sequence file holds (T frames at 30 fps, S text segments; world frame: metres, z up, floor z = 0):

========================  =================  =========================================================
field                     dtype, shape       meaning
========================  =================  =========================================================
``fps``                   float32 ()         frames per second, 30
``transl``                float32 (T, 3)     root translation; the pelvis is at ``transl + pelvis_delta``
``pelvis_delta``          float32 (3,)       rest pelvis offset, equal to ``rest_joints[0]``
``rest_joints``           float32 (22, 3)    SMPL-22 joints of the rest pose with zero translation
``poses``                 float32 (T, 22, 3) axis-angle; [:, 0] global orientation, [:, j] joint j local
``joints``                float32 (T, 22, 3) world joints = forward kinematics of the above (< 1e-4 m)
``seg_start``             int32 (S,)         first frame of each text segment
``seg_end``               int32 (S,)         one past the last frame of each text segment
``seg_text``              unicode (S,)       segment texts; segments may overlap and cover every frame
``seats`` (optional)      float32 (K, 4)     seats sat on: x, y of the seat point under the seated pelvis,
                                             seat top height (m), facing yaw (rad, counter-clockwise from +x)
``stairs`` (optional)     float32 (J, 8)     stair flights: x, y of the bottom edge's midpoint, climbing
                                             direction (rad from +x), width, riser, tread (m), steps, base z
``foot_floor`` (optional) float32 (T, 2)     terrain height under the left and right foot joints (10, 11)
``reaches`` (optional)    float32 (R, 6)     hand targets: x, y, z, hand (0 left, 1 right), first and last
                                             frame of the hold with the wrist joint on the target
========================  =================  =========================================================

Optional fields (``OPTIONAL_FIELDS``) are scene data: a file without them has none of that kind.

Files load with ``allow_pickle=False``. Every problem is reported as one ``DataError`` line that names the
file, the field and what was expected.
"""

from __future__ import annotations

import json
import os
import tempfile
import zipfile
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from latentrl.errors import DataError
from latentrl.motion.skeleton import FPS, JOINT_NAMES, NUM_JOINTS
from latentrl.safe_io import atomic_write_text

#: Field name -> (dtype kind, shape template) in file order; "T" and "S" are the frame and segment counts.
FIELDS: dict[str, tuple[str, tuple]] = {
    "fps": ("float32", ()),
    "transl": ("float32", ("T", 3)),
    "pelvis_delta": ("float32", (3,)),
    "rest_joints": ("float32", (NUM_JOINTS, 3)),
    "poses": ("float32", ("T", NUM_JOINTS, 3)),
    "joints": ("float32", ("T", NUM_JOINTS, 3)),
    "seg_start": ("int32", ("S",)),
    "seg_end": ("int32", ("S",)),
    "seg_text": ("unicode", ("S",)),
}

#: Scene fields a sequence may carry (same notation); "K" is the number of seats.
OPTIONAL_FIELDS: dict[str, tuple[str, tuple]] = {
    "seats": ("float32", ("K", 4)),
    "stairs": ("float32", ("J", 8)),
    "foot_floor": ("float32", ("T", 2)),
    "reaches": ("float32", ("R", 6)),
}

#: Largest allowed distance (m) between stored ``joints`` and the forward kinematics of the stored pose.
FK_TOLERANCE_M = 1e-4

META_FILE = "meta.json"


def _shape_text(template: tuple) -> str:
    return "(" + ", ".join(str(d) for d in template) + ("," if len(template) == 1 else "") + ")"


def _check_field(name: str, field: str, value: np.ndarray, sizes: dict[str, int]) -> None:
    """Dtype, shape (binding T/S on first sight) and finiteness of one field."""
    kind, template = FIELDS[field] if field in FIELDS else OPTIONAL_FIELDS[field]
    if kind == "unicode":
        if value.dtype.kind != "U":
            raise DataError(f"{name}: field '{field}' has dtype {value.dtype}, expected unicode strings")
    elif value.dtype != np.dtype(kind):
        raise DataError(f"{name}: field '{field}' has dtype {value.dtype}, expected {kind}")
    symbolic = [d for d in template if isinstance(d, str)]
    for axis, dim in enumerate(template):
        if isinstance(dim, str) and dim not in sizes and value.ndim == len(template):
            sizes[dim] = value.shape[axis]
    expected = tuple(sizes.get(d, d) if isinstance(d, str) else d for d in template)
    if value.shape != expected:
        bound = ", ".join(f"{d} = {sizes[d]}" for d in dict.fromkeys(symbolic) if d in sizes)
        raise DataError(
            f"{name}: field '{field}' has shape {value.shape}, expected {_shape_text(template)}"
            + (f" with {bound}" if bound else "")
        )
    if kind == "float32" and not np.all(np.isfinite(value)):
        raise DataError(f"{name}: field '{field}' contains NaN or infinite values")


def _check_segments(name: str, seq: Mapping, num_frames: int) -> None:
    """Segment bounds, texts and coverage of every frame."""
    start, end, text = seq["seg_start"], seq["seg_end"], seq["seg_text"]
    if len(start) == 0:
        raise DataError(f"{name}: field 'seg_start' is empty, expected at least one text segment")
    bad = np.flatnonzero((start < 0) | (end > num_frames) | (start >= end))
    if bad.size:
        i = int(bad[0])
        raise DataError(
            f"{name}: segment {i} has seg_start = {int(start[i])}, seg_end = {int(end[i])}, "
            f"expected 0 <= seg_start < seg_end <= T = {num_frames}"
        )
    empty = [i for i, t in enumerate(text) if not str(t).strip()]
    if empty:
        raise DataError(f"{name}: field 'seg_text' entry {empty[0]} is empty, expected a text label")
    covered = np.zeros(num_frames + 1, dtype=np.int64)
    np.add.at(covered, start, 1)
    np.add.at(covered, end, -1)
    missing = np.flatnonzero(np.cumsum(covered)[:num_frames] == 0)
    if missing.size:
        breaks = np.flatnonzero(np.diff(missing) != 1)
        last = int(missing[breaks[0]] if breaks.size else missing[-1])
        raise DataError(
            f"{name}: fields 'seg_start'/'seg_end' leave frames {int(missing[0])}-{last} "
            "without a text segment, expected every frame to be covered"
        )


def _check_kinematics(name: str, seq: Mapping) -> None:
    """``pelvis_delta`` equals ``rest_joints[0]`` and ``joints`` equals forward kinematics of the pose.

    Uses the numpy twins of ``latentrl.motion.skeleton.forward_kinematics`` (equal to float64 precision, see
    tests/datasets/test_locomotion.py), which avoid torch's per-call overhead when checking many files.
    """
    from latentrl.datasets.body import axis_angle_to_matrix_np, forward_kinematics_np

    rest = seq["rest_joints"].astype(np.float64)
    if np.max(np.abs(seq["pelvis_delta"] - rest[0])) > 1e-6:
        raise DataError(
            f"{name}: field 'pelvis_delta' = {np.round(seq['pelvis_delta'], 4).tolist()} differs from "
            f"rest_joints[0] = {np.round(rest[0], 4).tolist()}, expected them equal"
        )
    rot = axis_angle_to_matrix_np(seq["poses"].astype(np.float64))
    fk = forward_kinematics_np(rest, rot, seq["transl"].astype(np.float64))
    err = np.linalg.norm(fk - seq["joints"].astype(np.float64), axis=-1)
    if err.size and err.max() > FK_TOLERANCE_M:
        frame, joint = np.unravel_index(int(np.argmax(err)), err.shape)
        raise DataError(
            f"{name}: field 'joints' differs from forward kinematics of rest_joints/poses/transl by "
            f"{err.max():.4g} m at frame {frame}, joint '{JOINT_NAMES[joint]}', expected < {FK_TOLERANCE_M} m"
        )


def make_sequence(rest_joints: np.ndarray, poses: np.ndarray, transl: np.ndarray,
                  segments: list[tuple[int, int, str]]) -> dict[str, np.ndarray]:
    """A sequence in this format from a pose: rest joints (22, 3), axis-angle poses (T, 22, 3), transl (T, 3).

    ``joints`` is the forward kinematics of the values *as stored* (float32), so a reader's check
    (``validate_sequence``) reproduces them exactly. ``segments`` are ``(start, end, text)`` frames.
    """
    from latentrl.datasets.body import axis_angle_to_matrix_np, forward_kinematics_np

    rest = np.asarray(rest_joints).astype(np.float32)
    poses = np.asarray(poses).astype(np.float32)
    transl = np.asarray(transl).astype(np.float32)
    joints = forward_kinematics_np(rest.astype(np.float64), axis_angle_to_matrix_np(poses.astype(np.float64)),
                                   transl.astype(np.float64))
    return {
        "fps": np.array(FPS, dtype=np.float32),
        "transl": transl,
        "pelvis_delta": rest[0].copy(),
        "rest_joints": rest,
        "poses": poses,
        "joints": joints.astype(np.float32),
        "seg_start": np.array([s[0] for s in segments], dtype=np.int32),
        "seg_end": np.array([s[1] for s in segments], dtype=np.int32),
        "seg_text": np.array([s[2] for s in segments], dtype=str),
    }


def validate_sequence(seq: Mapping, name: str, check_fk: bool = True) -> None:
    """Raise ``DataError`` unless ``seq`` holds every field with the exact dtype and shape of the format.

    Args:
        seq: field name -> numpy array (as loaded from a file or produced by a generator).
        name: file name used in messages, e.g. ``"walk_0003.npz"``.
        check_fk: also check ``joints`` against forward kinematics (a few ms per thousand frames).
    """
    missing = [f for f in FIELDS if f not in seq]
    if missing:
        raise DataError(f"{name}: missing field '{missing[0]}', expected fields {', '.join(FIELDS)}")
    sizes: dict[str, int] = {}
    for field in FIELDS:
        value = seq[field]
        if not isinstance(value, np.ndarray):
            raise DataError(f"{name}: field '{field}' is a {type(value).__name__}, expected a numpy array")
        _check_field(name, field, value, sizes)
    for field in OPTIONAL_FIELDS:
        if field in seq:
            if not isinstance(seq[field], np.ndarray):
                raise DataError(f"{name}: field '{field}' is a {type(seq[field]).__name__}, expected a numpy array")
            _check_field(name, field, seq[field], sizes)
    fps = float(seq["fps"])
    if fps != FPS:
        raise DataError(f"{name}: field 'fps' is {fps:g}, expected {FPS}")
    if sizes["T"] < 1:
        raise DataError(f"{name}: field 'transl' has no frames, expected T >= 1")
    _check_segments(name, seq, sizes["T"])
    if check_fk:
        _check_kinematics(name, seq)


def _canonical(seq: Mapping) -> dict[str, np.ndarray]:
    """Cast each field to its format dtype (texts to fixed-width unicode); values are left unchanged."""
    out = {}
    for field, (kind, _) in (FIELDS | OPTIONAL_FIELDS).items():
        value = np.asarray(seq[field]) if field in seq else None
        if value is None:
            continue
        out[field] = value.astype(str) if kind == "unicode" else value.astype(kind)
    return out


def write_sequence(path: str | os.PathLike, seq: Mapping, check_fk: bool = True) -> Path:
    """Validate ``seq`` (after casting to the format dtypes) and write it atomically to ``path`` (.npz)."""
    path = Path(path)
    data = _canonical(seq)
    validate_sequence(data if all(f in data for f in FIELDS) else seq, path.name, check_fk=check_fk)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=path.name, suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            np.savez_compressed(handle, **data)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def read_sequence(path: str | os.PathLike, check_fk: bool = True) -> dict[str, np.ndarray]:
    """Load and validate one sequence file; returns field name -> array (unknown fields dropped).

    Known fields are those of ``FIELDS`` and ``OPTIONAL_FIELDS``.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: file not found, expected a motion-text .npz file")
    if not zipfile.is_zipfile(path):  # np.load would otherwise try to unpickle it
        raise DataError(f"{path.name}: cannot read as .npz (not a zip archive), expected a numpy .npz archive")
    try:
        with np.load(path, allow_pickle=False) as npz:
            seq = {}
            for field in (*FIELDS, *OPTIONAL_FIELDS):
                if field in npz.files:
                    seq[field] = npz[field]
    except ValueError as exc:  # object arrays need pickle, which we refuse
        raise DataError(f"{path.name}: {exc}; expected plain numeric and unicode arrays only") from None
    except (OSError, zipfile.BadZipFile, EOFError) as exc:
        raise DataError(f"{path.name}: cannot read as .npz ({exc}), expected a numpy .npz archive") from None
    validate_sequence(seq, path.name, check_fk=check_fk)
    return seq


def list_dataset(folder: str | os.PathLike) -> list[Path]:
    """Sorted ``.npz`` files of a dataset folder; raises ``DataError`` if the folder is missing or empty."""
    folder = Path(folder)
    if not folder.is_dir():
        raise DataError(f"{folder}: dataset folder not found, expected a folder of .npz sequences")
    files = sorted(p for p in folder.iterdir() if p.suffix == ".npz" and p.is_file())
    if not files:
        raise DataError(f"{folder}: no .npz sequences found, expected at least one")
    return files


def write_meta(folder: str | os.PathLike, meta: Mapping) -> Path:
    """Write ``meta.json`` (name, generator settings, seed, licence, frame counts...) into ``folder``."""
    return atomic_write_text(Path(folder) / META_FILE, json.dumps(meta, indent=2, sort_keys=False) + "\n")


def read_meta(folder: str | os.PathLike) -> dict | None:
    """The folder's ``meta.json`` as a dict, or ``None`` if it has none (the file is optional)."""
    path = Path(folder) / META_FILE
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise DataError(f"{path}: invalid JSON ({exc.msg} at line {exc.lineno}), expected a JSON object") from None
