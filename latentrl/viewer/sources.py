"""What ``latentrl view PATH`` shows: a motion file, an evaluation folder, a run, or a folder of motions.

:func:`open_source` turns PATH into a :class:`Source` (a title, a summary and a list of
:class:`Entry`); :meth:`Entry.load` reads one motion as a :class:`Clip`, lazily, so an evaluation
of hundreds of episodes opens at once. Nothing here needs Viser, so every check runs (and fails
with one line) before a server starts.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from latentrl.errors import DataError
from latentrl.motion.skeleton import NUM_JOINTS
from latentrl.viewer.markup import plain

REPORT_JSON = "report.json"
RUN_MARKERS = ("config.yaml", "final.pt", "checkpoints")
"""Files a training run folder holds (``latentrl train`` writes them)."""
PRIMITIVE_FRAMES = 8
SEED_FRAMES = 2


@dataclass
class Clip:
    """One motion, ready to draw.

    Attributes:
        joints: (T, 22, 3) world joints, metres, z up.
        fps: frames per second.
        texts: (T,) the prompt in force at each frame ('' for seed frames).
        goals: (T, 3) the goal in force at each frame, or None.
        waypoints: (W, 3) the path the episode follows, or None.
    """

    joints: np.ndarray
    fps: float
    texts: list[str]
    goals: np.ndarray | None = None
    waypoints: np.ndarray | None = None
    targets: np.ndarray | None = None
    """(K, 3) world positions of an optimized motion's point targets (``latentrl optimize``), or None."""
    target_frames: np.ndarray | None = None
    """(K,) the motion frame each target is for."""
    scene: str | None = None
    """The scene the motion moves in, ``latentrl.scene/1`` JSON text as the file carries it, or None."""
    waypoint_joints: np.ndarray | None = None
    """(W,) the SMPL joint of each waypoint when they are a joint-goal episode's targets (the file's
    ``waypoint_joints``), or None."""

    @property
    def frames(self) -> int:
        """Number of frames of the clip."""
        return len(self.joints)

    def keyframes(self) -> dict[int, np.ndarray]:
        """Frame -> (22, 3) for every frame whose targets name all 22 joints (drawn as ghost skeletons)."""
        if self.targets is None or self.target_frames is None:
            return {}
        out = {}
        for f in np.unique(self.target_frames):
            rows = self.targets[self.target_frames == f]
            if len(rows) == NUM_JOINTS:
                out[int(f)] = rows
        return out


@dataclass
class Entry:
    """One motion of a source: a label for the picker, its file and the metrics to show beside it."""

    label: str
    path: Path
    metrics: dict[str, Any] = field(default_factory=dict)
    waypoints: np.ndarray | None = None
    targets: list[dict] | None = None
    """An optimized motion's targets as ``report.json`` lists them (``motion_frame``, ``position``)."""

    def load(self) -> Clip:
        """The entry's clip, with its point targets and their frames when it has any."""
        clip = load_clip(self.path, self.waypoints)
        if self.targets:
            clip.targets = np.asarray([t["position"] for t in self.targets], dtype=np.float32).reshape(-1, 3)
            clip.target_frames = np.asarray([t["motion_frame"] for t in self.targets], dtype=np.int64)
        return clip


@dataclass
class Source:
    """Everything ``latentrl view`` offers for one PATH."""

    title: str
    kind: str  # "motion", "evaluation", "optimize", "run" or "folder"
    entries: list[Entry]
    summary: str = ""
    """Markdown shown above the picker; every string in it that comes from a file went through :func:`plain`."""


def per_frame_goals(goals: np.ndarray, frames: int, primitive: np.ndarray | None = None) -> np.ndarray:
    """(S, 3) per-step goals -> (T, 3) per frame: frame t shows the goal of the step that made it.

    Seed frames (primitive -1) show the first step's goal. Without a ``primitive`` array, frames are
    assigned by the layout 2 seed frames + 8 per primitive.
    """
    goals = np.asarray(goals, dtype=np.float32).reshape(-1, 3)
    if primitive is None or len(primitive) != frames:
        primitive = (np.arange(frames) - SEED_FRAMES) // PRIMITIVE_FRAMES
    step = np.clip(np.asarray(primitive, dtype=np.int64), 0, max(len(goals) - 1, 0))
    return goals[step]


def load_clip(path: str | Path, waypoints: np.ndarray | None = None) -> Clip:
    """Read a motion ``.npz`` of the shared format (``latentrl.render``) as a :class:`Clip`."""
    from latentrl.motion.clip import MotionClip

    motion = MotionClip.load(path)
    joints = motion.joints
    if len(joints) == 0 or not np.isfinite(joints).all():
        raise DataError(f"{path}: 'joints' is empty or holds non-finite values")
    frames = len(joints)
    goals = None
    if motion.goals is not None and np.asarray(motion.goals).size:
        goals = per_frame_goals(motion.goals, frames, motion.primitive)
    if waypoints is None and motion.waypoints is not None and np.asarray(motion.waypoints).size:
        waypoints = np.asarray(motion.waypoints, dtype=np.float32).reshape(-1, 3)
    marks = np.asarray(motion.meta.get("waypoint_joints", np.zeros(0)))
    marks = marks.astype(np.int64) if marks.dtype.kind in "iu" and marks.ndim == 1 and marks.size else None
    return Clip(joints, motion.fps, motion.texts, goals, waypoints, scene=motion.scene, waypoint_joints=marks)


def motion_metrics(clip: Clip) -> dict[str, float]:
    """DART's skate (cm/s) and floor (cm) metrics of a clip (what an evaluation report holds per episode)."""
    from latentrl.evaluation.metrics import foot_floor_distance_cm, foot_skate_cm_s

    return {
        "skate_cm_s": float(foot_skate_cm_s(clip.joints, fps=clip.fps)),
        "floor_cm": float(foot_floor_distance_cm(clip.joints)),
    }


def _fmt(value: Any, digits: int = 2) -> str:
    if isinstance(value, dict):  # report aggregates: {"mean", "ci95"}
        mean, ci = value.get("mean"), value.get("ci95")
        if mean is None or not math.isfinite(mean):
            return "–"
        return f"{mean:.{digits}f} ± {ci:.{digits}f}" if ci is not None else f"{mean:.{digits}f}"
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        return f"{value:.{digits}f}" if math.isfinite(value) else "–"
    return str(value)


METRIC_LABELS = (
    ("success", "success"),
    ("end", "end"),
    ("goal_error_cm", "goal error (cm)"),
    ("reach_time_s", "reach time (s)"),
    ("skate_cm_s", "skate (cm/s)"),
    ("floor_cm", "floor (cm)"),
    ("steps", "steps"),
    ("final_dist_m", "final distance (m)"),
    ("success_rate", "success"),
)


def metrics_table(metrics: dict[str, Any]) -> str:
    """A two-column markdown table of the metrics an entry carries (known keys, in a fixed order)."""
    rows = [f"| {label} | {plain(_fmt(metrics[key]))} |" for key, label in METRIC_LABELS if key in metrics]
    return "\n".join(["| metric | value |", "|---|---|", *rows]) if rows else ""


# --------------------------------------------------------------------------- opening PATH
def open_source(path: str | Path) -> Source:
    """PATH -> :class:`Source`; one-line :class:`~latentrl.errors.DataError` for anything else."""
    path = Path(path)
    if not path.exists():
        raise DataError(f"{path}: no such file or folder (give a motion .npz, an evaluation folder or a run folder)")
    if path.is_file():
        if path.name == REPORT_JSON:
            return _report_source(path.parent)
        if path.suffix == ".npz":
            return motion_source(path)
        if path.suffix == ".pt":
            raise DataError(f"{path}: a checkpoint, not a motion; to steer a policy live use: latentrl play {path}")
        raise DataError(f"{path}: expected a motion .npz, an evaluation folder (report.json) or a training run folder")
    if (path / REPORT_JSON).is_file():
        return _report_source(path)
    if any((path / marker).exists() for marker in RUN_MARKERS):
        return run_source(path)
    if sorted(path.glob("*.npz")):
        return folder_source(path)
    raise DataError(f"{path}: holds no report.json, no run files ({', '.join(RUN_MARKERS)}) and no .npz motions")


def motion_source(path: Path) -> Source:
    """One motion file as a source, with its stored outcome and its motion metrics."""
    clip = load_clip(path)  # checks the file now, not when the browser connects
    scalars = _npz_scalars(path)
    metrics = {k: scalars[k] for k in ("success", "end", "reach_time_s") if k in scalars}
    metrics.update(motion_metrics(clip))
    entry = Entry(path.name, path, metrics, clip.waypoints)
    seconds = clip.frames / clip.fps
    texts = ", ".join(dict.fromkeys(t for t in clip.texts if t)) or "–"
    return Source(f"{path.name}", "motion", [entry], f"{clip.frames} frames ({seconds:.1f} s), texts: {plain(texts)}")


def _npz_scalars(path: Path) -> dict[str, Any]:
    """The 0-d fields of a motion file (an evaluation writes success, end, reach_time_s there)."""
    from latentrl.motion.clip import read_motion_arrays

    return {key: value.item() for key, value in read_motion_arrays(path).items() if value.ndim == 0}


def folder_source(path: Path) -> Source:
    """Every motion file of a folder as a source, one entry each, in name order."""
    files = sorted(path.glob("*.npz"))
    entries = [Entry(f.name, f) for f in files]
    return Source(str(path), "folder", entries, f"{len(files)} motion files")


def evaluation_source(folder: Path, title: str | None = None) -> Source:
    """Every episode of an evaluation that has a motion file, with its metrics from report.json."""
    from latentrl.evaluation.report import load_report

    report = load_report(folder)
    entries = []
    for suite, body in report["suites"].items():
        for path_entry in body.get("paths", []):
            waypoints = np.asarray(path_entry.get("waypoints") or np.zeros((0, 3)), dtype=np.float32).reshape(-1, 3)
            for ep in path_entry.get("episodes", []):
                if not ep.get("motion"):
                    continue
                mark = "reached" if ep.get("success") else str(ep.get("end", "failed"))
                label = f"{suite} path {path_entry.get('index')} ep {ep.get('episode', 0):03d} ({mark})"
                metrics = {k: ep.get(k) for k in ("success", "end", "reach_time_s", "skate_cm_s", "floor_cm",
                                                   "steps", "final_dist_m")}
                entries.append(Entry(label, folder / ep["motion"], metrics, waypoints))
    if not entries:
        raise DataError(f"{folder}: the evaluation has no motion files (written with --no-motions?); "
                        "run latentrl eval again without --no-motions")
    missing = [e.path for e in entries if not e.path.is_file()]
    if missing:
        raise DataError(f"{missing[0]}: motion file named in {folder / REPORT_JSON} is missing "
                        f"({len(missing)} of {len(entries)} missing)")
    overall = report["overall"].get("metrics", {})
    policy = (report.get("policy") or {}).get("path", "?")
    shown = {k: plain(_fmt(overall.get(k))) for k in ("success_rate", "reach_time_s", "skate_cm_s", "floor_cm")}
    summary = (f"policy {plain(policy)}, {len(entries)} episodes; overall success {shown['success_rate']}, "
               f"reach time {shown['reach_time_s']} s, skate {shown['skate_cm_s']} cm/s, "
               f"floor {shown['floor_cm']} cm")
    return Source(title or str(folder), "evaluation", entries, summary)


OPTIMIZE_FORMAT = "latentrl.optimize-report/1"
MAX_REPORT_BYTES = 64 * 1024 * 1024


def _report_source(folder: Path) -> Source:
    """The folder's report.json, read once: an optimize output or an evaluation."""
    from latentrl.safe_io import read_json_file

    report = read_json_file(folder / REPORT_JSON, "report", MAX_REPORT_BYTES, DataError)
    if isinstance(report, dict) and report.get("format") == OPTIMIZE_FORMAT:
        return optimize_source(folder, report)
    return evaluation_source(folder)


def _target_rows(targets: Any, where: str) -> list[dict]:
    """The checked targets of one problem: ``motion_frame`` an int >= 0, ``position`` three finite numbers."""
    if not isinstance(targets, list):
        raise DataError(f"{where}: 'targets' must be a list")
    rows = []
    for t in targets:
        pos = t.get("position") if isinstance(t, dict) else None
        frame = t.get("motion_frame") if isinstance(t, dict) else None
        if (not isinstance(frame, int) or isinstance(frame, bool) or frame < 0 or not isinstance(pos, list)
                or len(pos) != 3 or not all(isinstance(v, (int, float)) and math.isfinite(v) for v in pos)):
            raise DataError(f"{where}: a target needs 'motion_frame' (int >= 0) and 'position' [x, y, z], got "
                            f"{str(t)[:60]}")
        rows.append({"motion_frame": frame, "position": [float(v) for v in pos]})
    return rows


def optimize_source(folder: Path, report: dict) -> Source:
    """Every problem of a ``latentrl optimize`` output (its parsed ``report``), with its targets."""
    from latentrl.optim.report import check_report

    path = folder / REPORT_JSON
    check_report(report, path)
    problems = report.get("problems")
    if not isinstance(problems, list) or not problems:
        raise DataError(f"{path}: an optimize report needs a non-empty 'problems' list")
    entries = []
    for i, e in enumerate(problems):
        if not isinstance(e, dict) or not isinstance(e.get("motion"), str) or not isinstance(e.get("name"), str):
            raise DataError(f"{path}: problems[{i}] needs 'name' and 'motion' strings")
        motion = (folder / e["motion"]).resolve()
        if folder.resolve() not in motion.parents:
            raise DataError(f"{path}: problems[{i}].motion {e['motion']!r} points outside {folder}")
        if not motion.is_file():
            raise DataError(f"{motion}: motion file named in {path} is missing")
        metrics = e.get("metrics") if isinstance(e.get("metrics"), dict) else {}
        shown = {k: metrics.get(k) for k in ("goal_error_cm", "skate_cm_s", "floor_cm", "steps") if k in metrics}
        label = f"{e['name']} ({_fmt(metrics.get('goal_error_cm'))} cm)"
        entries.append(Entry(label, motion, shown, None, _target_rows(e.get("targets", []), f"{path} problems[{i}]")))
    overall = report.get("overall") if isinstance(report.get("overall"), dict) else {}
    summary = (f"noise optimization of {plain(report.get('suite', '?'))}, {len(entries)} problems; mean goal error "
               f"{plain(_fmt(overall.get('goal_error_cm')))} cm, {plain(_fmt(overall.get('share_within_1cm')))} "
               "within 1 cm; "
               "targets: markers (bright on their frame), keyframes: ghost skeletons")
    return Source(str(folder), "optimize", entries, summary)


def latest_evaluation(run: Path) -> Path | None:
    """The newest evaluation folder inside a run (``eval/``, ``eval-final/``, ...), by report time."""
    reports = [p for pattern in (f"*/{REPORT_JSON}", f"*/*/{REPORT_JSON}") for p in run.glob(pattern)]
    if not reports:
        return None
    return max(reports, key=lambda p: (p.stat().st_mtime, str(p))).parent


def run_source(run: Path) -> Source:
    """A training run as a source: the entries of its latest evaluation folder."""
    folder = latest_evaluation(run)
    if folder is None:
        final = run / "final.pt"
        policy = final if final.is_file() else run / "checkpoints" / "iter_N.pt"
        raise DataError(f"{run}: the run has no evaluation yet (no */report.json); "
                        f"evaluate it first: latentrl eval {policy} --out {run / 'eval'}")
    source = evaluation_source(folder, title=f"{run} (latest evaluation: {folder.relative_to(run)})")
    source.kind = "run"
    return source
