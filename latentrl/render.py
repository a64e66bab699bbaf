"""Motion files and pictures: the shared ``.npz`` motion format, skeleton animations and BVH export.

BVH (:func:`save_bvh`, :func:`load_bvh`): the SMPL-22 skeleton, Y-up, centimetres, 6 channels per joint
so that the file reproduces the generated joint positions exactly (docs/evaluation.md, section 6).

Motion ``.npz``: :class:`latentrl.motion.clip.MotionClip` holds the shared format and its schema;
:func:`save_motion_npz` and :func:`load_motion_npz` are re-exported from there.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from latentrl.errors import DataError
from latentrl.motion.clip import (  # noqa: F401  (the old address)
    MAX_COORD_M,
    MAX_FPS,
    MotionClip,
    check_motion,
    load_motion_npz,
    save_motion_npz,
)
from latentrl.motion.skeleton import FPS, JOINT_NAMES, NUM_JOINTS, PARENTS, SMPL_REST_OFFSETS, rest_offsets
from latentrl.safe_io import atomic_write_bytes, atomic_write_with


def render_gif(
    path: str | Path,
    joints: np.ndarray,
    fps: float = FPS,
    texts: Sequence[str] | None = None,
    title: str = "",
    stride: int = 3,
    size: float = 4.0,
    goals: np.ndarray | None = None,
) -> Path:
    """Animate a skeleton (T, 22, 3) as a GIF: a 3-D view that follows the pelvis, with its track.

    ``stride`` keeps every n-th frame; the GIF plays in real time at ``fps / stride`` (the default 3
    gives 10 frames/s: GIF frame times are whole centiseconds, so 30 / 2 = 15 frames/s would play ~10%
    fast). Goals and the pelvis track are drawn only where they lie inside the moving box (3-D axes do
    not clip), the title and the prompt sit above the axes, and a legend names what is drawn.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter
    from matplotlib.lines import Line2D

    joints = np.asarray(joints, dtype=np.float32)
    stride = max(1, int(stride))
    frames = list(range(0, len(joints), stride))
    fig = plt.figure(figsize=(size, size))
    ax = fig.add_axes((0.0, 0.07, 1.0, 0.78), projection="3d")
    pelvis = joints[:, 0]
    lines = [ax.plot([], [], [], lw=2, color="tab:blue" if j % 2 else "tab:red")[0] for j in range(1, NUM_JOINTS)]
    track = ax.plot([], [], [], lw=1, color="gray")[0]
    goal_marks = ax.plot([], [], [], "o", ms=5, color="tab:green")[0]
    goals = None if goals is None or not len(goals) else np.asarray(goals, dtype=np.float32)
    heading = fig.text(0.02, 0.98, title, va="top", fontsize=7, wrap=True)
    label = fig.text(0.02, 0.89, "", va="top", fontsize=8, weight="bold")
    fig.legend(handles=[Line2D([], [], color="tab:red", lw=2, label="left"),
                        Line2D([], [], color="tab:blue", lw=2, label="right"),
                        Line2D([], [], color="gray", lw=1, label="pelvis track"),
                        Line2D([], [], color="tab:green", marker="o", ls="none", label="goal")],
               loc="lower center", ncol=4, fontsize=6, frameon=False)
    half = 1.2

    def inside(xy: np.ndarray, cx: float, cy: float) -> np.ndarray:
        return (np.abs(xy[:, 0] - cx) <= half) & (np.abs(xy[:, 1] - cy) <= half)

    def draw(i: int):
        p = joints[i]
        cx, cy = float(pelvis[i, 0]), float(pelvis[i, 1])
        ax.set_xlim(cx - half, cx + half)
        ax.set_ylim(cy - half, cy + half)
        ax.set_zlim(0, 2 * half)
        for line, j in zip(lines, range(1, NUM_JOINTS)):
            a, b = p[j], p[PARENTS[j]]
            line.set_data([a[0], b[0]], [a[1], b[1]])
            line.set_3d_properties([a[2], b[2]])
        trail = pelvis[: i + 1, :2].copy()
        trail[~inside(trail, cx, cy)] = np.nan  # a gap, not a line floating outside the box
        track.set_data(trail[:, 0], trail[:, 1])
        track.set_3d_properties(np.zeros(i + 1))
        if goals is not None:
            shown = goals[inside(goals, cx, cy)]
            goal_marks.set_data(shown[:, 0], shown[:, 1])
            goal_marks.set_3d_properties(np.zeros(len(shown)))
        text = texts[i] if texts is not None and i < len(texts) else ""
        label.set_text(f"{i / fps:5.2f} s  {text}".strip())
        return [*lines, track, goal_marks, heading, label]

    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    anim = FuncAnimation(fig, draw, frames=frames, blit=False)
    try:  # a fresh temporary file, renamed over the GIF: never written through a link
        return atomic_write_with(path, lambda tmp: anim.save(tmp, writer=PillowWriter(fps=fps / stride)))
    finally:
        plt.close(fig)


# --------------------------------------------------------------------------- BVH
# BVH is Y-up by convention; latentrl's world is z-up. ZUP_TO_YUP maps (x right, y forward, z up) to
# (x right, y up, z backward): a proper rotation (-90 degrees about x), so a body facing +y (ours)
# faces -z in the file, which Blender's default BVH import (forward -Z, up Y) turns back into +y.
ZUP_TO_YUP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
BVH_UNITS_PER_M = 100.0
"""BVH files are written in centimetres (the usual mocap unit; import with scale 0.01 in Blender)."""
BVH_ROTATION_CHANNELS = ("Zrotation", "Xrotation", "Yrotation")
"""Channel order of every joint's rotation: R = Rz(z) Rx(x) Ry(y) (column vectors), degrees."""

_SMPL_REST_OFFSETS = SMPL_REST_OFFSETS  # the old address (tests and scripts import it from here)
# End Site offsets of the leaf joints (toes forward, head up, hands along the arm), metres, z up.
_END_SITES = {10: (0.0, 0.06, 0.0), 11: (0.0, 0.06, 0.0), 15: (0.0, 0.0, 0.12), 20: (-0.09, 0.0, 0.0),
              21: (0.09, 0.0, 0.0)}


def _children(j: int) -> list[int]:
    return [c for c, p in enumerate(PARENTS) if p == j]


def _dfs_order() -> list[int]:
    """SMPL joints in BVH's depth-first hierarchy order (children in index order)."""
    order, stack = [], [0]
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(reversed(_children(j)))
    return order


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-12, n, 1.0)


def _swing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(T, 3, 3) shortest-arc rotations taking unit vectors a (T, 3) onto unit vectors b (T, 3)."""
    v, c = np.cross(a, b), np.einsum("ti,ti->t", a, b)
    k = np.zeros(a.shape[:1] + (3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    k -= np.swapaxes(k, 1, 2)
    rot = np.eye(3) + k + k @ k / np.maximum(1.0 + c, 1e-12)[:, None, None]
    flip = c < -1.0 + 1e-9  # opposite vectors: half turn about any axis perpendicular to a
    if flip.any():
        axis = np.cross(a[flip], np.array([1.0, 0.0, 0.0]))
        axis = np.where(np.linalg.norm(axis, axis=-1, keepdims=True) < 1e-6, np.cross(a[flip], [0.0, 1.0, 0.0]), axis)
        u = _unit(axis)
        rot[flip] = 2.0 * u[:, :, None] * u[:, None, :] - np.eye(3)
    return rot


def _kabsch(rest: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotations best mapping rest vectors (K, 3) onto observed ones (T, K, 3) (least squares)."""
    u, _, vt = np.linalg.svd(np.einsum("kc,tkd->tcd", rest, observed))
    v = np.swapaxes(vt, 1, 2)
    d = np.sign(np.linalg.det(v @ np.swapaxes(u, 1, 2)))
    v[:, :, 2] *= np.where(d == 0, 1.0, d)[:, None]
    return v @ np.swapaxes(u, 1, 2)


_bone_offsets = rest_offsets


def _global_rotations(joints: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(T, 22, 3, 3) world rotations that swing each joint's rest bones onto the observed ones.

    Joints with several children (pelvis, spine3) take the least-squares rotation of all their
    bones; joints with one child the shortest arc from the parent-rotated rest bone (so twist is
    inherited from the parent and stays smooth); leaves copy their parent.
    """
    t = len(joints)
    glob = np.zeros((t, NUM_JOINTS, 3, 3))
    for j in range(NUM_JOINTS):
        base = glob[:, PARENTS[j]] if j > 0 else np.broadcast_to(np.eye(3), (t, 3, 3))
        kids = _children(j)
        if len(kids) > 1:
            glob[:, j] = _kabsch(offsets[kids], joints[:, kids] - joints[:, j : j + 1])
        elif kids:
            observed = joints[:, kids[0]] - joints[:, j]
            a = _unit(base @ offsets[kids[0]])
            b = np.where(np.linalg.norm(observed, axis=-1, keepdims=True) > 1e-9, _unit(observed), a)
            glob[:, j] = _swing(a, b) @ base
        else:
            glob[:, j] = base
    return glob


def _axis_rotation(axis: str, degrees: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotations by ``degrees`` (T,) about the x, y or z axis."""
    r = np.radians(degrees)
    c, s = np.cos(r), np.sin(r)
    m = np.zeros(r.shape + (3, 3))
    i, k = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    m[:, "xyz".index(axis), "xyz".index(axis)] = 1.0
    m[:, i, i], m[:, i, k], m[:, k, i], m[:, k, k] = c, -s, s, c
    return m


def _euler_zxy_degrees(rot: np.ndarray) -> np.ndarray:
    """(T, 3, 3) -> (T, 3) angles (z, x, y) in degrees with rot = Rz Rx Ry (the channel order)."""
    x = np.arcsin(np.clip(rot[:, 2, 1], -1.0, 1.0))
    z = np.arctan2(-rot[:, 0, 1], rot[:, 1, 1])
    y = np.arctan2(-rot[:, 2, 0], rot[:, 2, 2])
    lock = np.abs(rot[:, 2, 1]) > 1.0 - 1e-9  # gimbal lock: put everything in z (x is +-90)
    z = np.where(lock, np.arctan2(rot[:, 1, 0], rot[:, 0, 0]), z)
    y = np.where(lock, 0.0, y)
    return np.degrees(np.stack((z, x, y), axis=-1))


def _zxy_matrix(angles: np.ndarray) -> np.ndarray:
    return _axis_rotation("z", angles[:, 0]) @ _axis_rotation("x", angles[:, 1]) @ _axis_rotation("y", angles[:, 2])


def _bvh_channels(joints_y: np.ndarray, glob_zup: np.ndarray) -> np.ndarray:
    """(T, 22, 6) channel values per joint: position (cm, in the parent's frame) then Z, X, Y rotation (deg).

    The written (rounded) angles are re-composed before the translations are derived from them, so
    the file's forward kinematics reproduce ``joints_y`` exactly, whatever rotations were chosen.
    """
    t = len(joints_y)
    glob_y = ZUP_TO_YUP @ glob_zup @ ZUP_TO_YUP.T
    values = np.zeros((t, NUM_JOINTS, 6))
    chain = np.zeros((t, NUM_JOINTS, 3, 3))
    for j in range(NUM_JOINTS):
        parent = np.broadcast_to(np.eye(3), (t, 3, 3)) if j == 0 else chain[:, PARENTS[j]]
        angles = np.round(_euler_zxy_degrees(np.swapaxes(parent, 1, 2) @ glob_y[:, j]), 6)
        chain[:, j] = parent @ _zxy_matrix(angles)
        rel = joints_y[:, j] - (joints_y[:, PARENTS[j]] if j > 0 else 0.0)
        values[:, j, :3] = np.einsum("tji,tj->ti", parent, rel)  # parent^T @ rel
        values[:, j, 3:] = angles
    return values


def _bvh_hierarchy(offsets_y: np.ndarray, root_offset: np.ndarray) -> list[str]:
    """HIERARCHY lines: joints depth-first, 6 channels each, End Sites on the leaves (file units and axes)."""
    lines = ["HIERARCHY"]
    channels = "CHANNELS 6 Xposition Yposition Zposition " + " ".join(BVH_ROTATION_CHANNELS)

    def emit(j: int, depth: int) -> None:
        pad = "  " * depth
        off = root_offset if j == 0 else offsets_y[j]
        lines.extend([f"{pad}{'ROOT' if j == 0 else 'JOINT'} {JOINT_NAMES[j]}", f"{pad}{{",
                      f"{pad}  OFFSET {off[0]:.5f} {off[1]:.5f} {off[2]:.5f}", f"{pad}  {channels}"])
        for c in _children(j):
            emit(c, depth + 1)
        if j in _END_SITES:
            end = ZUP_TO_YUP @ np.asarray(_END_SITES[j]) * BVH_UNITS_PER_M
            lines.extend([f"{pad}  End Site", f"{pad}  {{", f"{pad}    OFFSET {end[0]:.5f} {end[1]:.5f} {end[2]:.5f}",
                          f"{pad}  }}"])
        lines.append(f"{pad}}}")

    emit(0, 0)
    return lines


def save_bvh(path: str | Path, joints, fps: float = FPS) -> Path:
    """Write world joints (T, 22, 3) (metres, z up) as a BVH file of the SMPL-22 skeleton, atomically.

    The file is Y-up (:data:`ZUP_TO_YUP`) and in centimetres. OFFSETs are a T-pose with the motion's
    median bone lengths. Generated joint positions are not rigid (bone lengths drift a little), so
    rotations alone cannot reproduce them: **every joint has 6 channels**, its position in the parent's
    frame (which replaces the OFFSET, as Blender and MotionBuilder read non-root position channels)
    and a ZXY rotation that swings the rest bones onto the observed ones, so the skeleton also
    animates sensibly in tools that ignore the child positions. :func:`load_bvh` reproduces the
    input positions to well under 1 mm. BVH has no comment syntax, so these conventions are
    documented here and in docs/evaluation.md, not inside the file.
    """
    joints, fps = check_motion(joints, fps, str(path))
    offsets = _bone_offsets(joints)
    leg = offsets[1] + offsets[4] + offsets[7] + offsets[10]  # rest pelvis height: the rest pose stands on the floor
    root_offset = ZUP_TO_YUP @ np.array([0.0, 0.0, max(-leg[2], 0.0)]) * BVH_UNITS_PER_M
    joints_y = joints @ ZUP_TO_YUP.T * BVH_UNITS_PER_M
    values = _bvh_channels(joints_y, _global_rotations(joints, offsets))
    order = _dfs_order()
    lines = _bvh_hierarchy(offsets @ ZUP_TO_YUP.T * BVH_UNITS_PER_M, root_offset)
    lines += ["MOTION", f"Frames: {len(joints)}", f"Frame Time: {1.0 / float(fps):.8f}"]
    flat = values[:, order].reshape(len(joints), -1) + 0.0  # + 0.0 turns -0.0 into 0.0
    lines += [" ".join(f"{v:.6f}" for v in row) for row in flat]
    return atomic_write_bytes(path, ("\n".join(lines) + "\n").encode("ascii"))


def _parse_hierarchy(tokens: list[str], source: str) -> tuple[list[str], list[int], list, list[list[str]], int]:
    """BVH HIERARCHY tokens -> (names, parents, offsets, channels, index of the token after it)."""
    names, parents, offsets, channels = [], [], [], []
    stack: list[int] = []
    i, end_site = 1, False
    while i < len(tokens) and tokens[i].upper() != "MOTION":
        tok = tokens[i].upper()
        if tok in ("ROOT", "JOINT"):
            names.append(tokens[i + 1])
            parents.append(stack[-1] if stack else -1)
            i += 2
        elif tok == "END":  # "End Site": its offset only shapes bone tails
            end_site, i = True, i + 2
        elif tok == "{":
            stack.append(-2 if end_site else len(names) - 1)
            end_site, i = False, i + 1
        elif tok == "}":
            stack.pop()
            i += 1
        elif tok == "OFFSET":
            if stack[-1] != -2:
                offsets.append([float(v) for v in tokens[i + 1 : i + 4]])
            i += 4
        elif tok == "CHANNELS":
            n = int(tokens[i + 1])
            channels.append(tokens[i + 2 : i + 2 + n])
            i += 2 + n
        else:
            raise DataError(f"{source}: unexpected token '{tokens[i]}' in HIERARCHY")
    if not names or len(offsets) != len(names) or len(channels) != len(names):
        raise DataError(f"{source}: every ROOT/JOINT needs an OFFSET and CHANNELS")
    return names, parents, offsets, channels, i


def _bvh_forward_kinematics(offsets, channels, parents, values: np.ndarray) -> np.ndarray:
    """(T, J, 3) joint positions in file units and axes from channel values (T, C).

    Position channels give the joint's translation in its parent's frame (replacing the OFFSET);
    rotation channels compose in the listed order (``Zrotation Xrotation Yrotation`` -> Rz Rx Ry).
    """
    t, col = len(values), 0
    pos = np.zeros((t, len(offsets), 3))
    glob = np.zeros((t, len(offsets), 3, 3))
    for j, chans in enumerate(channels):
        trans = np.broadcast_to(np.asarray(offsets[j], dtype=np.float64), (t, 3)).copy()
        rot = np.broadcast_to(np.eye(3), (t, 3, 3))
        for name in chans:
            axis, kind = name[0].lower(), name[1:].lower()
            if kind == "position":
                trans[:, "xyz".index(axis)] = values[:, col]
            else:
                rot = rot @ _axis_rotation(axis, values[:, col])
            col += 1
        p = parents[j]
        pos[:, j] = trans if p < 0 else pos[:, p] + np.einsum("tij,tj->ti", glob[:, p], trans)
        glob[:, j] = rot if p < 0 else glob[:, p] @ rot
    return pos


def load_bvh(path: str | Path) -> dict[str, np.ndarray]:
    """Read a BVH file (a small parser for round trips and checks) back into latentrl's convention.

    Returns ``joints`` (T, J, 3) world metres, z up (the inverse of :func:`save_bvh`'s axes and
    centimetres), ``fps``, ``names`` and ``parents``. Joints come in SMPL order when the file holds
    exactly the 22 SMPL joint names, otherwise in file order.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"BVH file not found: {path}")
    tokens = path.read_text(encoding="ascii", errors="replace").split()
    if not tokens or tokens[0].upper() != "HIERARCHY":
        raise DataError(f"{path}: not a BVH file (it must start with HIERARCHY)")
    try:
        names, parents, offsets, channels, i = _parse_hierarchy(tokens, str(path))
        frames, frame_time = int(tokens[i + 2]), float(tokens[i + 5])
        width = sum(len(c) for c in channels)
        values = np.asarray(tokens[i + 6 : i + 6 + frames * width], dtype=np.float64)
    except (IndexError, ValueError) as exc:
        raise DataError(f"{path}: malformed BVH ({str(exc)[:120]})") from None
    if values.size != frames * width:
        raise DataError(f"{path}: MOTION holds {values.size} values, expected {frames} frames x {width} channels")
    joints = _bvh_forward_kinematics(offsets, channels, parents, values.reshape(frames, width))
    joints = joints @ ZUP_TO_YUP / BVH_UNITS_PER_M  # inverse of the proper rotation is its transpose
    if sorted(names) == sorted(JOINT_NAMES):
        order = [names.index(n) for n in JOINT_NAMES]
        joints, names = joints[:, order], list(JOINT_NAMES)
        parents = list(PARENTS)
    return {"joints": joints.astype(np.float32), "fps": np.float32(1.0 / frame_time), "names": np.asarray(names),
            "parents": np.asarray(parents, dtype=np.int32)}
