"""One motion clip and its ``.npz`` file: what envs export, ``motion sample`` and evaluation write, the viewer reads.

:class:`MotionClip` holds one motion in world coordinates; :meth:`MotionClip.save` writes it and
:meth:`MotionClip.load` reads it (older files without the newer keys load too: contacts are then
computed from the joints, rest offsets from the bone lengths). Load with ``allow_pickle=False``.

Motion ``.npz`` schema (docs/evaluation.md, section 6):

================  ==================  ==========================================================
key               shape, dtype        meaning
================  ==================  ==========================================================
``joints``        (T, 22, 3) float32  world joint positions, metres, z up, SMPL-22 order
``fps``           () float32          frames per second (30)
``texts``         (T,) unicode        the prompt in force at each frame ('' for seed frames)
``contacts``      (T, 2) bool         left, right foot joint (10, 11) lower than 3 cm above ``floor``
``floor``         () float32          the floor height the contacts refer to, metres
``rest_offsets``  (22, 3) float32     each joint's rest offset from its parent, metres, z up
``parents``       (22,) int32         each joint's parent (-1 for the pelvis), as BVH export uses
``features``      (T, 276) float32    optional: DART features in world coordinates
``actions``       (S, D) float32      optional: the latent noise of each primitive (RL action)
``goals``         (S, 3) float32      optional: the goal in force during each primitive, world metres
``primitive``     (T,) int32          optional: which primitive produced each frame (-1 = seed)
``waypoints``     (W, 3) float32      optional: the path an evaluation episode follows
``scene``         () unicode          optional: the scene the motion moves in, ``latentrl.scene/1`` JSON text
================  ==================  ==========================================================

Any other key is a 0-d (or small) value kept in :attr:`MotionClip.meta` (an evaluation writes
``suite``, ``path_index``, ``episode``, ``success``, ``end``, ``reach_time_s``, and for a joint-goal episode
``waypoint_joints``, the SMPL joint of each waypoint; ``motion sample``
writes ``seed``, ``guidance_scale``, ``motion_model``).
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from latentrl.constants import CONTACT_HEIGHT_M
from latentrl.errors import DataError
from latentrl.motion.contacts import foot_contacts
from latentrl.motion.representation import FEATURE_DIM, FUTURE_LENGTH, HISTORY_LENGTH
from latentrl.motion.skeleton import FPS, NUM_JOINTS, PARENTS, rest_offsets
from latentrl.safe_io import atomic_write_bytes

ARRAYS = ("features", "actions", "goals", "primitive", "waypoints")
"""The optional array fields, in the order they are written."""
_DERIVED = ("contacts", "floor", "rest_offsets", "parents")


def contacts_of(joints: np.ndarray, floor: float = 0.0) -> np.ndarray:
    """(T, 22, 3) world joints -> (T, 2) bool foot contacts (:func:`latentrl.motion.contacts.foot_contacts`)."""
    return foot_contacts(torch.as_tensor(np.asarray(joints)), floor, CONTACT_HEIGHT_M).numpy()


def primitive_layout(steps: int) -> np.ndarray:
    """(2 + 8 * steps,) int32: -1 for the seed frames, then the primitive of each frame."""
    return np.repeat(np.arange(-1, steps, dtype=np.int32), [HISTORY_LENGTH] + [FUTURE_LENGTH] * steps)


@dataclass
class MotionClip:
    """One motion, world metres, z up (the shared motion format; see the module docstring for the file).

    Attributes:
        joints: (T, 22, 3) float32 world joints.
        fps: frames per second.
        texts: (T,) prompt per frame ('' for seed frames).
        actions: (S, D) latent noise per primitive, or None.
        goals: (S, 3) goal per primitive, or None.
        contacts: (T, 2) bool left/right foot contacts; computed from ``joints`` and ``floor`` when None.
        floor: floor height, metres.
        features: (T, 276) world DART features, or None.
        primitive: (T,) primitive per frame (-1 = seed), or None.
        waypoints: (W, 3) path of an evaluation episode, or None.
        meta: other values written beside (scalars: seed, success, ...).
        scene: the scene's ``latentrl.scene/1`` JSON text (docs/scenes.md), or None for the flat floor; kept as
            text here (:func:`latentrl.scenes.scene_from_json` reads it).
    """

    joints: np.ndarray
    fps: float = float(FPS)
    texts: list[str] | None = None
    actions: np.ndarray | None = None
    goals: np.ndarray | None = None
    contacts: np.ndarray | None = None
    floor: float = 0.0
    features: np.ndarray | None = None
    primitive: np.ndarray | None = None
    waypoints: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)
    scene: str | None = None

    def __post_init__(self) -> None:
        self.joints = np.asarray(self.joints, dtype=np.float32)
        if self.joints.ndim != 3 or self.joints.shape[1:] != (NUM_JOINTS, 3):
            raise DataError(f"joints must be (T, {NUM_JOINTS}, 3), got {self.joints.shape}")
        self.fps = float(self.fps)
        t = len(self.joints)
        self.texts = [str(x) for x in self.texts] if self.texts is not None else [""] * t
        if len(self.texts) != t:
            raise DataError(f"texts has {len(self.texts)} entries for {t} frames")
        if self.contacts is None:
            self.contacts = contacts_of(self.joints, self.floor)
        self.contacts = np.asarray(self.contacts, dtype=bool).reshape(t, 2)
        if self.scene is not None:
            scene = np.asarray(self.scene)
            if scene.shape != () or scene.dtype.kind != "U" or len(str(scene)) > MAX_SCENE_CHARS:
                raise DataError(f"field 'scene' must be the scene's JSON text (at most {MAX_SCENE_CHARS} characters), "
                                f"got {scene.dtype} of shape {scene.shape}")
            self.scene = str(scene)

    @property
    def frames(self) -> int:
        """Number of frames in the clip."""
        return len(self.joints)

    @property
    def rest_offsets(self) -> np.ndarray:
        """(22, 3) rest offsets: SMPL T-pose directions times the motion's median bone lengths."""
        return rest_offsets(self.joints).astype(np.float32)

    def cut(self, steps: int) -> MotionClip:
        """The first ``steps`` primitives (2 seed frames + 8 per primitive) of a clip in the primitive layout."""
        frames = HISTORY_LENGTH + FUTURE_LENGTH * int(steps)

        def head(x, n):
            return None if x is None else x[:n]

        return MotionClip(self.joints[:frames], self.fps, self.texts[:frames], head(self.actions, steps),
                          head(self.goals, steps), self.contacts[:frames], self.floor, head(self.features, frames),
                          head(self.primitive, frames), self.waypoints, dict(self.meta), scene=self.scene)

    def to_dict(self) -> dict[str, Any]:
        """The fields as a flat dict (``joints``, ``fps``, ``texts``, ``contacts``, present optional arrays, meta)."""
        out: dict[str, Any] = {"joints": self.joints, "fps": self.fps, "texts": list(self.texts),
                               "contacts": self.contacts, "floor": self.floor}
        out.update({k: getattr(self, k) for k in ARRAYS if getattr(self, k) is not None})
        if self.scene is not None:
            out["scene"] = self.scene
        out.update(self.meta)
        return out

    def arrays(self) -> dict[str, np.ndarray]:
        """What :meth:`save` writes: every key of the schema with its dtype."""
        data = {"joints": self.joints, "fps": np.float32(self.fps), "texts": np.asarray(self.texts, dtype=str),
                "contacts": self.contacts, "floor": np.float32(self.floor), "rest_offsets": self.rest_offsets,
                "parents": np.asarray(PARENTS, dtype=np.int32)}
        if self.features is not None:
            data["features"] = np.asarray(self.features, dtype=np.float32)
        if self.actions is not None:
            data["actions"] = np.asarray(self.actions, dtype=np.float32).reshape(len(self.actions), -1)
        if self.goals is not None:
            data["goals"] = np.asarray(self.goals, dtype=np.float32)
        if self.primitive is not None:
            data["primitive"] = np.asarray(self.primitive, dtype=np.int32)
        if self.waypoints is not None:
            data["waypoints"] = np.asarray(self.waypoints, dtype=np.float32)
        if self.scene is not None:
            data["scene"] = np.asarray(self.scene, dtype=str)
        for key, value in self.meta.items():
            data[key] = np.asarray(value)
        return data

    def save(self, path: str | Path) -> Path:
        """Write the clip as a motion ``.npz``, atomically (refuses what :func:`check_motion` refuses)."""
        check_motion(self.joints, self.fps, str(path))
        buf = io.BytesIO()
        np.savez_compressed(buf, **self.arrays())
        return atomic_write_bytes(path, buf.getvalue())

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> MotionClip:
        """A clip from the schema's keys; unknown keys go to ``meta`` (``rest_offsets``, ``parents`` are derived)."""
        known = {"joints", "fps", "texts", "contacts", "floor", "scene", *ARRAYS}
        kwargs = {k: data[k] for k in known if k in data}
        if "fps" in kwargs:
            kwargs["fps"] = float(kwargs["fps"])
        if "floor" in kwargs:
            kwargs["floor"] = float(kwargs["floor"])
        meta = {k: v for k, v in data.items() if k not in known and k not in _DERIVED}
        return cls(**kwargs, meta=meta)

    @classmethod
    def load(cls, path: str | Path) -> MotionClip:
        """Read a motion ``.npz`` (one-line :class:`DataError` on a missing, broken or malformed file)."""
        data = read_motion_arrays(path)
        meta = {k: (v.item() if v.ndim == 0 else v) for k, v in data.items()}
        try:
            return cls.from_dict(meta)
        except DataError as exc:
            raise DataError(f"{path}: {exc}") from None


MAX_SCENE_CHARS = 1 << 20
"""Longest scene JSON a motion file may carry (the scene file's own bound)."""
MAX_FPS = 1000.0
"""Frame rates above this are refused."""
MIN_FPS = 0.001
"""Frame rates below this are refused (1e-300 would round to 0 in the file's float32)."""
MAX_FRAMES = 1_000_000
"""Most frames a motion may have: 9 hours at 30 fps (``eval --max-steps`` 100,000 makes 800,002)."""
MAX_MOTION_BYTES = 1 << 30
"""Most bytes a motion ``.npz`` may decompress to, all members together (checked before any is read)."""
MAX_MEMBERS = 64
"""Most arrays a motion ``.npz`` may hold (the schema has 13 plus a few scalars)."""
MAX_COORD_M = 10_000.0
"""Joint coordinates beyond +/- this many metres are no human motion (a diverged rollout or a broken file)."""


def check_motion(joints, fps, source: str) -> tuple[np.ndarray, float]:
    """The one check of a motion's arrays; returns (float64 joints, fps).

    Joints: real floating point (T>0, 22, 3), finite and within +/- :data:`MAX_COORD_M`;
    ``fps``: one finite number in (0, :data:`MAX_FPS`].
    """
    joints = np.asarray(joints)
    if joints.dtype.kind != "f":  # integers, complex, strings, objects: not positions in metres
        raise DataError(f"{source}: field 'joints' must hold real floating-point numbers, got dtype {joints.dtype}")
    if joints.ndim != 3 or joints.shape[1:] != (NUM_JOINTS, 3) or len(joints) == 0:
        raise DataError(f"{source}: field 'joints' must be (T, {NUM_JOINTS}, 3) with T > 0, got {joints.shape}")
    joints = joints.astype(np.float64)
    if not np.isfinite(joints).all():
        bad = int((~np.isfinite(joints)).any(axis=(1, 2)).sum())
        raise DataError(f"{source}: field 'joints' holds NaN or inf in {bad} of {len(joints)} frames")
    peak = float(np.abs(joints).max())
    if peak > MAX_COORD_M:
        raise DataError(f"{source}: field 'joints' reaches {peak:.3g} m, beyond the +/-{MAX_COORD_M:g} m "
                        f"a motion may span")
    fps_arr = np.asarray(fps)
    if fps_arr.shape != () or fps_arr.dtype.kind not in "iuf":
        raise DataError(f"{source}: field 'fps' must be one real number, got {fps_arr.dtype} of shape {fps_arr.shape}")
    fps = float(fps_arr)
    if not MIN_FPS <= fps <= MAX_FPS:  # also refuses nan
        raise DataError(f"{source}: field 'fps' must lie in [{MIN_FPS:g}, {MAX_FPS:g}], got {fps:g}")
    if len(joints) > MAX_FRAMES:
        raise DataError(f"{source}: field 'joints' has {len(joints):,} frames; a motion may have at most "
                        f"{MAX_FRAMES:,}")
    return joints, fps


def _member_headers(path: Path) -> dict[str, tuple[tuple[int, ...], np.dtype]]:
    """Shape and dtype of every ``.npy`` member, read from the headers alone, before any data is decompressed.

    Refuses an archive whose members would decompress to more than :data:`MAX_MOTION_BYTES`, or whose ``joints``
    have more than :data:`MAX_FRAMES`. ``np.load`` allocates what a member's header announces and reads a
    non-``.npy`` member whole, so both sizes are summed.
    """
    import zipfile

    from numpy.lib import format as npy

    headers: dict[str, tuple[tuple[int, ...], np.dtype]] = {}
    total = 0
    try:
        with zipfile.ZipFile(path) as zf:
            infos = zf.infolist()
            if len(infos) > MAX_MEMBERS:
                raise DataError(f"{path}: holds {len(infos)} arrays; a motion .npz may hold at most {MAX_MEMBERS}")
            for info in infos:
                name = info.filename.removesuffix(".npy")
                size = info.file_size
                if info.filename.endswith(".npy"):
                    with zf.open(info) as f:
                        version = npy.read_magic(f)
                        if version not in ((1, 0), (2, 0)):
                            raise DataError(f"{path}: field '{name}': .npy format version {version} is not read")
                        read = npy.read_array_header_1_0 if version == (1, 0) else npy.read_array_header_2_0
                        shape, _, dtype = read(f)
                    size = max(size, int(np.prod(shape, dtype=object)) * dtype.itemsize)
                    headers[name] = (tuple(shape), dtype)
                    if name == "joints" and len(shape) == 3 and shape[0] > MAX_FRAMES:
                        raise DataError(f"{path}: field 'joints' has {shape[0]:,} frames; a motion may have at most "
                                        f"{MAX_FRAMES:,}")
                total += size
                if total > MAX_MOTION_BYTES:
                    raise DataError(f"{path}: its arrays decompress to more than {MAX_MOTION_BYTES / 2**30:g} GiB "
                                    f"(field '{name}' alone is {size:,} bytes); refused before reading")
    except DataError:
        raise
    except Exception as exc:  # zipfile and numpy raise several types for broken archives and headers
        raise DataError(f"{path}: not a readable motion .npz ({str(exc)[:120]})") from None
    return headers


def _field_problem(key: str, value: np.ndarray, frames: int) -> str | None:
    """What is wrong with one optional field of a motion file (the schema above), or None."""
    real = value.dtype.kind in "fiu"
    if key == "texts":
        if value.dtype.kind != "U" or value.shape != (frames,):
            return f"must be ({frames},) text, one prompt per frame"
    elif key == "contacts":
        if value.dtype.kind not in "biu" or value.shape != (frames, 2):
            return f"must be ({frames}, 2) booleans"
    elif key == "primitive":
        if value.dtype.kind not in "iu" or value.shape != (frames,):
            return f"must be ({frames},) integers"
    elif key == "features":
        if not real or value.shape != (frames, FEATURE_DIM):
            return f"must be ({frames}, {FEATURE_DIM}) real numbers"
    elif key == "actions":
        if not real or (value.ndim != 2 and value.size):
            return "must be (S, D) real numbers"
    elif key in ("goals", "waypoints"):
        if not real or ((value.ndim != 2 or value.shape[1] != 3) and value.size):
            return "must be (N, 3) real numbers"
    elif key == "scene":
        if value.dtype.kind != "U" or value.shape != () or len(str(value)) > MAX_SCENE_CHARS:
            return f"must be the scene's JSON text (at most {MAX_SCENE_CHARS:,} characters)"
    elif key == "floor":
        if not real or value.shape != ():
            return "must be one real number"
    else:
        return None
    if real and not np.isfinite(value).all():
        return f"holds NaN or inf ({int((~np.isfinite(value)).sum())} of {value.size} values)"
    if key in ("goals", "waypoints", "floor") and value.size and float(np.abs(value).max()) > MAX_COORD_M:
        return f"reaches {float(np.abs(value).max()):.3g} m, beyond the +/-{MAX_COORD_M:g} m a motion may span"
    return None


def check_motion_fields(data: dict[str, np.ndarray], source: str) -> None:
    """The one check of a motion file's optional fields: shape, dtype and finite values (one line naming the field).

    ``rest_offsets`` and ``parents`` are not checked: loading recomputes them from the joints.
    """
    frames = len(data["joints"])
    for key in ("texts", "contacts", "primitive", "features", "actions", "goals", "waypoints", "floor", "scene"):
        if key in data:
            value = np.asarray(data[key])
            problem = _field_problem(key, value, frames)
            if problem and problem.startswith("must"):
                problem += f", got {value.dtype} of shape {value.shape}"
            if problem:
                raise DataError(f"{source}: field '{key}' {problem}")


def read_motion_arrays(path: str | Path) -> dict[str, np.ndarray]:
    """The raw arrays of a motion ``.npz``, checked: the one reader of motion files.

    Before reading: the archive's decompressed size, member count and frame count (:func:`_member_headers`).
    After: ``joints`` and ``fps`` (:func:`check_motion`; ``fps`` 30 for old files) and every optional field
    (:func:`check_motion_fields`). Every refusal is one :class:`DataError` line naming the file and field.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"motion file not found: {path}")
    _member_headers(path)
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except Exception as exc:  # numpy raises several types for broken archives
        raise DataError(f"{path}: not a readable motion .npz ({str(exc)[:120]})") from None
    joints = data.get("joints")
    if joints is None:
        raise DataError(f"{path}: no field 'joints' (expected (T, {NUM_JOINTS}, 3) positions in metres)")
    data.setdefault("fps", np.float32(FPS))
    joints, fps = check_motion(joints, data["fps"], str(path))
    data["joints"], data["fps"] = joints.astype(np.float32), np.float32(fps)
    check_motion_fields(data, str(path))
    return data


def save_motion_npz(path: str | Path, joints, fps: float = FPS, texts: Sequence[str] | None = None, **fields) -> Path:
    """Write one motion in the shared format, atomically: ``MotionClip(joints, fps, texts, **fields).save(path)``.

    Keyword arguments other than the clip's fields are written as extra values (``meta``).
    """
    try:
        return MotionClip.from_dict({"joints": joints, "fps": fps, "texts": texts, **fields}).save(path)
    except DataError as exc:
        raise DataError(f"{path}: {exc}") from None


def load_motion_npz(path: str | Path) -> dict[str, np.ndarray]:
    """Read a motion ``.npz`` as its arrays (``joints`` checked, ``fps`` and ``contacts`` filled for old files)."""
    data = read_motion_arrays(path)
    if "contacts" not in data:
        data["contacts"] = contacts_of(data["joints"], float(data.get("floor", 0.0)))
    return data
