"""Convert AMASS-style SMPL / SMPL-H / SMPL-X sequences with text labels into the motion-text format.

latentrl never ships AMASS data or body-model files (both forbid redistribution). This module converts the
files a user already has:

* **motion**: an AMASS ``.npz`` with ``poses`` (T, 72 | 156 | 165 | 66) axis-angle (global orientation, then
  the body joints; only the first 22 joints are kept), ``trans`` (T, 3), ``mocap_framerate`` or
  ``mocap_frame_rate``, and optionally ``betas`` and ``gender``;
* **labels**: BABEL-style segments ``{"start_t": s, "end_t": s, "proc_label": text}`` (a BABEL entry with
  ``frame_ann`` / ``seq_ann``, or a whole BABEL file keyed by sequence id with ``feat_p``), or a plain list
  ``[{"start": s, "end": s, "text": "walk"}, ...]``; times in seconds;
* **body model** (pluggable): the 22 rest joint positions of the body, either from the ``smplx`` package and
  the user's own model folder (``SmplxBody``, extra ``latentrl[amass]``) or from an array / ``.npz`` / ``.npy``
  the user provides (``RestJointsBody``). Joint positions then come from forward kinematics, which for the
  SMPL family is exact: posed joints are the rigid transform chain applied to the rest joints.

Steps per file: rotations are moved from SMPL's canonical frame (y up, facing +z, body left = +x) into
latentrl's rest frame (z up, facing +y, body right = +x); AMASS worlds are already z up, so only the rest
frame changes. The pelvis is ``trans + J0`` (SMPL's rule, J0 = rest pelvis in SMPL coordinates). Rotations
are resampled to 30 fps by slerp and the pelvis by linear interpolation; label times become frame ranges;
``transl = pelvis - pelvis_delta`` as the format requires. See docs/datasets.md, "Converting AMASS".
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import zipfile
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from latentrl.datasets.body import (
    TOE_HEIGHT_M,
    axis_angle_to_matrix_np,
    forward_kinematics_np,
    matrix_to_axis_angle_np,
)
from latentrl.datasets.motion_text import make_sequence, write_meta, write_sequence
from latentrl.errors import DataError, closest
from latentrl.motion.skeleton import ANKLE_JOINTS, FOOT_JOINTS, FPS, NUM_JOINTS

#: Maps latentrl rest-frame vectors (x right, y forward, z up) to SMPL canonical ones (x left, y up, z forward).
SMPL_FROM_LATENTRL = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])

#: Width of ``poses`` -> body model it comes from; the first 66 columns are always the 22 body joints.
POSE_WIDTHS: dict[int, str] = {66: "SMPL body (22 joints)", 72: "SMPL", 156: "SMPL-H", 165: "SMPL-X"}

#: Label times may run past the end of a sequence by this much (s) and are clipped (BABEL rounds durations).
LABEL_END_TOLERANCE_S = 0.1

_TEXT_KEYS = ("proc_label", "text", "raw_label", "label")
_START_KEYS = ("start_t", "start")
_END_KEYS = ("end_t", "end")


# --- rotations and resampling (numpy, float64) --------------------------------------------------------------


def smpl_rotations_to_latentrl(rot: np.ndarray) -> np.ndarray:
    """(..., 22, 3, 3) SMPL rotations (rest frame: y up, facing +z) -> latentrl ones (z up, facing +y).

    The world frame is kept: the global orientation becomes ``R0 @ C`` and each joint ``C^T @ Rj @ C`` with
    ``C = SMPL_FROM_LATENTRL``, so world joint positions do not change.
    """
    c = SMPL_FROM_LATENTRL
    out = c.T @ rot @ c
    out[..., 0, :, :] = rot[..., 0, :, :] @ c
    return out


def latentrl_rotations_to_smpl(rot: np.ndarray) -> np.ndarray:
    """Inverse of ``smpl_rotations_to_latentrl`` (for exporting latentrl poses to SMPL tools)."""
    c = SMPL_FROM_LATENTRL
    out = c @ rot @ c.T
    out[..., 0, :, :] = rot[..., 0, :, :] @ c.T
    return out


def _interval(src_times: np.ndarray, dst_times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index of the source interval holding each destination time and the fraction (0..1) within it."""
    index = np.clip(np.searchsorted(src_times, dst_times, side="right") - 1, 0, max(len(src_times) - 2, 0))
    if len(src_times) < 2:
        return index, np.zeros(len(dst_times))
    span = src_times[index + 1] - src_times[index]
    frac = np.clip((dst_times - src_times[index]) / np.where(span > 0, span, 1.0), 0.0, 1.0)
    return index, frac


def lerp_resample(values: np.ndarray, src_times: np.ndarray, dst_times: np.ndarray) -> np.ndarray:
    """(T, ...) samples at increasing ``src_times`` -> (T', ...) at ``dst_times`` by linear interpolation."""
    values = np.asarray(values, dtype=np.float64)
    index, frac = _interval(np.asarray(src_times, float), np.asarray(dst_times, float))
    if len(values) < 2:
        return values[index]
    frac = frac.reshape(-1, *([1] * (values.ndim - 1)))
    return values[index] * (1.0 - frac) + values[index + 1] * frac


def slerp_resample(rot: np.ndarray, src_times: np.ndarray, dst_times: np.ndarray) -> np.ndarray:
    """(T, ..., 3, 3) rotations at ``src_times`` -> (T', ..., 3, 3) at ``dst_times`` by slerp.

    Between samples a and b the rotation is ``Ra @ exp(u * log(Ra^T Rb))``: the shortest arc, at constant
    angular speed.
    """
    rot = np.asarray(rot, dtype=np.float64)
    index, frac = _interval(np.asarray(src_times, float), np.asarray(dst_times, float))
    if len(rot) < 2:
        return rot[index]
    start, end = rot[index], rot[index + 1]
    delta = matrix_to_axis_angle_np(np.swapaxes(start, -1, -2) @ end)
    frac = frac.reshape(-1, *([1] * (delta.ndim - 1)))
    return start @ axis_angle_to_matrix_np(delta * frac)


def output_times(num_frames: int, fps: float) -> np.ndarray:
    """Times (s) of the 30 fps frames that fit inside ``num_frames`` samples at ``fps``."""
    duration = (num_frames - 1) / fps
    return np.arange(int(math.floor(duration * FPS + 1e-6)) + 1) / FPS


# --- body models ----------------------------------------------------------------------------------------------


def _detect_frame(joints: np.ndarray, name: str) -> str:
    """'smpl' or 'latentrl' from the pelvis -> head axis and the side of the left hip; DataError otherwise."""
    up = joints[15] - joints[0]
    axis = int(np.argmax(np.abs(up)))
    if axis == 2 and up[2] > 0:
        frame = "latentrl"
    elif axis == 1 and up[1] > 0:
        frame = "smpl"
    else:
        raise DataError(f"{name}: rest joints have the head along {np.round(up, 3).tolist()} from the pelvis, "
                        "expected +z (latentrl frame) or +y (SMPL frame)")
    return frame


def _check_sides(joints: np.ndarray, frame: str, name: str) -> None:
    across = joints[1, 0] - joints[2, 0]  # left hip minus right hip along x
    if (frame == "latentrl" and across >= 0) or (frame == "smpl" and across <= 0):
        want = "-x (latentrl frame: body right = +x)" if frame == "latentrl" else "+x (SMPL frame: body left = +x)"
        raise DataError(f"{name}: rest joint 'left_hip' is at x = {joints[1, 0]:.3f} and 'right_hip' at "
                        f"x = {joints[2, 0]:.3f}, expected the left hip towards {want}")


class RestJointsBody:
    """A body given by its 22 rest joint positions (SMPL joint order), in metres.

    Args:
        rest_joints: (22, 3) array (more rows are cut to 22, e.g. SMPL's 24 or SMPL-X's 55 joints).
        frame: ``"smpl"`` for joints as SMPL models return them at zero pose (y up, facing +z, left = +x),
            ``"latentrl"`` for our rest frame (z up, facing +y, right = +x; e.g. ``body.rest_joints(1.75)`` or
            the ``rest_joints`` field of a motion-text file), or ``"auto"`` to tell them apart by the
            pelvis -> head direction.
        name: used in error messages.

    The AMASS translation is applied with SMPL's rule ``pelvis = trans + J0``, where J0 is the rest pelvis in
    SMPL coordinates. That is exact for the subject's own SMPL rest joints; for any other skeleton, pass
    ``floor="feet"`` to ``convert_amass`` to put the feet back on the floor.
    """

    def __init__(self, rest_joints: Any, frame: str = "auto", name: str = "rest_joints") -> None:
        joints = np.asarray(rest_joints, dtype=np.float64)
        if joints.ndim != 2 or joints.shape[1] != 3 or joints.shape[0] < NUM_JOINTS:
            raise DataError(f"{name}: rest joints have shape {joints.shape}, expected (22, 3) "
                            "(or more joints in SMPL order)")
        joints = joints[:NUM_JOINTS]
        if not np.all(np.isfinite(joints)):
            raise DataError(f"{name}: rest joints contain NaN or infinite values")
        if frame not in ("auto", "smpl", "latentrl"):
            raise DataError(f"{name}: unknown rest frame '{frame}'{closest(frame, ['auto', 'smpl', 'latentrl'])}, "
                            "expected 'auto', 'smpl' or 'latentrl'")
        detected = _detect_frame(joints, name)
        if frame != "auto" and frame != detected:
            raise DataError(f"{name}: rest joints were given as frame '{frame}' but point the head along "
                            f"{'+z' if detected == 'latentrl' else '+y'}, expected the {frame} frame's up axis")
        _check_sides(joints, detected, name)
        self.name = name
        self.frame = detected
        self._smpl = joints if detected == "smpl" else joints @ SMPL_FROM_LATENTRL.T

    def rest_joints_smpl(self, betas: np.ndarray | None = None, gender: str | None = None) -> np.ndarray:
        """(22, 3) rest joints in SMPL coordinates (shape and gender are those of the given joints)."""
        return self._smpl.copy()

    def __repr__(self) -> str:
        return f"RestJointsBody(name={self.name!r}, frame={self.frame!r})"


class SmplxBody:
    """Rest joints from the ``smplx`` package and the user's own model files (never shipped with latentrl).

    Needs ``pip install 'latentrl[amass]'`` and a model folder as ``smplx.create`` expects it (for example
    ``models/`` holding ``smplx/SMPLX_NEUTRAL.npz``). The rest joints are computed once per (gender, betas)
    at zero pose; forward kinematics then gives exactly the model's posed body joints.

    Args:
        model_path: the model folder (or a model file).
        model_type: ``"smplx"``, ``"smplh"`` or ``"smpl"``.
        gender: ``"neutral"``, ``"male"`` or ``"female"``; ``None`` uses the file's ``gender`` (else neutral).
        ext: model file extension; ``None`` picks ``npz`` for SMPL-X and ``pkl`` otherwise.
    """

    def __init__(self, model_path: str | os.PathLike, model_type: str = "smplx", gender: str | None = None,
                 ext: str | None = None) -> None:
        if model_type not in ("smplx", "smplh", "smpl"):
            raise DataError(f"SmplxBody: unknown model_type '{model_type}'"
                            f"{closest(model_type, ['smplx', 'smplh', 'smpl'])}, expected smplx, smplh or smpl")
        self.model_path = Path(model_path)
        if not self.model_path.exists():
            raise DataError(f"{self.model_path}: SMPL model folder not found, expected the folder holding your "
                            f"own {model_type} model files (latentrl does not ship them)")
        self.model_type = model_type
        self.gender = gender
        self.ext = ext or ("npz" if model_type == "smplx" else "pkl")
        self.name = f"smplx:{model_type}:{self.model_path}"
        self._models: dict[tuple[str, int], Any] = {}

    def _model(self, gender: str, num_betas: int):
        key = (gender, num_betas)
        if key not in self._models:
            try:
                import smplx
            except ImportError:
                raise DataError("body model 'smplx' needs the optional 'amass' extra: "
                                "pip install 'latentrl[amass]' (the smplx package)") from None
            try:
                self._models[key] = smplx.create(str(self.model_path), model_type=self.model_type, gender=gender,
                                                 num_betas=num_betas, ext=self.ext, use_pca=False)
            except Exception as exc:  # smplx raises assorted errors for missing or mismatched files
                raise DataError(f"{self.model_path}: cannot load the {self.model_type} {gender} model ({exc}), "
                                "expected your own model files in the layout smplx.create reads") from None
        return self._models[key]

    def rest_joints_smpl(self, betas: np.ndarray | None = None, gender: str | None = None) -> np.ndarray:
        """(22, 3) rest joints in SMPL coordinates for ``betas`` (zero pose, zero translation)."""
        import torch

        gender = (self.gender or gender or "neutral").lower()
        betas = np.zeros(10) if betas is None else np.asarray(betas, dtype=np.float64).reshape(-1)
        model = self._model(gender, len(betas))
        usable = int(getattr(model, "num_betas", len(betas)))  # a model may hold fewer shape components
        betas = np.pad(betas[:usable], (0, max(usable - len(betas), 0)))
        with torch.no_grad():
            out = model(betas=torch.as_tensor(betas[None], dtype=torch.float32), return_verts=False)
        return out.joints[0, :NUM_JOINTS].double().numpy()

    def __repr__(self) -> str:
        return f"SmplxBody({str(self.model_path)!r}, model_type={self.model_type!r})"


def resolve_body_model(spec: Any) -> RestJointsBody | SmplxBody:
    """A body model from ``spec``.

    ``spec`` is a body-model object, a (22, 3) array, a ``.npz``/``.npy`` file of rest joints, or
    ``"smplx:<folder>"`` (also ``"smplh:<folder>"``, ``"smpl:<folder>"``).

    A ``.npz`` file may hold ``rest_joints`` (as motion-text files do; latentrl frame) or ``joints``/``J``, and
    optionally ``frame`` (``"smpl"`` or ``"latentrl"``).
    """
    if hasattr(spec, "rest_joints_smpl"):
        return spec
    if isinstance(spec, np.ndarray | list | tuple):
        return RestJointsBody(spec)
    if isinstance(spec, str | os.PathLike):
        text = str(spec)
        prefix, _, rest = text.partition(":")
        if prefix in ("smplx", "smplh", "smpl") and rest:
            return SmplxBody(rest, model_type=prefix)
        path = Path(text)
        if path.suffix in (".npz", ".npy"):
            return _rest_joints_file(path)
    expected = ("a RestJointsBody/SmplxBody, a (22, 3) array, a .npz/.npy rest-joints file or "
                "'smplx:<model folder>'")
    raise DataError(f"unknown body model {spec!r}, expected {expected}")


def _rest_joints_file(path: Path, frame: str = "auto") -> RestJointsBody:
    if path.suffix not in (".npz", ".npy"):
        raise DataError(f"{path}: rest joints must be a .npz or .npy file of (22, 3) joints")
    if not path.is_file():
        raise DataError(f"{path}: rest-joints file not found, expected a .npz or .npy file of (22, 3) joints")
    try:
        if path.suffix == ".npy":
            return RestJointsBody(np.load(path, allow_pickle=False), frame=frame, name=path.name)
        with np.load(path, allow_pickle=False) as npz:
            key = next((k for k in ("rest_joints", "joints", "J") if k in npz.files), None)
            if key is None:
                raise DataError(f"{path.name}: missing field 'rest_joints', expected (22, 3) rest joints "
                                f"(found {', '.join(npz.files) or 'no fields'})")
            if frame == "auto" and "frame" in npz.files:
                frame = str(npz["frame"])
            return RestJointsBody(npz[key], frame=frame, name=f"{path.name}:{key}")
    except (ValueError, OSError, zipfile.BadZipFile) as exc:
        raise DataError(f"{path.name}: cannot read rest joints ({exc}), expected a plain .npz/.npy file") from None


def rest_joints_latentrl(rest_smpl: np.ndarray) -> np.ndarray:
    """(22, 3) SMPL-frame rest joints -> latentrl rest frame, placed as ``body.rest_joints`` places them.

    The pelvis goes to x = y = 0 and the lower foot joint (10/11) to ``TOE_HEIGHT_M``. The shift moves only
    where the rest skeleton sits; ``transl`` absorbs it, so world joints are unchanged.
    """
    joints = np.asarray(rest_smpl, dtype=np.float64) @ SMPL_FROM_LATENTRL  # row-vector form of C^T @ v
    shift = np.array([-joints[0, 0], -joints[0, 1], TOE_HEIGHT_M - joints[list(FOOT_JOINTS), 2].min()])
    return joints + shift


def sole_heights(joints: np.ndarray, rest: np.ndarray) -> np.ndarray:
    """(T, 2) height of each foot's sole (left, right) above the floor, metres.

    The lower of toe-base and ankle height, each minus its height in the rest pose, where the rest feet stand
    flat with the toe base at ``TOE_HEIGHT_M`` (as in ``body.rest_joints`` and ``rest_joints_latentrl``).
    """
    rest_floor = rest[list(FOOT_JOINTS), 2].min() - TOE_HEIGHT_M
    out = []
    for ankle, toe in zip(ANKLE_JOINTS, FOOT_JOINTS):
        out.append(np.minimum(joints[:, toe, 2] - (rest[toe, 2] - rest_floor),
                              joints[:, ankle, 2] - (rest[ankle, 2] - rest_floor)))
    return np.stack(out, axis=-1)


def foot_speeds(joints: np.ndarray) -> np.ndarray:
    """(T, 2) speed (m/s at 30 fps) of each foot: the slower of its ankle and toe-base joints."""
    if len(joints) < 2:
        return np.zeros((len(joints), 2))
    out = [np.linalg.norm(np.gradient(joints[:, [a, t]], axis=0), axis=-1).min(axis=-1) * FPS
           for a, t in zip(ANKLE_JOINTS, FOOT_JOINTS)]
    return np.stack(out, axis=-1)


def floor_height(joints: np.ndarray, rest: np.ndarray, speed_m_s: float = 0.5) -> float:
    """Height (m) of the floor the feet stand on, from the stance feet.

    The median sole height (``sole_heights``) of the lower foot over the frames where it is nearly still; the
    5th percentile of the lower sole when no such frame exists.
    """
    sole = sole_heights(joints, rest)
    lower = np.argmin(sole, axis=1)
    rows = np.arange(len(sole))
    low = sole[rows, lower]
    still = foot_speeds(joints)[rows, lower] < speed_m_s
    return float(np.median(low[still]) if still.any() else np.percentile(low, 5))


# --- AMASS files ----------------------------------------------------------------------------------------------


def _text(value: np.ndarray) -> str:
    item = value.item() if value.ndim == 0 else value.reshape(-1)[0]
    return item.decode() if isinstance(item, bytes) else str(item)


def load_amass(path: str | os.PathLike) -> dict[str, Any]:
    """Read one AMASS ``.npz`` (raises ``DataError`` naming the file and field).

    Returns ``poses`` (T, 22, 3) SMPL axis-angle, ``trans`` (T, 3), ``fps``, ``betas`` (or None) and
    ``gender`` (or None).
    """
    path = Path(path)
    name = path.name
    if not path.is_file():
        raise DataError(f"{path}: file not found, expected an AMASS .npz file")
    if not zipfile.is_zipfile(path):
        raise DataError(f"{name}: cannot read as .npz (not a zip archive), expected an AMASS .npz file")
    try:
        with np.load(path, allow_pickle=False) as npz:
            files = set(npz.files)
            if "poses" not in files:
                hint = " (a shape.npz holds no motion)" if "betas" in files and "trans" not in files else ""
                raise DataError(f"{name}: missing field 'poses'{hint}, expected (T, 156), (T, 165) or (T, 72) "
                                "axis-angle poses")
            if "trans" not in files:
                raise DataError(f"{name}: missing field 'trans', expected (T, 3) root translations")
            rate_key = next((k for k in ("mocap_framerate", "mocap_frame_rate") if k in files), None)
            if rate_key is None:
                raise DataError(f"{name}: missing field 'mocap_framerate' (or 'mocap_frame_rate'), expected the "
                                "frame rate in Hz")
            poses = np.asarray(npz["poses"], dtype=np.float64)
            trans = np.asarray(npz["trans"], dtype=np.float64)
            fps = float(np.asarray(npz[rate_key]).reshape(-1)[0])
            betas = np.asarray(npz["betas"], dtype=np.float64).reshape(-1) if "betas" in files else None
            gender = _text(np.asarray(npz["gender"])) if "gender" in files else None
    except DataError:
        raise
    except (ValueError, OSError, zipfile.BadZipFile, EOFError) as exc:
        raise DataError(f"{name}: cannot read as .npz ({exc}), expected an AMASS .npz file") from None
    if poses.ndim != 2 or poses.shape[1] not in POSE_WIDTHS:
        widths = ", ".join(f"{w} ({m})" for w, m in POSE_WIDTHS.items())
        raise DataError(f"{name}: field 'poses' has shape {poses.shape}, expected (T, W) with W one of {widths}")
    if poses.shape[0] < 2:
        raise DataError(f"{name}: field 'poses' has {poses.shape[0]} frames, expected at least 2")
    if trans.shape != (poses.shape[0], 3):
        raise DataError(f"{name}: field 'trans' has shape {trans.shape}, expected ({poses.shape[0]}, 3) "
                        "like 'poses'")
    for field, value in (("poses", poses), ("trans", trans)):
        if not np.all(np.isfinite(value)):
            raise DataError(f"{name}: field '{field}' contains NaN or infinite values")
    if not (math.isfinite(fps) and fps > 0):
        raise DataError(f"{name}: field '{rate_key}' is {fps:g}, expected a positive frame rate in Hz")
    if betas is not None and not np.all(np.isfinite(betas)):
        raise DataError(f"{name}: field 'betas' contains NaN or infinite values")
    return {"poses": poses[:, : 3 * NUM_JOINTS].reshape(-1, NUM_JOINTS, 3), "trans": trans, "fps": fps,
            "betas": betas, "gender": gender}


# --- labels -------------------------------------------------------------------------------------------------------


def _segment(item: Any, where: str) -> tuple[float | None, float | None, str]:
    if not isinstance(item, Mapping):
        raise DataError(f"{where}: expected an object with start/end times and a text, got {type(item).__name__}")
    text = next((item[k] for k in _TEXT_KEYS if k in item and item[k] is not None), None)
    if text is None or not str(text).strip():
        raise DataError(f"{where}: missing text, expected one of the keys {', '.join(_TEXT_KEYS)}")
    start = next((item[k] for k in _START_KEYS if k in item), None)
    end = next((item[k] for k in _END_KEYS if k in item), None)
    if (start is None) != (end is None):
        raise DataError(f"{where}: has only one of start/end, expected both ('start_t'/'end_t' or 'start'/'end')")
    try:
        times = (None, None) if start is None else (float(start), float(end))
    except (TypeError, ValueError):
        raise DataError(f"{where}: start/end are {start!r}/{end!r}, expected numbers of seconds") from None
    return times[0], times[1], str(text).strip()


def parse_labels(spec: Any, name: str = "labels") -> list[tuple[float | None, float | None, str]]:
    """Label segments ``(start_s, end_s, text)`` from a JSON file path or an already-parsed object.

    Accepted shapes: a list of segments (``start``/``end`` or ``start_t``/``end_t``, and ``text``,
    ``proc_label``, ``raw_label`` or ``label``); ``{"labels": [...]}``; a BABEL entry (``frame_ann`` labels,
    or ``seq_ann`` labels covering the whole sequence when ``frame_ann`` is null). A segment without times
    covers the whole sequence (returned with ``None`` times).
    """
    if isinstance(spec, str | os.PathLike):
        path = Path(spec)
        if not path.is_file():
            raise DataError(f"{path}: label file not found, expected a JSON file of text segments")
        try:
            spec = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise DataError(f"{path.name}: invalid JSON ({exc}), expected a list of text segments") from None
        name = path.name
    if isinstance(spec, Mapping):
        if spec.get("frame_ann"):
            items, where = spec["frame_ann"].get("labels", []), f"{name}: frame_ann.labels"
        elif spec.get("seq_ann"):
            items, where = spec["seq_ann"].get("labels", []), f"{name}: seq_ann.labels"
            items = [{**i, "start_t": None, "end_t": None} for i in items]
        elif "labels" in spec:
            items, where = spec["labels"], f"{name}: labels"
        else:
            raise DataError(f"{name}: no 'frame_ann', 'seq_ann' or 'labels' key, expected BABEL-style segments "
                            "or a list of {start, end, text}")
    elif isinstance(spec, list | tuple):
        items, where = spec, name
    else:
        raise DataError(f"{name}: labels are a {type(spec).__name__}, expected a list of segments or a JSON path")
    if not items:
        raise DataError(f"{where}: no segments, expected at least one text segment")
    out = []
    for i, item in enumerate(items):
        if isinstance(item, Mapping) and "start_t" in item and item["start_t"] is None:
            item = {k: v for k, v in item.items() if k not in ("start_t", "end_t")}
        out.append(_segment(item, f"{where}[{i}]"))
    return out


def segments_to_frames(segments: Sequence[tuple[float | None, float | None, str]], num_frames: int,
                       duration_s: float, name: str) -> list[tuple[int, int, str]]:
    """Second-based segments -> ``(first_frame, end_frame, text)`` at 30 fps (end exclusive).

    A segment [start, end) holds the frames whose time k / 30 lies in it, so back-to-back segments neither
    overlap nor leave a gap; one that reaches the last frame's time holds the last frame too. ``duration_s`` is
    the source's length (frames / frame rate, as BABEL's ``dur``); a segment may end up to
    ``LABEL_END_TOLERANCE_S`` past it. Anything else outside the sequence raises ``DataError``.
    """
    last_time = (num_frames - 1) / FPS
    frames = []
    for i, (start, end, text) in enumerate(segments):
        if start is None:
            frames.append((0, num_frames, text))
            continue
        if not (math.isfinite(start) and math.isfinite(end)) or end <= start:
            raise DataError(f"{name}: label {i} ('{text}') runs from {start:g} s to {end:g} s, expected "
                            "start < end")
        if start < -1e-6 or start >= duration_s or end > duration_s + LABEL_END_TOLERANCE_S:
            raise DataError(f"{name}: label {i} ('{text}') runs from {start:g} s to {end:g} s, outside the "
                            f"sequence (0 to {duration_s:.3f} s), expected times inside it")
        first = min(max(math.ceil(start * FPS - 1e-6), 0), num_frames - 1)
        stop = num_frames if end >= last_time - 1e-6 else min(math.ceil(end * FPS - 1e-6), num_frames)
        frames.append((first, max(stop, first + 1), text))
    return frames


def _covered_runs(segments: Sequence[tuple[int, int, str]], num_frames: int) -> list[tuple[int, int]]:
    covered = np.zeros(num_frames, dtype=bool)
    for a, b, _ in segments:
        covered[a:b] = True
    edges = np.flatnonzero(np.diff(np.concatenate(([0], covered.astype(int), [0]))))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]


def _babel_lookup(spec: Mapping, path: Path) -> Any | None:
    """The entry of a whole BABEL file (sid -> {feat_p, ...}) whose ``feat_p`` ends like ``path``."""
    parts = path.as_posix().split("/")
    best, best_len = None, 0
    for entry in spec.values():
        if not isinstance(entry, Mapping) or "feat_p" not in entry:
            continue
        feat = str(entry["feat_p"]).replace("\\", "/").split("/")
        common = 0
        while common < min(len(feat), len(parts)) and feat[-1 - common] == parts[-1 - common]:
            common += 1
        if common > best_len:
            best, best_len = entry, common
    return best


def _labels_for(labels: Any, index: int, path: Path, count: int) -> Any:
    """The label spec of source ``index`` from the forms ``convert_amass`` accepts."""
    if isinstance(labels, str | os.PathLike) and Path(labels).is_dir():
        found = Path(labels) / f"{path.stem}.json"
        if not found.is_file():
            raise DataError(f"{path.name}: no label file {found}, expected <stem>.json in the labels folder")
        return found
    if isinstance(labels, str | os.PathLike):
        try:
            loaded = json.loads(Path(labels).read_text()) if Path(labels).is_file() else None
        except (json.JSONDecodeError, UnicodeDecodeError) as exc:
            raise DataError(f"{Path(labels).name}: invalid JSON ({exc}), expected text segments") from None
        if isinstance(loaded, Mapping) and _is_keyed(loaded):
            return _labels_for(loaded, index, path, count)
        if count == 1:
            return labels
        raise DataError(f"{labels}: one label file for {count} sources, expected a list of label specs, a "
                        "labels folder, a BABEL file or a mapping keyed by file name")
    if isinstance(labels, Mapping) and _is_keyed(labels):
        for key in (str(path), path.name, path.stem):
            if key in labels:
                return labels[key]
        entry = _babel_lookup(labels, path)
        if entry is None:
            raise DataError(f"{path.name}: no labels for this file, expected a key '{path.name}' or '{path.stem}' "
                            "(or a BABEL entry whose feat_p ends with its path)")
        return entry
    if isinstance(labels, list | tuple) and len(labels) == count and count > 0 and not _is_segment(labels[0]):
        return labels[index]
    if count == 1:
        return labels
    raise DataError(f"labels: got {type(labels).__name__}, expected one label spec per source ({count} sources)")


def _is_segment(item: Any) -> bool:
    return isinstance(item, Mapping) and any(k in item for k in _TEXT_KEYS)


def _is_keyed(spec: Mapping) -> bool:
    """True for a mapping of file keys / BABEL sids to label specs (not a single BABEL entry)."""
    return not any(k in spec for k in ("frame_ann", "seq_ann", "labels"))


# --- conversion -----------------------------------------------------------------------------------------------------


def amass_to_sequences(path: str | os.PathLike, labels: Any, body_model: Any, floor: str = "keep",
                       uncovered: str = "crop") -> list[dict[str, np.ndarray]]:
    """Convert one AMASS file into motion-text sequences (dicts of the format's fields).

    Args:
        path: the AMASS ``.npz``.
        labels: its label spec (see ``parse_labels``).
        body_model: see ``resolve_body_model``.
        floor: ``"keep"`` the AMASS heights, or ``"feet"``: shift vertically so the stance feet stand on
            z = 0 (``floor_height``; use it when the rest joints are not the subject's own).
        uncovered: frames without a label are ``"crop"``-ped (a gap splits the sequence into parts), or raise
            (``"error"``).

    Returns:
        One sequence per labelled stretch (one when the labels cover every frame).
    """
    path = Path(path)
    name = path.name
    if floor not in ("keep", "feet"):
        raise DataError(f"floor: '{floor}'{closest(floor, ['keep', 'feet'])}, expected 'keep' or 'feet'")
    if uncovered not in ("crop", "error"):
        raise DataError(f"uncovered: '{uncovered}'{closest(uncovered, ['crop', 'error'])}, "
                        "expected 'crop' or 'error'")
    data = load_amass(path)
    body = resolve_body_model(body_model)
    rest_smpl = np.asarray(body.rest_joints_smpl(data["betas"], data["gender"]), dtype=np.float64)
    rest = rest_joints_latentrl(rest_smpl)
    local = smpl_rotations_to_latentrl(axis_angle_to_matrix_np(data["poses"]))
    pelvis = data["trans"] + rest_smpl[0]  # SMPL: the root rotates about the rest pelvis J0, then + trans
    src_times = np.arange(len(local)) / data["fps"]
    times = output_times(len(local), data["fps"])
    local = slerp_resample(local, src_times, times)
    pelvis = lerp_resample(pelvis, src_times, times)
    poses = matrix_to_axis_angle_np(local).astype(np.float32)
    transl = pelvis - rest[0]
    if floor == "feet":
        fk = forward_kinematics_np(rest, axis_angle_to_matrix_np(poses.astype(np.float64)), transl)
        transl[:, 2] -= floor_height(fk, rest)
    segments = segments_to_frames(parse_labels(labels, f"{name} labels"), len(times),
                                  len(data["poses"]) / data["fps"], f"{name} labels")
    runs = _covered_runs(segments, len(times))
    if uncovered == "error" and runs != [(0, len(times))]:
        bounds = [0] + [x for run in runs for x in run] + [len(times)]
        first, stop = next((a, b) for a, b in zip(bounds[::2], bounds[1::2]) if b > a)
        raise DataError(f"{name} labels: frames {first}-{stop - 1} (30 fps) have no label, expected "
                        "every frame labelled (or uncovered='crop')")
    out = []
    for a, b in runs:
        segs = [(max(s, a) - a, min(e, b) - a, t) for s, e, t in segments if min(e, b) > max(s, a)]
        out.append(make_sequence(rest, poses[a:b], transl[a:b], segs))
    return out


def convert_amass(src_files: Sequence[str | os.PathLike] | str | os.PathLike, labels: Any,
                  out_dir: str | os.PathLike, body_model: Any, floor: str = "keep", uncovered: str = "crop",
                  overwrite: bool = False, name: str = "amass-converted") -> list[Path]:
    """Convert AMASS files into a motion-text dataset folder (``.npz`` sequences and ``meta.json``).

    Args:
        src_files: AMASS ``.npz`` paths (a single path, or a folder searched recursively, also works).
        labels: one label spec per source (a list), a mapping keyed by file path, name or stem, a whole BABEL
            JSON (entries matched by ``feat_p``), a folder of ``<stem>.json`` files, or (for one source) a
            single spec. A spec is a JSON path or parsed object (see ``parse_labels``).
        out_dir: output folder; refused if it already holds ``.npz`` files unless ``overwrite``.
        body_model: see ``resolve_body_model`` (e.g. ``"smplx:/path/to/models"`` or a rest-joints array).
        floor, uncovered: see ``amass_to_sequences``.
        name: dataset name written to ``meta.json``.

    Returns:
        The written sequence paths: ``<stem>.npz``, or ``<stem>_p<k>.npz`` when unlabelled gaps split a file.
    """
    sources = _expand_sources(src_files)
    out_dir = Path(out_dir)
    old = sorted(out_dir.glob("*.npz")) if out_dir.is_dir() else []
    if old and not overwrite:
        raise DataError(f"{out_dir}: already holds {len(old)} .npz files, expected an empty folder "
                        "(or overwrite=True)")
    body = resolve_body_model(body_model)
    for stale in old + [out_dir / "meta.json"]:
        stale.unlink(missing_ok=True)
    written: list[Path] = []
    records = []
    used: set[str] = set()
    texts: dict[str, int] = {}
    for index, src in enumerate(sources):
        seqs = amass_to_sequences(src, _labels_for(labels, index, src, len(sources)), body, floor=floor,
                                  uncovered=uncovered)
        stem = src.stem
        while stem in used:
            stem = f"{stem}_{index}"
        used.add(stem)
        outs = []
        for k, seq in enumerate(seqs):
            target = out_dir / (f"{stem}.npz" if len(seqs) == 1 else f"{stem}_p{k}.npz")
            written.append(write_sequence(target, seq, check_fk=False))
            outs.append({"file": target.name, "frames": int(len(seq["transl"]))})
            for a, b, text in zip(seq["seg_start"], seq["seg_end"], seq["seg_text"]):
                texts[str(text)] = texts.get(str(text), 0) + int(b - a)
        records.append({"source": str(src), "outputs": outs})
    write_meta(out_dir, {
        "name": name,
        "converter": "latentrl.datasets.amass",
        "licence": "derived from AMASS/BABEL: their licences apply; do not redistribute",
        "fps": FPS,
        "body_model": getattr(body, "name", repr(body)),
        "floor": floor,
        "num_sequences": len(written),
        "frames": int(sum(o["frames"] for r in records for o in r["outputs"])),
        "frames_per_text": texts,
        "sources": records,
    })
    return written


def _expand_sources(src_files: Any) -> list[Path]:
    items = [src_files] if isinstance(src_files, str | os.PathLike) else list(src_files)
    sources: list[Path] = []
    for item in items:
        path = Path(item)
        if path.is_dir():
            found = sorted(p for p in path.rglob("*.npz") if p.name != "shape.npz")
            if not found:
                raise DataError(f"{path}: no .npz files found, expected AMASS sequences")
            sources.extend(found)
        else:
            sources.append(path)
    if not sources:
        raise DataError("src_files: empty, expected at least one AMASS .npz file")
    return sources


# --- command line ----------------------------------------------------------------------------------------------------


@dataclass
class ConvertAmassRequest:
    """``latentrl data convert-amass`` (and ``python -m latentrl.datasets.amass``): what to convert, and how."""

    sources: list[str]
    """AMASS ``.npz`` files or folders (searched recursively)."""
    labels: str
    """JSON labels (see :func:`convert_amass`)."""
    out: str
    """Output dataset folder."""
    rest_joints: str | None = None
    """``.npz``/``.npy`` with the body's 22 rest joints (key ``rest_joints``); this or ``smplx_model``."""
    smplx_model: str | None = None
    """Your SMPL-X/SMPL-H/SMPL model folder (needs ``latentrl[amass]``)."""
    rest_frame: str = "auto"
    model_type: str = "smplx"
    floor: str = "keep"
    uncovered: str = "crop"
    overwrite: bool = False


def add_convert_arguments(parser: argparse.ArgumentParser) -> argparse.ArgumentParser:
    """The arguments of :class:`ConvertAmassRequest` (shared by ``latentrl data convert-amass`` and ``main``)."""
    parser.add_argument("sources", nargs="+", help="AMASS .npz files or folders (searched recursively)")
    parser.add_argument("--labels", required=True,
                        help="JSON labels: a BABEL file (matched by feat_p), a mapping {file name or stem: "
                             "segments}, one segment list (single source), or a folder of <stem>.json files")
    parser.add_argument("--out", required=True, help="output dataset folder")
    body = parser.add_mutually_exclusive_group(required=True)
    body.add_argument("--rest-joints", help=".npz/.npy with the 22 rest joints of the body (key rest_joints)")
    body.add_argument("--smplx-model", help="your SMPL-X/SMPL-H/SMPL model folder (needs latentrl[amass])")
    parser.add_argument("--rest-frame", default="auto", choices=("auto", "smpl", "latentrl"),
                        help="frame of --rest-joints (default: detect)")
    parser.add_argument("--model-type", default="smplx", choices=("smplx", "smplh", "smpl"),
                        help="model type for --smplx-model (default smplx)")
    parser.add_argument("--floor", default="keep", choices=("keep", "feet"),
                        help="keep AMASS heights, or put the feet on the floor (default keep)")
    parser.add_argument("--uncovered", default="crop", choices=("crop", "error"),
                        help="unlabelled frames: crop them (default) or fail")
    parser.add_argument("--overwrite", action="store_true", help="replace .npz files already in --out")
    return parser


def run_convert(req: ConvertAmassRequest) -> int:
    """Convert as ``req`` says and print where; raises :class:`DataError` on bad input."""
    if req.smplx_model:
        model: Any = SmplxBody(req.smplx_model, model_type=req.model_type)
    elif req.rest_joints:
        model = _rest_joints_file(Path(req.rest_joints), frame=req.rest_frame)
    else:
        raise DataError("give the body: --rest-joints FILE or --smplx-model FOLDER")
    paths = convert_amass(req.sources, req.labels, req.out, model, floor=req.floor, uncovered=req.uncovered,
                          overwrite=req.overwrite)
    print(f"wrote {len(paths)} sequences to {req.out}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m latentrl.datasets.amass SRC... --labels L --out DIR (--rest-joints F | --smplx-model D)``."""
    parser = add_convert_arguments(argparse.ArgumentParser(
        prog="python -m latentrl.datasets.amass",
        description="Convert AMASS .npz sequences with text labels (BABEL-style JSON) into a latentrl "
                    "motion-text dataset (30 fps, z up, SMPL-22)."))
    args = parser.parse_args(argv)
    try:
        return run_convert(ConvertAmassRequest(**vars(args)))
    except DataError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return exc.exit_code


__all__ = [
    "ConvertAmassRequest",
    "POSE_WIDTHS",
    "SMPL_FROM_LATENTRL",
    "RestJointsBody",
    "SmplxBody",
    "amass_to_sequences",
    "convert_amass",
    "floor_height",
    "foot_speeds",
    "latentrl_rotations_to_smpl",
    "lerp_resample",
    "load_amass",
    "main",
    "add_convert_arguments",
    "run_convert",
    "output_times",
    "parse_labels",
    "resolve_body_model",
    "rest_joints_latentrl",
    "segments_to_frames",
    "slerp_resample",
    "sole_heights",
    "smpl_rotations_to_latentrl",
]


if __name__ == "__main__":
    sys.exit(main())
