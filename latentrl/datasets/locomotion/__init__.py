"""Procedural locomotion generator: a deterministic motion-text dataset for the motion model.

There is no AMASS/BABEL on a fresh machine, so the shipped motion model trains on this data (design notes in
offline_assets.md section 2; user guide in docs/datasets.md). One sequence is made in five steps:

1. **Plan**: a chain of skill blocks (walk, run, hop, jump, turn, sidestep, stand...) joined by 0.3-0.6 s
   cross-fades along an allowed-transition graph; the next skill is drawn to balance frames across skills.
2. **Channels**: each skill maps a gait phase (cycles, advancing at the blended cycle frequency, continuous
   across transitions) to named channels: root velocity and yaw rate, pelvis bob/sway/yaw/list/tilt, trunk
   lean and twist, arm swing opposite the legs, elbow flexion, foot-placement settings and per-leg contact.
   The periodic channels are one- or two-harmonic Fourier series of the phase; jumps use C1 keyframes with
   an exactly ballistic flight. Block channels are blended with partition-of-unity weights.
3. **Root and footprints**: the root is integrated from the commanded velocity and yaw rate. Each stance is
   a footprint fixed in the world, placed at the foot's nominal spot under the root at mid-stance.
4. **Feet and pelvis height**: stance toes are locked on their footprints (heel rise late in stance, toe-first
   or heel-first landings pivot about the toe or heel); swing toes follow smooth arcs between footprints. The
   pelvis is lowered wherever a stance foot would otherwise be out of reach.
5. **Pose**: legs by analytic two-bone IK (knee towards the toes), upper body from the channels, then
   axis-angle poses and forward kinematics with ``latentrl.motion.skeleton``.

Why footprints + IK rather than Fourier leg angles with the root chosen to hold the stance foot: in double
support both feet must stay still, and Fourier hip/knee curves do not keep the distance between the feet
constant, so one foot always slides. Locking footprints and solving the legs makes stance feet exactly still
(zero horizontal skate by construction) and keeps stance toes exactly at ``TOE_HEIGHT_M`` above the floor; the
hip and knee curves then follow from the foot paths and pelvis motion.

Scene skills (``SCENE_SKILLS``, opt-in through ``LocomotionConfig.skills``) reuse these steps: crouching,
sitting and getting up keyframe the pelvis and trunk on planted feet from their block's start; stairs move
each stance onto a tread and build the flight under the steps; reach, wave and pick up put a hand on a
target by arm IK. Their scene data (seats, stair flights, the ground under each foot, hand targets) is
stored with the sequence (``motion_text.OPTIONAL_FIELDS``).

Everything is a pure function of ``LocomotionConfig`` (``numpy.random.Generator`` seeded per sequence with
``(seed, index)``; the skill balance carries over from earlier sequences in order).

Modules: ``config`` (skills, texts, transition graph, ``LocomotionConfig``), ``skills`` (per-skill channels),
``plan`` (blocks, blending, contacts), ``feet`` (footprints, swings, IK pose), ``generator`` (one sequence,
the public API, statistics).
"""

from latentrl.datasets.locomotion.config import (
    FOLLOWERS,
    LOCOMOTION_SKILLS,
    NEIGHBOURS,
    SCENE_SKILLS,
    SKILLS,
    SYNONYMS,
    TEXT_SPEED_RANGE,
    TEXT_TO_SKILL,
    LocomotionConfig,
    texts_for,
)
from latentrl.datasets.locomotion.generator import dataset_statistics, foot_skate, generate_dataset, generate_sequences

__all__ = [
    "FOLLOWERS",
    "LOCOMOTION_SKILLS",
    "NEIGHBOURS",
    "SCENE_SKILLS",
    "SKILLS",
    "SYNONYMS",
    "TEXT_SPEED_RANGE",
    "TEXT_TO_SKILL",
    "LocomotionConfig",
    "dataset_statistics",
    "foot_skate",
    "generate_dataset",
    "generate_sequences",
    "texts_for",
]
