"""Evaluation reports: aggregation, ``report.json`` (for machines), ``report.md`` (for people), ``compare``.

Aggregation (``reference/dart.md`` section 5):

- per path: mean and 95% CI (``1.96 * std / sqrt(n)``, population std as DART) over its episodes;
- per suite (path file) and ``overall``: DART's aggregation, i.e. each episode index is averaged
  over the paths first (DART's env index 0-31 over the 5 paths), then mean and CI over the indices;
- ``reach_time_success_s`` (successful episodes only) cannot be averaged per index (some are
  missing), so it is pooled: mean and CI over every successful episode of the suite.

``report.md`` is generated from the ``report.json`` dict alone, so it can be rebuilt from the JSON.
"""

from __future__ import annotations

import json
import math
from collections.abc import Sequence
from datetime import datetime, timezone
from pathlib import Path
from typing import Any

import numpy as np

from latentrl.errors import DataError
from latentrl.evaluation import metrics as M
from latentrl.evaluation import skills as K
from latentrl.evaluation.config import EvalSettings
from latentrl.evaluation.results import PathResult, SuiteResult
from latentrl.motion.rollout import LOCK_MIN_WEIGHT
from latentrl.motion.skeleton import FPS

FORMAT = "latentrl.eval/1"
REPORT_JSON, REPORT_MD, PATHS_PNG = "report.json", "report.md", "paths.png"

METRICS: dict[str, tuple[str, str]] = {
    "success_rate": ("success", ""),
    "reach_time_s": ("reach time", "s"),
    "reach_time_success_s": ("reach time, successes", "s"),
    "skate_cm_s": ("skate", "cm/s"),
    "skate_xy_cm_s": ("skate, xy part", "cm/s"),
    "floor_cm": ("floor", "cm"),
    "jerk": ("jerk", "m/s³"),
    "penetration_mm": ("penetration", "mm"),
    "floating_mm": ("floating", "mm"),
    "skating_mm": ("skating", "mm"),
}
"""Every aggregated metric: key -> (column title, unit). Each is stored as ``{"mean", "ci95"}``."""

TRANSITION_METRICS: dict[str, tuple[str, str]] = {
    "pj_seam": ("PJ at primitive boundaries", "m/frame³"),
}
"""DART's transition metric (:func:`latentrl.evaluation.metrics.seam_peak_jerk`), aggregated when the episodes carry
it (every evaluation since it exists; reports and episodes made before lack it)."""

SCENE_METRICS: dict[str, tuple[str, str]] = {
    "collision": ("collision rate", ""),
    "scene_penetration_cm": ("scene penetration", "cm"),
    "scene_penetration_max_cm": ("max scene penetration", "cm"),
}
"""Aggregated only when the episodes had a scene (:func:`latentrl.scenes.contact.scene_metrics`): the share of
episodes with a joint deeper than its skin radius in an object, the deepest joint per frame averaged over the
episode, and the episode's deepest point."""


def _keys(values: dict) -> list[str]:
    """:data:`METRICS`, then the transition and scene metrics when the episodes carry them."""
    return [*METRICS, *(k for k in (*TRANSITION_METRICS, *SCENE_METRICS) if k in values)]

COMPARE_METRICS = ("success_rate", "reach_time_s", "reach_time_success_s", "skate_cm_s", "floor_cm", "jerk")

DART_TABLE4: dict[str, dict[str, float]] = {
    "dart_walk_long": {"success_rate": 1.0, "reach_time_success_s": 17.08, "skate_cm_s": 2.67, "floor_cm": 2.24},
    "dart_run_long": {"success_rate": 1.0, "reach_time_success_s": 10.55, "skate_cm_s": 3.23, "floor_cm": 3.86},
    "dart_hop_long": {"success_rate": 1.0, "reach_time_success_s": 20.50, "skate_cm_s": 2.22, "floor_cm": 4.11},
}
"""DART paper, Table 4 (released BABEL model). Its script saved finished runs only, so its time is a mean over
successes (our ``reach_time_success_s``) and its success rate is 1.0 by construction (docs/evaluation.md)."""


# --------------------------------------------------------------------------- aggregation
def _values(path: PathResult) -> dict[str, list[float]]:
    """Metric -> one value per episode (success as 0/1; reach time censored at the budget)."""
    out: dict[str, list[float]] = {"success_rate": [], "reach_time_s": []}
    for ep in path.episodes:
        out["success_rate"].append(float(ep.success))
        out["reach_time_s"].append(ep.reach_time_s)
        for name, value in ep.metrics.items():
            out.setdefault(name, []).append(value)
    return out


def _success_times(paths: Sequence[PathResult]) -> list[float]:
    return [ep.reach_time_s for p in paths for ep in p.episodes if ep.success]


def path_metrics(path: PathResult) -> dict[str, dict[str, float]]:
    """Mean and CI over the path's episodes, for every :data:`METRICS` key."""
    out = {name: M.mean_ci95(v) for name, v in _values(path).items()}
    out["reach_time_success_s"] = M.mean_ci95(_success_times([path]))
    return {k: out[k] for k in _keys(out)}


def pooled_metrics(paths: Sequence[PathResult]) -> dict[str, dict[str, float]]:
    """DART's aggregation over several paths (episode index averaged over paths first); see the module docstring."""
    values = [_values(p) for p in paths]
    out = {name: M.dart_mean_ci95([v[name] for v in values]) for name in values[0]}
    out["reach_time_success_s"] = M.mean_ci95(_success_times(paths))
    return {k: out[k] for k in _keys(out)}


def waypoint_times(path: PathResult) -> list[dict[str, float]]:
    """Per waypoint: mean/CI of the reach time over the episodes that reached it, and the share that did."""
    out = []
    for k in range(len(path.path.waypoints)):
        times = [ep.waypoint_times_s[k] for ep in path.episodes if ep.waypoint_times_s[k] is not None]
        out.append({**M.mean_ci95(times), "reached_rate": len(times) / len(path.episodes)})
    return out


def skill_summary(paths: Sequence[PathResult]) -> dict[str, Any]:
    """The skill check of several paths, pooled over every segment of every episode.

    ``segment_skill_match``: share of judged segments whose motion matched their text (NaN when none
    was judged); ``skills``: :func:`~latentrl.evaluation.skills.per_text`.
    """
    entries = [e for p in paths for ep in p.episodes for e in ep.segments]
    return {"segment_skill_match": K.match_share(entries), "skills": K.per_text(entries)}


# --------------------------------------------------------------------------- report.json
def _path_length(path) -> float:
    pts = [(0.0, 0.0)] + [w[:2] for w in path.waypoints]
    return float(sum(math.dist(a, b) for a, b in zip(pts[:-1], pts[1:])))


def _episode_entry(ep) -> dict[str, Any]:
    return {
        "episode": ep.episode,
        "success": ep.success,
        "end": ep.end,
        "steps": ep.steps,
        "reach_time_s": ep.reach_time_s,
        "final_dist_m": ep.final_dist_m,
        "waypoint_times_s": ep.waypoint_times_s,
        **ep.metrics,
        "motion": ep.motion_file,
        "segments": ep.segments,
    }


def _path_entry(p: PathResult) -> dict[str, Any]:
    return {
        "index": p.index,
        "waypoints": [list(w) for w in p.path.waypoints],
        "texts": list(p.path.texts),
        "length_m": _path_length(p.path),
        "wall_s": p.wall_s,
        "metrics": path_metrics(p),
        "waypoint_reach_time_s": waypoint_times(p),
        "episodes": [_episode_entry(ep) for ep in p.episodes],
        **skill_summary([p]),
    }


def _sha256(file: str) -> str | None:
    from latentrl.motion.checkpoint import file_sha256

    return file_sha256(file) if Path(file).is_file() else None


def build_report(
    suites: Sequence[SuiteResult],
    settings: EvalSettings,
    *,
    policy: dict[str, Any],
    motion: dict[str, Any],
    speed: dict[str, Any] | None = None,
    hardware: dict[str, Any] | None = None,
    files: dict[str, Any] | None = None,
    avoid: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """The ``report.json`` dict (schema in docs/evaluation.md); NaN becomes ``null`` when written.

    ``avoid``: the scene filter's settings when ``eval --avoid`` ran (``latentrl.optim.avoid``).
    """
    from dataclasses import asdict

    from latentrl import __version__

    all_paths = [p for s in suites for p in s.paths]
    return {
        "format": FORMAT,
        "latentrl_version": __version__,
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "policy": policy,
        "motion": motion,
        "settings": {**{k: v for k, v in asdict(settings).items()
                        if k not in ("scene", "observe_scene", "height_grid", "height_grid_spacing", "route")
                        or settings.scene is not None}, "fps": FPS,
                     "budget_s": settings.budget_s, "files": [s.file for s in suites]},
        "hardware": hardware or {},
        "speed": speed or {},
        "suites": {
            s.name: {"file": s.file, "sha256": _sha256(s.file), "metrics": pooled_metrics(s.paths),
                     "paths": [_path_entry(p) for p in s.paths], **skill_summary(s.paths)}
            for s in suites
        },
        "overall": {"metrics": pooled_metrics(all_paths), "paths": len(all_paths),
                    "episodes": sum(len(p.episodes) for p in all_paths), **skill_summary(all_paths)},
        "files": files or {},
        **({"avoid": avoid} if avoid is not None else {}),
    }


def _finite(obj: Any) -> Any:
    """JSON has no NaN: replace non-finite floats by None, recursively."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_finite(v) for v in obj]
    if isinstance(obj, np.generic):
        return _finite(obj.item())
    return obj


def write_report(out_dir: str | Path, report: dict[str, Any]) -> tuple[Path, Path]:
    """Write ``report.json`` and ``report.md`` into ``out_dir`` (atomically); returns both paths."""
    from latentrl.safe_io import atomic_write_text

    out_dir = Path(out_dir)
    js = atomic_write_text(out_dir / REPORT_JSON, json.dumps(_finite(report), indent=1, allow_nan=False) + "\n")
    md = atomic_write_text(out_dir / REPORT_MD, report_markdown(report))
    return js, md


MAX_REPORT_BYTES = 64 << 20
"""Largest ``report.json`` read (65,536 episodes of 100 paths stay far below it)."""
EPISODE_NUMBERS = ("reach_time_s", "skate_cm_s", "floor_cm", "steps", "final_dist_m", "goal_error_cm")
"""Per-episode fields that must be numbers or null (what ``view`` and ``compare`` show)."""


def load_report(path: str | Path) -> dict[str, Any]:
    """Read a ``report.json`` (or a folder holding one); errors name the file and what is wrong."""
    path = Path(path)
    if path.is_dir():
        path = path / REPORT_JSON
    if not path.is_file():
        raise DataError(f"report not found: {path} (give a report.json or the eval output folder)")
    if path.stat().st_size > MAX_REPORT_BYTES:
        raise DataError(f"{path}: {path.stat().st_size:,} bytes is larger than the {MAX_REPORT_BYTES >> 20} MiB "
                        "a report may have")
    try:
        report = json.loads(path.read_text(encoding="utf-8"))
    except (ValueError, RecursionError) as exc:  # JSONDecodeError and UnicodeDecodeError are ValueErrors
        raise DataError(f"{path}: not a JSON report ({str(exc)[:120] or 'nested too deeply'})") from None
    if not isinstance(report, dict) or report.get("format") != FORMAT:
        found = report.get("format") if isinstance(report, dict) else type(report).__name__
        raise DataError(f"{path}: not a latentrl evaluation report (format {found!r}, expected {FORMAT!r})")
    for key in ("suites", "overall", "settings"):
        if key not in report:
            raise DataError(f"{path}: report lacks field '{key}'")
    _check_report(report, path)
    return report


def _check_report(report: dict, path: Path) -> None:
    """The types ``compare`` and ``report.md`` rely on; one line naming the field."""

    def need(ok: bool, field: str, expected: str, got: Any) -> None:
        if not ok:
            shown = type(got).__name__ if isinstance(got, (dict, list)) else repr(got)[:60]
            raise DataError(f"{path}: field '{field}' must be {expected}, got {shown}")

    def metrics(block: Any, field: str) -> None:
        need(isinstance(block, dict), field, "an object", block)
        found = block.get("metrics")
        need(found is None or isinstance(found, dict), f"{field}.metrics", "an object of metrics or null", found)
        for key, m in (found or {}).items():
            need(isinstance(m, dict), f"{field}.metrics.{key}", "an object {mean, ci95}", m)
            for part in ("mean", "ci95"):
                v = m.get(part)
                need(v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)),
                     f"{field}.metrics.{key}.{part}", "a number or null", v)

    def number(v: Any) -> bool:
        return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

    def episode(ep: Any, field: str) -> None:
        need(isinstance(ep, dict), field, "an object", ep)
        e = ep.get("episode", 0)
        need(isinstance(e, int) and not isinstance(e, bool) and 0 <= e <= 10**9, f"{field}.episode",
             "an integer >= 0", e)
        motion = ep.get("motion")
        need(motion is None or isinstance(motion, str), f"{field}.motion", "null or a file name", motion)
        if motion is not None and (Path(motion).is_absolute() or ".." in Path(motion).parts):
            raise DataError(f"{path}: field '{field}.motion' {motion[:80]!r} points outside the report's folder")
        need(ep.get("success") is None or isinstance(ep.get("success"), bool), f"{field}.success",
             "true, false or null", ep.get("success"))
        need(ep.get("end") is None or isinstance(ep.get("end"), str), f"{field}.end", "a string or null", ep.get("end"))
        for key in EPISODE_NUMBERS:  # NaN stays allowed (older reports wrote it for undefined values)
            v = ep.get(key)
            need(v is None or (isinstance(v, (int, float)) and not isinstance(v, bool)), f"{field}.{key}",
                 "a number or null", v)

    def path_entry(p: Any, field: str) -> None:
        metrics(p, field)
        index = p.get("index", 0)
        need(isinstance(index, int) and not isinstance(index, bool), f"{field}.index", "an integer", index)
        wps = p.get("waypoints", [])
        need(isinstance(wps, list) and all(isinstance(w, list) and len(w) == 3 and all(number(x) for x in w)
                                           for w in wps), f"{field}.waypoints", "a list of [x, y, z] finite numbers",
             wps)
        eps = p.get("episodes", [])
        need(isinstance(eps, list), f"{field}.episodes", "a list", eps)
        for j, ep in enumerate(eps):
            episode(ep, f"{field}.episodes.{j}")

    need(isinstance(report["settings"], dict), "settings", "an object", report["settings"])
    need(isinstance(report["suites"], dict), "suites", "an object of suites", report["suites"])
    policy = report.get("policy")
    need(policy is None or (isinstance(policy, dict) and isinstance(policy.get("path", ""), str)), "policy",
         "an object whose 'path' is a string", policy)
    metrics(report["overall"], "overall")
    for name, suite in report["suites"].items():
        metrics(suite, f"suites.{name}")
        paths = suite.get("paths", [])
        need(isinstance(paths, list), f"suites.{name}.paths", "a list", paths)
        for i, p in enumerate(paths):
            path_entry(p, f"suites.{name}.paths.{i}")


# --------------------------------------------------------------------------- report.md
def _fmt(m: dict[str, float] | None, digits: int = 2) -> str:
    """``mean ± ci`` of a ``{"mean", "ci95"}`` (None/NaN as an en dash)."""
    if not m or m.get("mean") is None or not math.isfinite(m["mean"]):
        return "–"
    ci = m.get("ci95")
    ci_text = f" ± {ci:.{digits}f}" if ci is not None and math.isfinite(ci) else ""
    return f"{m['mean']:.{digits}f}{ci_text}"


def _header(keys: Sequence[str], lead: Sequence[str]) -> list[str]:
    named = {**METRICS, **TRANSITION_METRICS, **SCENE_METRICS}
    titles = [f"{named[k][0]} ({named[k][1]})" if named[k][1] else named[k][0] for k in keys]
    cols = [*lead, *titles]
    return ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]


def _row(lead: Sequence[str], metrics: dict, keys: Sequence[str]) -> str:
    return "| " + " | ".join([*lead, *(_fmt(metrics.get(k)) for k in keys)]) + " |"


def _dart_row(name: str, keys: Sequence[str]) -> str | None:
    ref = DART_TABLE4.get(name)
    if ref is None:
        return None
    cells = [f"{ref[k]:.2f}" if k in ref else "" for k in keys]
    return "| " + " | ".join([f"DART paper, Table 4 ({name.split('_')[1]})", "", *cells]) + " |"


def results_table(report: dict[str, Any]) -> list[str]:
    """One row per path, one DART-aggregated row per suite (+ DART's published row), then ``overall``."""
    keys = _keys(report["overall"].get("metrics") or {})
    from latentrl.evaluation.results import prompts_label

    lines = _header(keys, ["suite", "path (prompts)"])
    for name, suite in report["suites"].items():
        for p in suite["paths"]:
            lines.append(_row([name, f"{p['index']} ({prompts_label(p.get('texts', []))})"], p.get("metrics") or {},
                              keys))
        lines.append(_row([f"**{name}**", "all"], suite.get("metrics") or {}, keys))
        dart = _dart_row(name, keys)
        if dart:
            lines.append(dart)
    lines.append(_row(["**overall**", "all"], report["overall"].get("metrics") or {}, keys))
    return lines


def _waypoint_table(report: dict[str, Any]) -> list[str]:
    width = max((len(p["waypoints"]) for s in report["suites"].values() for p in s["paths"]), default=0)
    lines = ["| suite | path | " + " | ".join(f"wp {k}" for k in range(width)) + " |", "|" + "---|" * (width + 2)]
    for name, suite in report["suites"].items():
        for p in suite["paths"]:
            cells = [f"{_fmt(w, 1)} ({w['reached_rate']:.0%})" for w in p["waypoint_reach_time_s"]]
            cells += [""] * (width - len(cells))
            lines.append(f"| {name} | {p['index']} | " + " | ".join(cells) + " |")
    return lines


def _share(value: Any) -> str:
    return f"{value:.0%}" if isinstance(value, (int, float)) and math.isfinite(value) else "–"


def _num(value: Any, digits: int = 2) -> str:
    return f"{value:.{digits}f}" if isinstance(value, (int, float)) and math.isfinite(value) else "–"


def _skills_total(lead: str, block: dict[str, Any]) -> str:
    skills = (block.get("skills") or {}).values()
    segments, judged = (sum(t.get(k) or 0 for t in skills) for k in ("segments", "judged"))
    return f"| {lead} | all | {segments} | {judged} | {_share(block.get('segment_skill_match'))} | | | |"


def skills_table(report: dict[str, Any]) -> list[str]:
    """Per suite and text: measured segments, judged, matched share, mean speed and single-foot shares."""
    lines = ["| suite | text | segments | judged | matched | speed (m/s) | left foot only | right foot only |",
             "|---|---|---|---|---|---|---|---|"]
    rows = 0
    for name, suite in report["suites"].items():
        skills = suite.get("skills") or {}
        for text, t in skills.items():
            matched = _share(t.get("match_share")) if t.get("judged") else "not judged"
            lines.append(f"| {name} | {text} | {t.get('segments')} | {t.get('judged')} | {matched} | "
                         f"{_num(t.get('speed_m_s'))} | {_share(t.get('left_only'))} | {_share(t.get('right_only'))} |")
            rows += 1
        if skills:
            lines.append(_skills_total(f"**{name}**", suite))
    if report["overall"].get("skills"):
        lines.append(_skills_total("**overall**", report["overall"]))
    return lines if rows else ["(no segment was long enough to measure, or the report predates the skill check)"]


def _speed_lines(report: dict[str, Any]) -> list[str]:
    if not report.get("speed"):
        return ["(not measured)"]
    lines = ["| batch | frames/s | ms per primitive (8 frames) |", "|---|---|---|"]
    for s in report["speed"].values():
        lines.append(f"| {s['batch']} | {s['frames_per_s']:.0f} | {s['ms_per_step']:.1f} |")
    hw = report.get("hardware") or {}
    lines.append("")
    lines.append(f"Hardware: {hw.get('gpu') or hw.get('cpu', '?')} ({hw.get('cpu_count', '?')} CPU cores, "
                 f"{hw.get('torch_threads', '?')} torch threads, torch {hw.get('torch', '?')}).")
    lines.append("")
    lines.append("A quick sample, not a benchmark: the median of a few steps after one warm-up step, taken while "
                 "this evaluation ran, so other load on the machine shows up in it (runs on a shared 2-core CPU "
                 "have differed tenfold). For figures to compare, run `latentrl bench rollout` or "
                 "`latentrl bench env` on an idle machine.")
    return lines


DEFINITIONS = """\
- **success**: the pelvis came within {thr} m (xy) of the final waypoint, after every earlier waypoint, within
  the budget of {steps} primitives ({budget:.1f} s). Episodes that time out, diverge or wander off are
  **failures** (DART's script counted only finished runs).
- **reach time**: seconds to the final waypoint, `frames / 30` with the 2 seed frames counted (DART's
  definition). A failed episode counts with the **budget time** ({budget:.1f} s): a censored value, so
  failures raise it instead of vanishing. **reach time, successes** averages successful episodes only
  (DART's number, comparable with its Table 4 when success is 1.0).
- **skate**: DART's contact-weighted foot (joints 10, 11) speed, weight `2 - 2^clamp(h / 3 cm, 0, 1)`, cm/s.
- **floor**: DART's mean over frames of `|min(z_left_foot, z_right_foot)|`, cm.
- **jerk**: mean norm of the third finite difference of all 22 joints, m/s³.
- **penetration / floating**: CLoSD's, the lowest joint's mean depth below / height above the floor beyond 5 mm, mm.
- **skating**: CLoSD's, mean horizontal foot displacement between frames in contact (within 5 mm), mm.
- All motion metrics are computed on each whole episode, seed frames included, then aggregated.
- Per path: mean ± 95% CI (1.96 std / sqrt(n)) over episodes. Per suite and overall: DART's aggregation,
  each episode index averaged over the paths first, then mean ± CI over the indices; *reach time,
  successes* is pooled over all successful episodes instead.
- **skill per segment**: a segment is the stretch of an episode while one waypoint is the goal (its text
  conditions the motion). Segments shorter than {min_seg:g} s are not measured; the first {skip:g} s of each
  are left out (the skill is still changing). On the rest: *speed* is the mean horizontal pelvis speed,
  *left / right foot only* the share of frames with only that foot joint within {contact:g} cm of the floor. A
  segment matches its text if run/jog: speed >= {run:g} m/s; walk: {walk0:g} <= speed < {walk1:g} m/s;
  hop on left (right) leg: left (right) foot only >= {stance:.0%} and the other foot only <= {other:.0%};
  other texts are not judged. *matched* is the share of judged segments that match (`segment_skill_match`).
- The DART rows are the paper's numbers on its released BABEL model. Its script counted finished runs only,
  so its time sits under *reach time, successes* and its success of 1.0 ignores timeouts. Ours run on the
  motion model named above.
"""


def report_markdown(report: dict[str, Any]) -> str:
    """The human-readable report, from the report dict alone."""
    s, pol, mot = report["settings"], report.get("policy") or {}, report.get("motion") or {}
    mode = "deterministic (mean) actions" if s.get("deterministic") else "sampled actions (as DART)"
    lines = [
        f"# Evaluation of `{Path(str(pol.get('path', 'policy'))).name}`",
        "",
        f"- policy: `{pol.get('path')}` (sha256 `{str(pol.get('sha256'))[:12]}`, iteration {pol.get('iteration')})",
        f"- motion model: `{mot.get('source')}` (sha256 `{str(mot.get('sha256'))[:12]}`)",
        f"- {s['episodes']} episodes per path, budget {s['max_steps']} primitives ({s['budget_s']:.1f} s), {mode}, "
        f"seed {s['seed']}, device {s['device']}, latentrl {report.get('latentrl_version')}, {report.get('created')}",
        f"- motion stepped with guidance {s.get('guidance_scale')}, action bound {s.get('action_bound')}, foot lock "
        + (f"on (full from contact weight {s.get('foot_lock_min_weight', LOCK_MIN_WEIGHT)})"
           if s.get("foot_lock") else "off"),
        "",
        "## Results",
        "",
        *results_table(report),
        "",
        "## Per-waypoint reach times (s, successes at that waypoint; share of episodes that reached it)",
        "",
        *_waypoint_table(report),
        "",
        "## Skill per segment (does the motion match the text in force while heading to each waypoint?)",
        "",
        *skills_table(report),
        "",
        "## Generation speed (policy + motion model; a quick sample, see the note below the table)",
        "",
        *_speed_lines(report),
        "",
        "## Definitions",
        "",
        DEFINITIONS.format(thr=s["success_threshold"], steps=s["max_steps"], budget=s["budget_s"],
                           min_seg=K.MIN_SEGMENT_S, skip=K.TRANSITION_S, run=K.RUN_MIN_SPEED_M_S,
                           walk0=K.WALK_SPEED_M_S[0], walk1=K.WALK_SPEED_M_S[1], stance=K.HOP_STANCE_MIN_SHARE,
                           other=K.HOP_OTHER_MAX_SHARE, contact=K.CONTACT_HEIGHT_M * 100),
    ]
    return "\n".join(lines)


# --------------------------------------------------------------------------- compare
def _label(path: Path, report: dict[str, Any]) -> str:
    folder = path.parent.name if path.name == REPORT_JSON else path.stem
    return folder or Path(str((report.get("policy") or {}).get("path", "report"))).name


def compare_markdown(reports: Sequence[tuple[str, dict[str, Any]]], keys: Sequence[str] = COMPARE_METRICS) -> str:
    """Several reports side by side: for every suite (and ``overall``), one row per report."""
    names = list(dict.fromkeys(n for _, r in reports for n in r["suites"])) + ["overall"]
    lines = _header(list(keys), ["suite", "report"])
    for name in names:
        for label, report in reports:
            block = report["overall"] if name == "overall" else report["suites"].get(name)
            if block is not None:
                lines.append(_row([name, label], block.get("metrics") or {}, keys))
    notes = _setting_notes(reports)
    return "\n".join(lines + ([""] + notes if notes else [])) + "\n"


def _setting_notes(reports: Sequence[tuple[str, dict[str, Any]]]) -> list[str]:
    """Warn where reports differ in what makes numbers comparable."""
    notes = []
    for key in ("episodes", "max_steps", "deterministic", "success_threshold"):
        seen = {label: r["settings"].get(key) for label, r in reports}
        if len(set(map(str, seen.values()))) > 1:
            notes.append(f"Note: `{key}` differs: " + ", ".join(f"{k}={v}" for k, v in seen.items()))
    motions = {label: str((r.get("motion") or {}).get("sha256"))[:12] for label, r in reports}
    if len(set(motions.values())) > 1:
        notes.append("Note: the motion models differ: " + ", ".join(f"{k}={v}" for k, v in motions.items()))
    return notes


def compare_reports(paths: Sequence[str | Path]) -> str:
    """Load every report (files or eval folders) and return the side-by-side table."""
    loaded = []
    for p in paths:
        p = Path(p)
        report = load_report(p)
        loaded.append((_label(p if p.is_file() else p / REPORT_JSON, report), report))
    labels = [label for label, _ in loaded]
    loaded = [(f"{label} ({i})" if labels.count(label) > 1 else label, r) for i, (label, r) in enumerate(loaded)]
    return compare_markdown(loaded)
