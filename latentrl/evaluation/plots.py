"""``paths.png``: top-down pelvis tracks of every episode over the waypoints, one panel per path.

World frame seen from above: x right, y up on the page (the body starts at the origin facing +y),
metres, equal aspect. Successful episodes are drawn in green, failures in red; waypoints are
numbered in order of visit (a point visited twice reads "0,2"), the start is a black triangle.
Scene objects are grey footprints; where each episode had its own random obstacles, every episode's are drawn
faintly, so places that were often blocked read darker.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

from latentrl.evaluation.results import PathResult, SuiteResult

SUCCESS_COLOR, FAILURE_COLOR = "tab:green", "tab:red"
MAX_LABELS = 60
"""Paths with more distinct waypoints get numbers only at the first and last (10,000 labels take minutes)."""


def draw_scenes(ax, scenes: Sequence[str | None]) -> None:
    """The footprints of the episodes' scenes (JSON texts; each distinct scene once, None: no scene)."""
    from matplotlib.patches import Circle, Polygon

    from latentrl.scenes.spec import scene_from_json

    distinct = list(dict.fromkeys(s for s in scenes if s))
    alpha = max(0.06, 0.6 / max(1, len(distinct)))
    for text in distinct:
        boxes, cylinders = scene_from_json(text).primitives()
        for x, y, _, hx, hy, _, yaw in boxes:
            c, s = math.cos(yaw), math.sin(yaw)
            corners = [(x + c * u - s * v, y + s * u + c * v) for u, v in ((-hx, -hy), (hx, -hy), (hx, hy), (-hx, hy))]
            ax.add_patch(Polygon(corners, closed=True, color="dimgray", alpha=alpha, lw=0, zorder=1))
        for x, y, _, r, _ in cylinders:
            ax.add_patch(Circle((x, y), r, color="dimgray", alpha=alpha, lw=0, zorder=1))


def _draw_path(ax, result: PathResult) -> None:
    """One panel: the scene, every episode's pelvis track, then the waypoints on top."""
    draw_scenes(ax, [ep.scene for ep in result.episodes])
    for ep in result.episodes:
        color = SUCCESS_COLOR if ep.success else FAILURE_COLOR
        ax.plot(ep.pelvis_xy[:, 0], ep.pelvis_xy[:, 1], color=color, lw=0.8, alpha=0.45)
    wps = [(0.0, 0.0)] + [w[:2] for w in result.path.waypoints]
    ax.plot([w[0] for w in wps], [w[1] for w in wps], ls="--", color="gray", lw=0.8)
    ax.plot(0.0, 0.0, marker="^", color="black", ms=7)
    labels: dict[tuple[float, float], list[str]] = {}  # waypoints visited twice share one label: "0,2,4"
    for k, (x, y, _) in enumerate(result.path.waypoints):
        labels.setdefault((round(x, 2), round(y, 2)), []).append(str(k))
    points = list(labels)
    ax.plot([x for x, _ in points], [y for _, y in points], "o", ls="none", ms=6, mfc="white", mec="black", zorder=3)
    shown = points if len(points) <= MAX_LABELS else [points[0], points[-1]]
    for x, y in shown:
        ax.annotate(",".join(labels[(x, y)]), (x, y), xytext=(4, 4), textcoords="offset points", fontsize=7, zorder=4)
    n = len(result.episodes)
    wins = sum(ep.success for ep in result.episodes)
    from latentrl.evaluation.results import prompts_label

    ax.set_title(f"{result.suite} / path {result.index} ({prompts_label(result.path.texts)}): {wins}/{n} reached",
                 fontsize=8)
    ax.set_aspect("equal", adjustable="datalim")
    ax.tick_params(labelsize=6)
    ax.grid(alpha=0.3)


def paths_figure(suites: Sequence[SuiteResult], columns: int = 5):
    """A matplotlib figure with one panel per path of every suite (rows of ``columns`` panels)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.lines import Line2D

    results = [p for s in suites for p in s.paths]
    cols = max(1, min(columns, len(results)))
    rows = max(1, math.ceil(len(results) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 3.2 * rows), squeeze=False)
    for ax, result in zip(axes.flat, results):
        _draw_path(ax, result)
    for ax in list(axes.flat)[len(results):]:
        ax.axis("off")
    handles = [Line2D([], [], color=c, label=t) for c, t in ((SUCCESS_COLOR, "reached"), (FAILURE_COLOR, "failed"))]
    fig.legend(handles=handles, loc="upper center", ncol=2, fontsize=8, frameon=False)
    fig.supxlabel("x (m)", fontsize=8)
    fig.supylabel("y (m)", fontsize=8)
    fig.tight_layout(rect=(0, 0, 1, 1 - 0.25 / (3.2 * rows)))
    return fig


def save_paths_png(path: str | Path, suites: Sequence[SuiteResult], dpi: int = 110) -> Path:
    """Write :func:`paths_figure` as a PNG (through a fresh temporary file, then renamed)."""
    import matplotlib.pyplot as plt

    from latentrl.safe_io import atomic_write_with

    fig = paths_figure(suites)
    try:
        return atomic_write_with(path, lambda tmp: fig.savefig(tmp, dpi=dpi, format="png"))
    finally:
        plt.close(fig)
