"""Motion files and pictures: the shared ``.npz`` motion format and skeleton animations.

Motion ``.npz`` (written by every command that writes motion; load with ``allow_pickle=False``):

=============  ==================  =====================================================
key            shape, dtype        meaning
=============  ==================  =====================================================
``joints``     (T, 22, 3) float32  world joint positions, metres, z up, SMPL-22 order
``fps``        () float32          frames per second (30)
``texts``      (T,) unicode        the prompt in force at each frame ('' for seed frames)
``features``   (T, 276) float32    optional: DART features in world coordinates
``actions``    (S, D) float32      optional: the latent noise of each primitive (RL action)
``primitive``  (T,) int32          optional: which primitive produced each frame (-1 = seed)
=============  ==================  =====================================================
"""

from __future__ import annotations

import io
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from latentrl.errors import DataError
from latentrl.motion.skeleton import FPS, NUM_JOINTS, PARENTS
from latentrl.safe_io import atomic_write_bytes


def save_motion_npz(
    path: str | Path,
    joints,
    fps: float = FPS,
    texts: Sequence[str] | None = None,
    features=None,
    actions=None,
    primitive=None,
    **extra,
) -> Path:
    """Write one motion in the shared format, atomically."""
    joints = np.asarray(joints, dtype=np.float32)
    if joints.ndim != 3 or joints.shape[1:] != (NUM_JOINTS, 3):
        raise DataError(f"{path}: joints must be (T, {NUM_JOINTS}, 3), got {joints.shape}")
    data = {"joints": joints, "fps": np.float32(fps)}
    t = len(joints)
    data["texts"] = np.asarray(list(texts) if texts is not None else [""] * t, dtype=str)
    if len(data["texts"]) != t:
        raise DataError(f"{path}: texts has {len(data['texts'])} entries for {t} frames")
    if features is not None:
        data["features"] = np.asarray(features, dtype=np.float32)
    if actions is not None:
        data["actions"] = np.asarray(actions, dtype=np.float32).reshape(len(actions), -1)
    if primitive is not None:
        data["primitive"] = np.asarray(primitive, dtype=np.int32)
    for key, value in extra.items():
        data[key] = np.asarray(value)
    buf = io.BytesIO()
    np.savez_compressed(buf, **data)
    return atomic_write_bytes(path, buf.getvalue())


def load_motion_npz(path: str | Path) -> dict[str, np.ndarray]:
    """Read a motion ``.npz``; checks the required keys and shapes."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"motion file not found: {path}")
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except Exception as exc:  # numpy raises several types for broken archives
        raise DataError(f"{path}: not a readable motion .npz ({str(exc)[:120]})") from None
    joints = data.get("joints")
    if joints is None or joints.ndim != 3 or joints.shape[1:] != (NUM_JOINTS, 3):
        raise DataError(
            f"{path}: field 'joints' must be (T, {NUM_JOINTS}, 3), got {None if joints is None else joints.shape}"
        )
    data.setdefault("fps", np.float32(FPS))
    return data


def render_gif(
    path: str | Path,
    joints: np.ndarray,
    fps: float = FPS,
    texts: Sequence[str] | None = None,
    title: str = "",
    stride: int = 2,
    size: float = 4.0,
    goals: np.ndarray | None = None,
) -> Path:
    """Animate a skeleton (T, 22, 3) as a GIF: a 3-D view that follows the pelvis, with its track.

    ``stride`` keeps every n-th frame (the GIF plays at ``fps / stride``).
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter

    joints = np.asarray(joints, dtype=np.float32)
    frames = list(range(0, len(joints), max(1, stride)))
    fig = plt.figure(figsize=(size, size))
    ax = fig.add_subplot(111, projection="3d")
    pelvis = joints[:, 0]
    lines = [ax.plot([], [], [], lw=2, color="tab:blue" if j % 2 else "tab:red")[0] for j in range(1, NUM_JOINTS)]
    track = ax.plot([], [], [], lw=1, color="gray")[0]
    if goals is not None and len(goals):
        goals = np.asarray(goals)
        ax.scatter(goals[:, 0], goals[:, 1], np.zeros(len(goals)), color="tab:green", s=20)
    label = ax.text2D(0.02, 0.95, "", transform=ax.transAxes)
    half = 1.2

    def draw(i: int):
        p = joints[i]
        cx, cy = pelvis[i, 0], pelvis[i, 1]
        ax.set_xlim(cx - half, cx + half)
        ax.set_ylim(cy - half, cy + half)
        ax.set_zlim(0, 2 * half)
        for line, j in zip(lines, range(1, NUM_JOINTS)):
            a, b = p[j], p[PARENTS[j]]
            line.set_data([a[0], b[0]], [a[1], b[1]])
            line.set_3d_properties([a[2], b[2]])
        track.set_data(pelvis[: i + 1, 0], pelvis[: i + 1, 1])
        track.set_3d_properties(np.zeros(i + 1))
        text = texts[i] if texts is not None and i < len(texts) else ""
        label.set_text(f"{title}  {i / fps:5.2f} s  {text}".strip())
        return [*lines, track, label]

    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_zlabel("z (m)")
    anim = FuncAnimation(fig, draw, frames=frames, blit=False)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp.gif")
    anim.save(tmp, writer=PillowWriter(fps=max(1, round(fps / max(1, stride)))))
    plt.close(fig)
    tmp.replace(path)
    return path
