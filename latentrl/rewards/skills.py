"""Skill families of prompts and the rule that says whether motion matches its text.

One rule serves two readers: the evaluation judges each waypoint segment of a multi-skill path with it
(:mod:`latentrl.evaluation.skills`), and the ``skill`` reward term (:func:`latentrl.rewards.terms.skill_fidelity`)
penalises a step by how far it is from passing it, so a policy is trained toward what it is judged on.

- "run" family (run, jog, ...): mean horizontal pelvis speed >= :data:`RUN_MIN_SPEED_M_S`;
- "walk" family: speed within :data:`WALK_SPEED_M_S`;
- "hop on left leg": the left foot alone on the floor in >= :data:`HOP_STANCE_MIN_SHARE` of the
  frames and the right foot alone in <= :data:`HOP_OTHER_MAX_SHARE`; mirrored for the right leg;
- any other text is not judged (family None, code 0).

The thresholds are rough (the default model walks at about 0.85-1.2 m/s and runs at 3.2-4.2 m/s): they
separate the skills, they do not grade them.
"""

from __future__ import annotations

import re

RUN_MIN_SPEED_M_S = 2.0
"""A "run" segment matches at this mean horizontal pelvis speed or faster."""
WALK_SPEED_M_S = (0.5, 2.0)
"""A "walk" segment matches within [min, max) m/s: slower is standing, faster is running."""
HOP_STANCE_MIN_SHARE = 0.4
"""A "hop on left leg" segment needs the left foot alone on the floor in at least this share of frames..."""
HOP_OTHER_MAX_SHARE = 0.1
"""...and the right foot alone in at most this share (mirrored for the right leg)."""
CONTACT_HEIGHT_M = 0.05
"""A foot joint is on the floor within this height when skills are judged (looser than the ``foot_floor``
and ``skate`` terms' 3 cm: a hop's stance foot rolls)."""

SKILLS = ("run", "walk", "hop_left", "hop_right")
"""The skill families that are judged; a family's code is its index + 1 (0: not judged)."""
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


def skill_code(text: str) -> int:
    """:func:`skill_of` as an integer for tensors: index in :data:`SKILLS` + 1, or 0 when not judged."""
    skill = skill_of(text)
    return 0 if skill is None else SKILLS.index(skill) + 1


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
