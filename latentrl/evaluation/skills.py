"""Does the motion do what its text says? A per-segment skill check for paths that switch texts.

A path policy that handles every skill must not just reach the waypoints: while waypoint k is the
goal, its text conditions the motion, and the motion should look like that text. Success and reach
time cannot tell a policy that runs where it should run from one that walks everywhere, so each
*segment* (the stretch of an episode while waypoint k is the goal) is judged on its own by the rule of
:mod:`latentrl.rewards.skills` (run and walk by mean pelvis speed, hops by single-foot contact; the
``skill`` reward term trains toward the same rule), with the metric kernels of
:mod:`~latentrl.evaluation.metrics`.

The first :data:`TRANSITION_S` of a segment are left out (the motion is still changing skill), and
segments shorter than :data:`MIN_SEGMENT_S` are not measured at all. On a scene's terrain a foot counts as
down on whatever ground is under it (a tread, a box top), as the floor metrics measure it.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch

from latentrl.evaluation import metrics as M
from latentrl.motion.clip import MotionClip
from latentrl.motion.representation import FUTURE_LENGTH, HISTORY_LENGTH
from latentrl.motion.skeleton import FOOT_JOINTS
from latentrl.rewards.skills import (  # noqa: F401  (the rule's names, re-exported for the judge's readers)
    CONTACT_HEIGHT_M,
    HOP_OTHER_MAX_SHARE,
    HOP_STANCE_MIN_SHARE,
    RUN_MIN_SPEED_M_S,
    SKILLS,
    WALK_SPEED_M_S,
    matches,
    skill_of,
)

TRANSITION_S = 0.5
"""Seconds at the start of a segment that are not judged: the motion is still switching skill."""
MIN_SEGMENT_S = 1.0
"""Segments shorter than this (whole segment, transition included) are not measured."""


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


def judge_segment(clip: MotionClip, seg: Segment, terrain=None) -> dict[str, Any]:
    """One segment's entry: where it is, its skill, what was measured and whether it matches.

    ``terrain`` (a scene's one-row ``SceneBatch``; None: the flat floor at ``clip.floor``) is the ground the
    feet stand on (:func:`~latentrl.evaluation.metrics.terrain_floor`).

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
    ground = clip.floor if terrain is None else M.terrain_floor(
        torch.as_tensor(window, dtype=torch.float32), terrain, clip.floor)[:, list(FOOT_JOINTS)]
    shares = M.foot_contact_shares(window, ground, CONTACT_HEIGHT_M)
    left, right = float(shares["left_only"]), float(shares["right_only"])
    entry.update(measured=True, match=matches(skill, speed, left, right), speed_m_s=speed, left_only=left,
                 right_only=right)
    return entry


def judge_clip(clip: MotionClip, terrain=None) -> list[dict[str, Any]]:
    """:func:`judge_segment` of every segment of an episode, in order, on ``terrain`` (None: the flat floor)."""
    return [judge_segment(clip, seg, terrain) for seg in segments(clip)]


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
