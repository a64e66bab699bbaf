"""Does the motion do what its text says? A per-segment skill check for paths that switch texts.

A path policy that handles every skill must not just reach the waypoints: while waypoint k is the
goal, its text conditions the motion, and the motion should look like that text. Success and reach
time cannot tell a policy that runs where it should run from one that walks everywhere, so each
*segment* (the stretch of an episode while waypoint k is the goal) is judged on its own, with the
metric kernels of :mod:`~latentrl.evaluation.metrics`:

- "run" family (run, jog, ...): mean horizontal pelvis speed >= :data:`RUN_MIN_SPEED_M_S`;
- "walk" family: speed within :data:`WALK_SPEED_M_S`;
- "hop on left leg": the left foot alone on the floor in >= :data:`HOP_STANCE_MIN_SHARE` of the
  frames and the right foot alone in <= :data:`HOP_OTHER_MAX_SHARE`; mirrored for the right leg;
- any other text is not judged (reported with ``skill`` null).

The first :data:`TRANSITION_S` of a segment are left out (the motion is still changing skill), and
segments shorter than :data:`MIN_SEGMENT_S` are not measured at all. The thresholds are rough
(the default model walks at about 0.85-1.2 m/s and runs at 3.2-4.2 m/s): they separate the skills,
they do not grade them.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from latentrl.evaluation import metrics as M
from latentrl.motion.clip import MotionClip
from latentrl.motion.representation import FUTURE_LENGTH, HISTORY_LENGTH

TRANSITION_S = 0.5
"""Seconds at the start of a segment that are not judged: the motion is still switching skill."""
MIN_SEGMENT_S = 1.0
"""Segments shorter than this (whole segment, transition included) are not measured."""
RUN_MIN_SPEED_M_S = 2.0
"""A "run" segment matches at this mean horizontal pelvis speed or faster."""
WALK_SPEED_M_S = (0.5, 2.0)
"""A "walk" segment matches within [min, max) m/s: slower is standing, faster is running."""
HOP_STANCE_MIN_SHARE = 0.4
"""A "hop on left leg" segment needs the left foot alone on the floor in at least this share of frames..."""
HOP_OTHER_MAX_SHARE = 0.1
"""...and the right foot alone in at most this share (mirrored for the right leg)."""
CONTACT_HEIGHT_M = 0.05
"""A foot joint is on the floor within this height (:func:`~latentrl.evaluation.metrics.foot_contact_shares`)."""

SKILLS = ("run", "walk", "hop_left", "hop_right")
"""The skill families that are judged."""
_RUN_WORDS = {"run", "runs", "running", "jog", "jogs", "jogging", "sprint", "sprints", "sprinting"}
_WALK_WORDS = {"walk", "walks", "walking"}


def skill_of(text: str) -> str | None:
    """The judged family of a prompt (:data:`SKILLS`), or None when the rule has nothing to say about it.

    Hops are recognised first ("hop on left leg" -> ``hop_left``), then running words, then walking
    words; a hop that names no side, or both, is not judged.
    """
    words = set(re.findall(r"[a-z]+", str(text).lower()))
    if words & {"hop", "hops", "hopping"}:
        left, right = "left" in words, "right" in words
        return "hop_left" if left and not right else "hop_right" if right and not left else None
    if words & _RUN_WORDS:
        return "run"
    if words & _WALK_WORDS:
        return "walk"
    return None


def matches(skill: str | None, speed_m_s: float, left_only: float, right_only: float) -> bool | None:
    """Whether measured values fit ``skill`` by the rule of the module docstring; None if it is not judged."""
    if skill == "run":
        return speed_m_s >= RUN_MIN_SPEED_M_S
    if skill == "walk":
        return WALK_SPEED_M_S[0] <= speed_m_s < WALK_SPEED_M_S[1]
    if skill in ("hop_left", "hop_right"):
        stance, other = (left_only, right_only) if skill == "hop_left" else (right_only, left_only)
        return stance >= HOP_STANCE_MIN_SHARE and other <= HOP_OTHER_MAX_SHARE
    return None


@dataclass(frozen=True)
class Segment:
    """Frames ``[start, stop)`` of a clip during which waypoint ``waypoint`` was the goal, under ``text``."""

    waypoint: int
    text: str
    start: int
    stop: int


def segments(clip: MotionClip) -> list[Segment]:
    """Split an episode recorded in the primitive layout (2 seed frames + 8 per step) at each change of goal.

    The recorder stores the goal in force during each step (``clip.goals``); the env advances to the
    next waypoint after the step that reached it, so a new goal marks a new segment. Waypoints are
    counted from 0 in the order the goals appear. The seed frames belong to no segment.
    """
    goals = clip.goals
    if goals is None:
        raise ValueError("the clip has no per-step goals (record it with record_history=True)")
    steps = len(goals)
    if len(clip.joints) != HISTORY_LENGTH + FUTURE_LENGTH * steps:
        raise ValueError(f"{len(clip.joints)} frames do not fit {steps} steps of {FUTURE_LENGTH} frames after "
                         f"{HISTORY_LENGTH} seed frames")
    out: list[Segment] = []
    first = 0
    for s in range(1, steps + 1):
        if s == steps or not np.array_equal(goals[s], goals[s - 1]):
            start = HISTORY_LENGTH + FUTURE_LENGTH * first
            out.append(Segment(len(out), clip.texts[start], start, HISTORY_LENGTH + FUTURE_LENGTH * s))
            first = s
    return out


def judge_segment(clip: MotionClip, seg: Segment) -> dict[str, Any]:
    """One segment's entry: where it is, its skill, what was measured and whether it matches.

    Keys: ``waypoint``, ``text``, ``skill`` (None = not judged), ``start_s``, ``duration_s``,
    ``measured`` (long enough), ``match`` (None unless measured and judged), ``speed_m_s``,
    ``left_only``, ``right_only`` (None unless measured).
    """
    fps = clip.fps
    skill = skill_of(seg.text)
    entry: dict[str, Any] = {"waypoint": seg.waypoint, "text": seg.text, "skill": skill,
                             "start_s": seg.start / fps, "duration_s": (seg.stop - seg.start) / fps,
                             "measured": False, "match": None, "speed_m_s": None, "left_only": None,
                             "right_only": None}
    if seg.stop - seg.start < round(MIN_SEGMENT_S * fps):
        return entry
    window = clip.joints[seg.start + round(TRANSITION_S * fps): seg.stop]
    speed = float(M.pelvis_speed_m_s(window, fps))
    shares = M.foot_contact_shares(window, clip.floor, CONTACT_HEIGHT_M)
    left, right = float(shares["left_only"]), float(shares["right_only"])
    entry.update(measured=True, match=matches(skill, speed, left, right), speed_m_s=speed, left_only=left,
                 right_only=right)
    return entry


def judge_clip(clip: MotionClip) -> list[dict[str, Any]]:
    """:func:`judge_segment` of every segment of an episode, in order."""
    return [judge_segment(clip, seg) for seg in segments(clip)]


def match_share(entries: Iterable[dict[str, Any]]) -> float:
    """Share of judged segments (measured, known skill) that match; NaN when none was judged."""
    judged = [e["match"] for e in entries if e["match"] is not None]
    return sum(judged) / len(judged) if judged else math.nan


def _mean(values: Sequence[float]) -> float:
    return float(np.mean(values)) if values else math.nan


def per_text(entries: Iterable[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """The segments grouped by text, in order of first use.

    Per text: ``skill``, ``segments`` (measured ones), ``judged``, ``matched``, ``match_share`` and the
    mean ``speed_m_s``, ``left_only``, ``right_only`` over its measured segments.
    """
    groups: dict[str, list[dict[str, Any]]] = {}
    for e in entries:
        if e["measured"]:
            groups.setdefault(e["text"], []).append(e)
    out = {}
    for text, group in groups.items():
        judged = [e for e in group if e["match"] is not None]
        out[text] = {"skill": skill_of(text), "segments": len(group), "judged": len(judged),
                     "matched": sum(bool(e["match"]) for e in judged), "match_share": match_share(group),
                     **{k: _mean([e[k] for e in group]) for k in ("speed_m_s", "left_only", "right_only")}}
    return out
