"""Real motion capture for validation: pybullet's DeepMimic humanoid clips, retargeted to our SMPL-22 body.

``pip install 'latentrl[mocap]'`` installs pybullet (zlib licence), whose ``pybullet_data`` folder ships the
DeepMimic clips (Peng et al. 2018, from public mocap databases). They are read **at run time from the
installed package** and never copied into this repository. About 10 s of locomotion exists (walk, run, a
forward jump, walking turns), far too little to train on, but enough to check that the procedural data and
trained models move at human speeds and cadences (``mocap_reference_statistics``).

Pipeline for one clip:

1. **Read** ``data/motions/<name>.txt`` (JSON: ``Loop``, ``Frames``). A frame holds 44 floats: duration,
   root position, root quaternion (w, x, y, z), then local quaternions of chest, neck, right hip, the right
   knee angle, right ankle, right shoulder, right elbow angle, and the same for the left side.
2. **Change frame**: DeepMimic's world is y up with the character facing +x and its right along +z; ours is
   z up, facing +y, right along +x (a cyclic axis permutation, so rotations stay proper). The rest pose of
   ``humanoid/humanoid.urdf`` stands upright with the arms down, like ours.
3. **Loop and tile** (walk, run and turn clips): the last frame should repeat the first one a cycle later, but
   the recordings do not close exactly (up to 29 degrees at a shoulder, 53 at the neck), so the mismatch of
   every joint, the root height and the root tilt is spread linearly over the cycle. Cycles are then chained,
   each moved by the translation between the first and last root frame and, for the turning clips, by the
   root's yaw change (``CLIPS``).
4. **Resample** to 30 fps: slerp for rotations, linear for the root (the jump is recorded at 60 fps).
5. **Forward kinematics** on the DeepMimic skeleton (URDF lengths x 0.25 = metres: hip to ankle 0.83 m).
6. **Map to SMPL-22 positions**: hips, knees, ankles, shoulders, elbows, wrists and the neck exist; the SMPL
   pelvis sits above the hip line, spine1-3 are spaced along root -> chest -> neck, the head and the toe base
   come from the neck and ankle frames, and the collars lie between spine3 and the shoulders.
7. **Retarget** by bone-direction IK on our anthropometric skeleton (``body.rest_joints``; its height is set
   so its hip-to-ankle length equals DeepMimic's, 1.80 m): each joint is turned so that its rest bone points
   along the observed bone, starting from the DeepMimic segment's own orientation so that limb twist is kept.
   The collars (which DeepMimic lacks) and the wrists, toes and head (no child bone) keep their rest angles.
8. **Floor**: the clip is moved vertically so that the stance feet stand on z = 0 in our convention (toe
   base 2 cm up when flat; ``amass.floor_height``). DeepMimic's own floor differs by clip: its stance ankles
   sit 5-6 cm up (the foot box's sole is 5 cm below the ankle), and the run dips an ankle to the floor.
"""

from __future__ import annotations

import importlib.util
import json
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from latentrl.datasets.amass import floor_height, foot_speeds, lerp_resample, slerp_resample, sole_heights
from latentrl.datasets.body import (
    axis_angle_to_matrix_np,
    forward_kinematics_np,
    matrix_to_axis_angle_np,
    rest_joints,
    rot_z,
)
from latentrl.datasets.motion_text import make_sequence
from latentrl.errors import DataError, closest
from latentrl.motion.skeleton import FPS, NUM_JOINTS, PARENTS

#: Clip name (path under ``data/motions`` without ``.txt``) -> (text label, loops, turns). A looping clip
#: that turns is tiled with the yaw between its first and last root frame; a straight one with none (their
#: paths are straight, but the root yaw of the last frame is 3-7 degrees off the first one's).
CLIPS: dict[str, tuple[str, bool, bool]] = {
    "humanoid3d_walk": ("walk", True, False),
    "humanoid3d_run": ("run", True, False),
    "humanoid3d_jump": ("jump forward", False, False),
    "walker/0walk_forward": ("walk", True, False),
    "walker/turn_left0": ("turn left", True, True),
    "walker/turn_left1": ("turn left", True, True),
    "walker/turn_right0": ("turn right", True, True),
    "walker/turn_right1": ("turn right", True, True),
}

#: URDF units -> metres (pybullet's DeepMimic environment loads humanoid.urdf with globalScaling=0.25).
URDF_SCALE = 0.25

# DeepMimic links in FK order: name, parent index, joint origin in the parent link frame (URDF units, y up,
# x forward, z right), frame column of the quaternion's w (or of the hinge angle), hinge flag.
_LINKS: tuple[tuple[str, int, tuple[float, float, float], int, bool], ...] = (
    ("root", -1, (0.0, 0.0, 0.0), 4, False),
    ("chest", 0, (0.0, 0.944604, 0.0), 8, False),
    ("neck", 1, (0.0, 0.895576, 0.0), 12, False),
    ("right_hip", 0, (0.0, 0.0, 0.339548), 16, False),
    ("right_knee", 3, (0.0, -1.686184, 0.0), 20, True),
    ("right_ankle", 4, (0.0, -1.639480, 0.0), 21, False),
    ("right_shoulder", 1, (-0.0962, 0.974, 0.73244), 25, False),
    ("right_elbow", 6, (0.0, -1.099152, 0.0), 29, True),
    ("left_hip", 0, (0.0, 0.0, -0.339548), 30, False),
    ("left_knee", 8, (0.0, -1.686184, 0.0), 34, True),
    ("left_ankle", 9, (0.0, -1.639480, 0.0), 35, False),
    ("left_shoulder", 1, (-0.0962, 0.974, -0.73244), 39, False),
    ("left_elbow", 11, (0.0, -1.099152, 0.0), 43, True),
)
_WRIST_OFFSET = (0.0, -1.035788, 0.0)  # fixed joint below each elbow
#: Names of the points returned by ``deepmimic_joint_positions`` (the 13 joints plus the two wrists).
DM_JOINTS: tuple[str, ...] = tuple(link[0] for link in _LINKS) + ("right_wrist", "left_wrist")
_L = {name: i for i, name in enumerate(DM_JOINTS)}

#: DeepMimic (x forward, y up, z right) -> latentrl (x right, y forward, z up): a cyclic permutation.
_M = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
_FRAME_WIDTH = 44
#: Height of the body DeepMimic's legs correspond to: hip-to-ankle 0.8314 m over our 0.461 H.
DM_BODY_HEIGHT_M = URDF_SCALE * (1.686184 + 1.639480) / (0.50 - 0.039)


# --- availability and reading -------------------------------------------------------------------------------


def _motions_dir() -> Path | None:
    try:
        spec = importlib.util.find_spec("pybullet_data")
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    folder = Path(next(iter(spec.submodule_search_locations))) / "data" / "motions"
    return folder if folder.is_dir() else None


def deepmimic_available() -> bool:
    """True when pybullet's data package (with its DeepMimic motions) is installed."""
    return _motions_dir() is not None


def _require() -> Path:
    folder = _motions_dir()
    if folder is None:
        raise DataError("DeepMimic clips need the optional 'mocap' extra: pip install 'latentrl[mocap]' "
                        "(pybullet >= 3.2, which ships pybullet_data/data/motions)")
    return folder


def read_deepmimic_clip(name: str) -> dict:
    """Raw clip: ``frames`` (N, 44) float64, ``times`` (N,) s of each frame, ``loop`` (bool), ``path``."""
    if name not in CLIPS:
        raise DataError(f"unknown DeepMimic clip '{name}'{closest(name, list(CLIPS))}; expected one of "
                        f"{', '.join(CLIPS)}")
    path = _require() / f"{name}.txt"
    if not path.is_file():
        raise DataError(f"{path}: DeepMimic clip not found in the installed pybullet_data, expected "
                        "pybullet 3.2.x")
    try:
        raw = json.loads(path.read_text())
        frames = np.asarray(raw["Frames"], dtype=np.float64)
    except (json.JSONDecodeError, KeyError, ValueError, TypeError) as exc:
        raise DataError(f"{path.name}: cannot read as a DeepMimic clip ({exc}), expected JSON with 'Frames'") from None
    if frames.ndim != 2 or frames.shape[1] != _FRAME_WIDTH or len(frames) < 2:
        raise DataError(f"{path.name}: field 'Frames' has shape {frames.shape}, expected (N, {_FRAME_WIDTH}), N >= 2")
    times = np.concatenate(([0.0], np.cumsum(frames[:-1, 0])))  # a frame's duration leads to the next frame
    return {"frames": frames, "times": times, "loop": CLIPS[name][1] and raw.get("Loop") == "wrap",
            "path": str(path)}


# --- rotations ----------------------------------------------------------------------------------------------


def _quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """(..., 4) quaternion (w, x, y, z) -> (..., 3, 3)."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack((
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ), axis=-1).reshape(*q.shape[:-1], 3, 3)


def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(..., 3, 3) shortest rotation turning direction ``a`` onto direction ``b`` (any lengths)."""
    a = a / np.maximum(np.linalg.norm(a, axis=-1, keepdims=True), 1e-12)
    b = b / np.maximum(np.linalg.norm(b, axis=-1, keepdims=True), 1e-12)
    axis = np.cross(a, b)
    sin = np.linalg.norm(axis, axis=-1, keepdims=True)
    angle = np.arctan2(sin, np.sum(a * b, axis=-1, keepdims=True))
    fallback = np.cross(a, np.where(np.abs(a[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]))
    axis = np.where(sin > 1e-9, axis, fallback)
    axis = axis / np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), 1e-12)
    return axis_angle_to_matrix_np(axis * angle)


def _log(rot: np.ndarray) -> np.ndarray:
    return matrix_to_axis_angle_np(rot)


def _heading(rot: np.ndarray) -> np.ndarray:
    """(...,) yaw (rad, about +z) of a body's forward axis (+y column)."""
    return np.arctan2(-rot[..., 0, 1], rot[..., 1, 1])


# --- clip -> continuous DeepMimic channels in our world frame ----------------------------------------------


def _channels(clip: dict) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) root positions (m) and (N, 13, 3, 3) link rotations (root: world; others: local), our frame."""
    frames = clip["frames"]
    rots = []
    for _, _, _, col, hinge in _LINKS:
        if hinge:  # revolute joints turn about the link's z axis (the body's right)
            angle = frames[:, col]
            c, s = np.cos(angle), np.sin(angle)
            o, z = np.ones_like(c), np.zeros_like(c)
            rots.append(np.stack((c, -s, z, s, c, z, z, z, o), -1).reshape(-1, 3, 3))
        else:
            rots.append(_quat_to_matrix(frames[:, col:col + 4]))
    rot = _M @ np.stack(rots, axis=1) @ _M.T
    return frames[:, 1:4] @ _M.T, rot


def _close_loop(pos: np.ndarray, rot: np.ndarray, turns: bool) -> tuple[np.ndarray, np.ndarray, float]:
    """Spread the first/last mismatch of a cycle linearly over it; returns (pos, rot, cycle yaw)."""
    n = len(pos)
    w = np.linspace(0.0, 1.0, n)
    yaw = float(_heading(rot[-1, 0]) - _heading(rot[0, 0])) if turns else 0.0
    yaw = (yaw + math.pi) % (2 * math.pi) - math.pi
    turn = rot_z(np.array(yaw))
    pos, rot = pos.copy(), rot.copy()
    pos[:, 2] += w * (pos[0, 2] - pos[-1, 2])
    root_err = _log((turn @ rot[0, 0]) @ rot[-1, 0].T)
    rot[:, 0] = axis_angle_to_matrix_np(w[:, None] * root_err) @ rot[:, 0]
    local_err = _log(np.swapaxes(rot[-1, 1:], -1, -2) @ rot[0, 1:])  # (12, 3)
    rot[:, 1:] = rot[:, 1:] @ axis_angle_to_matrix_np(w[:, None, None] * local_err)
    return pos, rot, yaw


def _tile(pos, rot, times, cycles: int, turns: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Chain ``cycles`` copies of a closed cycle (its last frame is the next cycle's first)."""
    pos, rot, yaw = _close_loop(pos, rot, turns)
    period = times[-1] - times[0]
    all_pos, all_rot, all_t = [], [], []
    anchor, heading = pos[0, :2].copy(), 0.0
    for c in range(cycles):
        turn = rot_z(np.array(heading))
        p = pos.copy()
        p[:, :2] = (p[:, :2] - pos[0, :2]) @ turn[:2, :2].T + anchor
        r = rot.copy()
        r[:, 0] = turn @ rot[:, 0]
        last = c == cycles - 1
        all_pos.append(p if last else p[:-1])
        all_rot.append(r if last else r[:-1])
        all_t.append((times if last else times[:-1]) + c * period)
        anchor = p[-1, :2].copy()
        heading += yaw
    return np.concatenate(all_pos), np.concatenate(all_rot), np.concatenate(all_t)


def _clip_channels(name: str, seconds: float | None, cycles: int | None):
    """Root positions and link rotations at 30 fps, tiled and loop-closed where the clip loops."""
    clip = read_deepmimic_clip(name)
    pos, rot = _channels(clip)
    times = clip["times"]
    period = times[-1] - times[0]
    if clip["loop"]:
        count = cycles if cycles is not None else (1 if seconds is None else max(1, math.ceil(seconds / period)))
        pos, rot, times = _tile(pos, rot, times, count, CLIPS[name][2])
    num = int(math.floor(times[-1] * FPS + 0.01)) + 1  # durations are rounded (0.033332 s): keep the last frame
    if seconds is not None:
        num = min(num, int(round(seconds * FPS)))
    out_t = np.arange(num) / FPS
    return lerp_resample(pos, times, out_t), slerp_resample(rot, times, out_t)


# --- forward kinematics and mapping ---------------------------------------------------------------------------


def _dm_fk(pos: np.ndarray, rot: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T, 15, 3) DeepMimic joint positions (m) and (T, 13, 3, 3) link world rotations, our frame."""
    world = np.empty_like(rot)
    points = np.empty((len(pos), len(DM_JOINTS), 3))
    for i, (_, parent, offset, _, _) in enumerate(_LINKS):
        if parent < 0:
            world[:, i], points[:, i] = rot[:, i], pos
            continue
        world[:, i] = world[:, parent] @ rot[:, i]
        points[:, i] = points[:, parent] + world[:, parent] @ (_M @ np.array(offset) * URDF_SCALE)
    for k, elbow in enumerate((_L["right_elbow"], _L["left_elbow"])):
        points[:, len(_LINKS) + k] = points[:, elbow] + world[:, elbow] @ (_M @ np.array(_WRIST_OFFSET) * URDF_SCALE)
    return points, world


def deepmimic_joint_positions(name: str, seconds: float | None = None) -> np.ndarray:
    """(T, 15, 3) joints of the DeepMimic skeleton itself (``DM_JOINTS`` order, before retargeting).

    30 fps, metres, z up, facing +y, DeepMimic's own floor at z = 0; looping clips as one closed cycle.
    """
    return _dm_fk(*_clip_channels(name, seconds, None))[0]


def _smpl_targets(points: np.ndarray, world: np.ndarray, rest: np.ndarray):
    """SMPL-22 observed positions (T, 22, 3) and reference world rotations (T, 22, 3, 3) for the IK."""
    num = len(points)
    pts = {n: points[:, i] for n, i in _L.items()}
    rw = {n: world[:, i] for n, i in _L.items() if i < len(_LINKS)}
    obs = np.zeros((num, NUM_JOINTS, 3))
    ref = np.empty((num, NUM_JOINTS, 3, 3))
    hip_mid = 0.5 * (rest[1] + rest[2])
    obs[:, 0] = pts["root"] + rw["root"] @ (rest[0] - hip_mid)
    for side, (hip, knee, ankle, toe, sho, elb, wri) in (
        ("left", (1, 4, 7, 10, 16, 18, 20)), ("right", (2, 5, 8, 11, 17, 19, 21))
    ):
        obs[:, hip], obs[:, knee], obs[:, ankle] = pts[f"{side}_hip"], pts[f"{side}_knee"], pts[f"{side}_ankle"]
        obs[:, toe] = pts[f"{side}_ankle"] + rw[f"{side}_ankle"] @ (rest[toe] - rest[ankle])
        obs[:, sho], obs[:, elb], obs[:, wri] = pts[f"{side}_shoulder"], pts[f"{side}_elbow"], pts[f"{side}_wrist"]
        ref[:, hip], ref[:, knee], ref[:, ankle] = rw[f"{side}_hip"], rw[f"{side}_knee"], rw[f"{side}_ankle"]
        ref[:, toe] = rw[f"{side}_ankle"]
        ref[:, sho], ref[:, elb], ref[:, wri] = rw[f"{side}_shoulder"], rw[f"{side}_elbow"], rw[f"{side}_elbow"]
    # spine1-3 at our rest fractions of the arc pelvis -> chest -> neck
    neck_len = np.linalg.norm(rest[12] - rest[0])
    legs = (obs[:, 0], pts["chest"], pts["neck"])
    seg = [np.linalg.norm(legs[1] - legs[0], axis=-1), np.linalg.norm(legs[2] - legs[1], axis=-1)]
    total = seg[0] + seg[1]
    bend = _log(np.swapaxes(rw["root"], -1, -2) @ rw["chest"])
    for joint, share in ((3, 1 / 3), (6, 2 / 3), (9, 1.0)):
        arc = (np.linalg.norm(rest[joint] - rest[0]) / neck_len * total)[:, None]
        first = np.clip(arc / np.maximum(seg[0][:, None], 1e-9), 0.0, 1.0)
        second = np.clip((arc - seg[0][:, None]) / np.maximum(seg[1][:, None], 1e-9), 0.0, 1.0)
        obs[:, joint] = np.where(arc <= seg[0][:, None], legs[0] + first * (legs[1] - legs[0]),
                                 legs[1] + second * (legs[2] - legs[1]))
        ref[:, joint] = rw["root"] @ axis_angle_to_matrix_np(share * bend)
    obs[:, 12] = pts["neck"]
    obs[:, 15] = pts["neck"] + rw["neck"] @ (rest[15] - rest[12])
    ref[:, 0], ref[:, 12], ref[:, 15] = rw["root"], rw["neck"], rw["neck"]
    for collar, sho in ((13, 16), (14, 17)):
        frac = np.linalg.norm(rest[collar] - rest[9]) / np.linalg.norm(rest[sho] - rest[9])
        obs[:, collar] = obs[:, 9] + frac * (obs[:, sho] - obs[:, 9])
        ref[:, collar] = rw["chest"]
    return obs, ref


#: Joint -> the child whose bone direction the IK matches (None: keep the rest angle relative to the parent).
_IK_CHILD: dict[int, int | None] = {
    1: 4, 2: 5, 3: 6, 4: 7, 5: 8, 6: 9, 7: 10, 8: 11, 9: 12, 10: None, 11: None, 12: 15, 13: None, 14: None,
    15: None, 16: 18, 17: 19, 18: 20, 19: 21, 20: None, 21: None,
}


def bone_direction_ik(rest: np.ndarray, observed: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """(T, 22, 3, 3) local rotations that point each rest bone of ``rest`` along the ``observed`` one.

    Args:
        rest: (22, 3) our rest joints.
        observed: (T, 22, 3) target joint positions (any body proportions: only directions are used).
        reference: (T, 22, 3, 3) world orientations that carry the twist about each bone; entry 0 is the
            global orientation. A joint's world rotation is the shortest rotation taking
            ``reference @ rest_bone`` onto the observed bone, applied after ``reference``.
    """
    num = len(observed)
    world = np.empty((num, NUM_JOINTS, 3, 3))
    local = np.empty_like(world)
    world[:, 0] = local[:, 0] = reference[:, 0]
    for j in range(1, NUM_JOINTS):
        parent = PARENTS[j]
        child = _IK_CHILD[j]
        if child is None:
            world[:, j] = world[:, parent]
        else:
            bone = reference[:, j] @ (rest[child] - rest[j])
            world[:, j] = _rotation_between(bone, observed[:, child] - observed[:, j]) @ reference[:, j]
        local[:, j] = np.swapaxes(world[:, parent], -1, -2) @ world[:, j]
    return local


# --- public API ----------------------------------------------------------------------------------------------


def _retarget(name: str, seconds: float | None, cycles: int | None, height: float | None) -> dict[str, np.ndarray]:
    pos, rot = _clip_channels(name, seconds, cycles)
    points, world = _dm_fk(pos, rot)
    height = DM_BODY_HEIGHT_M if height is None else float(height)
    scale = height / DM_BODY_HEIGHT_M
    rest = rest_joints(height)
    observed, reference = _smpl_targets(points * scale, world, rest)
    local = bone_direction_ik(rest, observed, reference)
    poses = matrix_to_axis_angle_np(local).astype(np.float32)
    transl = observed[:, 0] - rest[0]
    transl[:, 2] -= floor_height(forward_kinematics_np(rest, axis_angle_to_matrix_np(poses.astype(np.float64)),
                                                       transl), rest)
    return make_sequence(rest, poses, transl, [(0, len(poses), CLIPS[name][0])])


def load_deepmimic_clips(names: Sequence[str] | None = None, seconds: float | None = None,
                         cycles: int | None = None, height: float | None = None) -> list[dict[str, np.ndarray]]:
    """The DeepMimic locomotion clips retargeted to our body, as motion-text sequences (format dicts).

    Args:
        names: clips to load (keys of ``CLIPS``; default all, in ``CLIPS`` order). The result follows this
            order; each sequence carries one text segment (``CLIPS[name][0]``) over all its frames.
        seconds: length of each sequence: looping clips are tiled to it, the jump is cut to it if longer.
            ``None``: one cycle (looping clips, including the closing frame) or the whole jump.
        cycles: tile looping clips this many cycles instead (exclusive with ``seconds``).
        height: body height in metres; default ``DM_BODY_HEIGHT_M`` (1.80 m, DeepMimic's leg length). Other
            heights scale the motion (positions and speeds) by ``height / DM_BODY_HEIGHT_M``.

    Raises:
        DataError: pybullet is not installed (names the ``mocap`` extra), or a clip name is unknown.
    """
    _require()
    if seconds is not None and cycles is not None:
        raise DataError("load_deepmimic_clips: both seconds and cycles given, expected at most one")
    if seconds is not None and not seconds * FPS >= 2:
        raise DataError(f"load_deepmimic_clips: seconds = {seconds}, expected at least {2 / FPS:.3f}")
    if cycles is not None and cycles < 1:
        raise DataError(f"load_deepmimic_clips: cycles = {cycles}, expected >= 1")
    if height is not None and not 0.5 <= height <= 2.5:
        raise DataError(f"load_deepmimic_clips: height = {height} m, expected 0.5-2.5 m")
    names = list(CLIPS) if names is None else [names] if isinstance(names, str) else list(names)
    return [_retarget(name, seconds, cycles, height) for name in names]


# --- gait statistics ------------------------------------------------------------------------------------------


def foot_contacts(seq: dict[str, np.ndarray], height_m: float = 0.04, speed_m_s: float = 0.6) -> np.ndarray:
    """(T, 2) bool: each foot (left, right) is planted.

    A foot is planted where its sole (``amass.sole_heights``) is below ``height_m`` and it moves slowly (its
    slower joint below ``speed_m_s``); contacts or gaps shorter than 3 frames inside the sequence are removed.
    """
    joints = seq["joints"].astype(np.float64)
    mask = (sole_heights(joints, seq["rest_joints"].astype(np.float64)) < height_m) & (
        foot_speeds(joints) < speed_m_s)
    return np.stack([_debounce(mask[:, leg], 3) for leg in range(2)], axis=-1)


def _debounce(mask: np.ndarray, min_frames: int) -> np.ndarray:
    """Fill interior gaps and drop interior contacts shorter than ``min_frames``."""
    mask = mask.copy()
    for value in (False, True):
        runs = (mask == value).astype(int)
        edges = np.flatnonzero(np.diff(np.concatenate(([0], runs, [0]))))
        for a, b in zip(edges[::2], edges[1::2]):
            if b - a < min_frames and a > 0 and b < len(mask):
                mask[a:b] = not value
    return mask


def gait_statistics(seqs: Sequence[dict[str, np.ndarray]]) -> dict[str, dict[str, float]]:
    """Gait figures per skill over its single-label frames.

    ``cadence_steps_s`` (steps/s, from the intervals between touch-downs of either foot, ``foot_contacts``),
    ``step_length_m`` (mean speed / cadence), ``turn_deg_s`` (signed mean yaw rate of the pelvis, + = left)
    and ``pelvis_height_m`` (mean).
    """
    from latentrl.datasets.locomotion import TEXT_TO_SKILL

    acc: dict[str, dict[str, float]] = {}
    for seq in seqs:
        num = len(seq["transl"])
        count = np.zeros(num, dtype=int)
        owner = np.full(num, "", dtype=object)
        for a, b, text in zip(seq["seg_start"], seq["seg_end"], seq["seg_text"]):
            count[a:b] += 1
            owner[a:b] = TEXT_TO_SKILL.get(str(text), str(text))
        pure = count == 1
        contact = foot_contacts(seq)
        onsets = sorted(int(t) for leg in range(2) for t in np.flatnonzero(contact[1:, leg] & ~contact[:-1, leg]) + 1)
        heading = np.unwrap(_heading(axis_angle_to_matrix_np(seq["poses"][:, 0].astype(np.float64))))
        pelvis = seq["joints"][:, 0].astype(np.float64)
        speed = np.linalg.norm(np.diff(pelvis[:, :2], axis=0), axis=-1) * FPS
        for skill in set(owner[pure]):
            a = acc.setdefault(skill, {"steps": 0.0, "step_time": 0.0, "turn": 0.0, "pairs": 0.0, "speed": 0.0,
                                       "height": 0.0, "frames": 0.0})
            mask = pure & (owner == skill)
            pair = mask[1:] & mask[:-1]
            a["pairs"] += pair.sum()
            a["turn"] += np.diff(heading)[pair].sum()
            a["speed"] += speed[pair].sum()
            a["height"] += pelvis[mask, 2].sum()
            a["frames"] += mask.sum()
            for t0, t1 in zip(onsets[:-1], onsets[1:]):
                if mask[t0:t1 + 1].all():
                    a["steps"] += 1
                    a["step_time"] += (t1 - t0) / FPS
    out = {}
    for skill, a in acc.items():
        cadence = a["steps"] / a["step_time"] if a["step_time"] else float("nan")
        speed = float(a["speed"]) / max(int(a["pairs"]), 1)
        out[skill] = {
            "cadence_steps_s": round(float(cadence), 3),
            "step_length_m": round(float(speed / cadence), 3) if a["steps"] else float("nan"),
            "turn_deg_s": round(math.degrees(float(a["turn"]) * FPS / max(int(a["pairs"]), 1)), 2),
            "pelvis_height_m": round(float(a["height"]) / max(int(a["frames"]), 1), 3),
        }
    return out


def mocap_reference_statistics(names: Sequence[str] | None = None, cycles: int = 4) -> dict:
    """Statistics of the retargeted DeepMimic clips, comparable with ``locomotion.dataset_statistics``.

    Returns ``{"skills": {skill: {...}}, "clips": {name: {...}}, "frames": int}``. Each entry holds
    ``dataset_statistics``' fields (``frames``, ``single_label_frames``, ``speed_m_s``, ``skate_cm_s``,
    ``skate_xy_cm_s``, ``floor_cm``) plus ``gait_statistics``' (``cadence_steps_s``, ``step_length_m``,
    ``turn_deg_s``, ``pelvis_height_m``). Looping clips are tiled ``cycles`` times, so speeds are exact cycle
    averages; the jump is used once. Raises ``DataError`` without pybullet.
    """
    from latentrl.datasets.locomotion import dataset_statistics

    names = list(CLIPS) if names is None else [names] if isinstance(names, str) else list(names)
    seqs = load_deepmimic_clips(names, cycles=cycles)
    stats = dataset_statistics(seqs)
    gait = gait_statistics(seqs)
    skills = {k: {**v, **gait.get(k, {})} for k, v in stats["skills"].items()}
    clips = {}
    for name, seq in zip(names, seqs):
        one = dataset_statistics([seq])["skills"]
        skill, values = next(iter(one.items()))
        clips[name] = {"text": CLIPS[name][0], "seconds": round((len(seq["transl"]) - 1) / FPS, 3), **values,
                       **gait_statistics([seq]).get(skill, {})}
    return {"frames": stats["frames"], "skills": skills, "clips": clips}


__all__ = [
    "CLIPS",
    "DM_BODY_HEIGHT_M",
    "DM_JOINTS",
    "bone_direction_ik",
    "deepmimic_available",
    "deepmimic_joint_positions",
    "foot_contacts",
    "gait_statistics",
    "load_deepmimic_clips",
    "mocap_reference_statistics",
    "read_deepmimic_clip",
]
