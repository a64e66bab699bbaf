"""Render procedural locomotion to PNG for a visual check: a film strip of poses plus foot heights.

Usage::

    python tools/preview_locomotion.py --skill walk --seed 0 --out /tmp/walk.png
    python tools/preview_locomotion.py --file data/loco/seq_00003.npz --start 60 --out /tmp/seq3.png

The strip is drawn in the body's side plane (forward to the right, z up) and, below it, from the front, so
knees and elbows should bend forward, arms swing opposite the legs, and stance feet sit on the floor line.
"""

from __future__ import annotations

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from latentrl.datasets.locomotion import LocomotionConfig, foot_skate, generate_sequences  # noqa: E402
from latentrl.datasets.motion_text import read_sequence  # noqa: E402
from latentrl.motion.skeleton import PARENTS  # noqa: E402

LEFT = {1, 4, 7, 10, 13, 16, 18, 20}
RIGHT = {2, 5, 8, 11, 14, 17, 19, 21}


def _heading(joints: np.ndarray) -> np.ndarray:
    """(T,) heading angle of the body (hips' normal in the floor plane)."""
    across = joints[:, 2, :2] - joints[:, 1, :2]
    return np.arctan2(across[:, 0], -across[:, 1])  # forward = z x across


def _draw(ax, pts: np.ndarray, offset: float) -> None:
    for j, p in enumerate(PARENTS):
        if p < 0:
            continue
        color = "tab:blue" if j in LEFT else "tab:red" if j in RIGHT else "k"
        ax.plot([pts[p, 0] + offset, pts[j, 0] + offset], [pts[p, 1], pts[j, 1]], color=color, lw=1.5)


def render(joints: np.ndarray, texts: str, out: str, start: int, count: int, step: int) -> None:
    """Side and front film strips of frames ``start, start+step, ...`` and the foot-height traces."""
    frames = list(range(start, min(start + count * step, len(joints)), step))
    yaw = _heading(joints)[frames[0]]
    c, s = np.cos(yaw), np.sin(yaw)
    fwd = np.array([c, s])  # heading direction in the floor plane
    side = np.array([s, -c])  # body right
    fig, axes = plt.subplots(3, 1, figsize=(2.0 * len(frames), 10), gridspec_kw={"height_ratios": [2, 2, 1]})
    origin = joints[frames[0], 0, :2]
    for k, f in enumerate(frames):
        rel = joints[f, :, :2] - origin
        sideview = np.stack((rel @ fwd, joints[f, :, 2]), axis=-1)
        frontview = np.stack((rel @ side, joints[f, :, 2]), axis=-1)
        _draw(axes[0], sideview, 1.2 * k - (rel[0] @ fwd))
        _draw(axes[1], frontview, 1.0 * k - (rel[0] @ side))
        axes[0].text(1.2 * k, -0.1, str(f), ha="center", fontsize=7)
    for ax in axes[:2]:
        ax.axhline(0.0, color="gray", lw=0.8)
        ax.set_aspect("equal")
        ax.set_ylim(-0.15, 2.1)
    axes[0].set_title(f"{texts} (side view, forward = right)")
    axes[1].set_title("front view (body right = right)")
    t = np.arange(len(joints))
    axes[2].plot(t, joints[:, 10, 2], label="left foot z", color="tab:blue")
    axes[2].plot(t, joints[:, 11, 2], label="right foot z", color="tab:red")
    axes[2].plot(t[1:], 100 * foot_skate(joints) * 30 / 100, label="skate (m/s)", color="k", lw=0.8)
    axes[2].axhline(0.03, color="gray", ls=":")
    for f in frames:
        axes[2].axvline(f, color="gray", lw=0.3)
    axes[2].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out, dpi=70)
    print(f"wrote {out}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--skill", default="walk", help="skill to generate (ignored with --file)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--index", type=int, default=0, help="sequence index within the generated set")
    parser.add_argument("--file", help="render an existing .npz sequence instead")
    parser.add_argument("--start", type=int, default=30, help="first frame")
    parser.add_argument("--count", type=int, default=12, help="number of poses in the strip")
    parser.add_argument("--step", type=int, default=3, help="frames between poses")
    parser.add_argument("--out", default="preview.png")
    args = parser.parse_args()
    if args.file:
        seq = read_sequence(args.file)
    else:
        skills = tuple(args.skill.split(","))
        cfg = LocomotionConfig(num_sequences=args.index + 1, seconds_per_sequence=8.0, seed=args.seed, skills=skills)
        seq = generate_sequences(cfg)[args.index]
    texts = "; ".join(f"{t} [{a}-{b})" for a, b, t in zip(seq["seg_start"], seq["seg_end"], seq["seg_text"]))
    render(seq["joints"].astype(np.float64), texts, args.out, args.start, args.count, args.step)


if __name__ == "__main__":
    main()
