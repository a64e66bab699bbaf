"""Time the matplotlib GIF renderer latentrl used until 2026-11-27 against today's Pillow renderer, same motion.

    python tools/render_comparison.py MOTION.npz [--out DIR] [--repeats 3]

Draws MOTION.npz (the shared motion format, e.g. from ``latentrl motion sample``) as a GIF with the
old renderer (kept below only for this comparison), as a GIF with :func:`latentrl.render.render_video`
(both every 3rd frame, as ``latentrl eval`` draws), and as an MP4 of every frame; prints seconds per
file (median of ``--repeats`` rounds in which the four take turns) and per second of motion, and the
speed-up over the old GIF (docs/benchmarks.md).
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np

from latentrl.motion.skeleton import NUM_JOINTS, PARENTS
from latentrl.render import GIF_STRIDE, load_motion_npz, render_video
from latentrl.timing import hardware


def old_matplotlib_gif(path, joints, fps=30.0, texts=None, title="", stride=3, size=4.0, goals=None):
    """The former ``render_gif``: a matplotlib 3-D skeleton (400x400, no floor) following the pelvis."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.animation import FuncAnimation, PillowWriter
    from matplotlib.lines import Line2D

    joints = np.asarray(joints, dtype=np.float32)
    frames = list(range(0, len(joints), max(1, int(stride))))
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

    def inside(xy, cx, cy):
        return (np.abs(xy[:, 0] - cx) <= half) & (np.abs(xy[:, 1] - cy) <= half)

    def draw(i):
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
        trail[~inside(trail, cx, cy)] = np.nan
        track.set_data(trail[:, 0], trail[:, 1])
        track.set_3d_properties(np.zeros(i + 1))
        if goals is not None:
            shown = goals[inside(goals, cx, cy)]
            goal_marks.set_data(shown[:, 0], shown[:, 1])
            goal_marks.set_3d_properties(np.zeros(len(shown)))
        text = texts[i] if texts is not None and i < len(texts) else ""
        label.set_text(f"{i / fps:5.2f} s  {text}".strip())
        return [*lines, track, goal_marks, heading, label]

    anim = FuncAnimation(fig, draw, frames=frames, blit=False)
    try:
        anim.save(str(path), writer=PillowWriter(fps=fps / stride))
    finally:
        plt.close(fig)
    return Path(path)


def timed_rows(rows: dict, repeats: int) -> dict[str, float]:
    """Median wall seconds of each row's call; the rows take turns, so a change in machine load hits all alike."""
    times: dict[str, list[float]] = {name: [] for name in rows}
    for _ in range(repeats):
        for name, fn in rows.items():
            start = time.perf_counter()
            fn()
            times[name].append(time.perf_counter() - start)
    return {name: float(np.median(t)) for name, t in times.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("motion", help="motion .npz (shared format)")
    parser.add_argument("--out", help="folder for the three files (default: a temporary folder)")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    motion = load_motion_npz(args.motion)
    joints, fps = motion["joints"], float(motion["fps"])
    texts = list(motion["texts"]) if "texts" in motion else None
    out = Path(args.out or tempfile.mkdtemp(prefix="render-"))
    out.mkdir(parents=True, exist_ok=True)
    seconds = len(joints) / fps
    rows = timed_rows({
        "old matplotlib GIF": lambda: old_matplotlib_gif(out / "old.gif", joints, fps, texts, stride=GIF_STRIDE),
        "Pillow GIF (body)": lambda: render_video(out / "new.gif", joints, fps, texts),
        "Pillow GIF (skeleton)": lambda: render_video(out / "skeleton.gif", joints, fps, texts, style="skeleton"),
        "Pillow MP4 (body, every frame)": lambda: render_video(out / "new.mp4", joints, fps, texts),
    }, args.repeats)
    old = rows["old matplotlib GIF"]
    print(f"motion: {args.motion} ({len(joints)} frames, {seconds:.1f} s); hardware: {hardware()}")
    for name, s in rows.items():
        print(f"{name:32s} {s:7.2f} s  {s / seconds:6.3f} s per motion second  speed-up {old / s:5.1f}x")
    print(json.dumps({"motion_seconds": seconds, "seconds": rows, "out": str(out)}))


if __name__ == "__main__":
    main()
