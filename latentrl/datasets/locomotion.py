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

Everything is a pure function of ``LocomotionConfig`` (``numpy.random.Generator`` seeded per sequence with
``(seed, index)``; the skill balance carries over from earlier sequences in order).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from latentrl.datasets.body import (
    TOE_HEIGHT_M,
    Body,
    axis_angle_to_matrix_np,
    forward_kinematics_np,
    leg_rotations,
    make_body,
    matrix_to_axis_angle_np,
    rot_x,
    rot_y,
    rot_z,
    two_bone_ik,
    yaw_roll_pitch,
)
from latentrl.datasets.motion_text import write_meta, write_sequence
from latentrl.errors import ConfigError, closest
from latentrl.motion.skeleton import FOOT_JOINTS, FPS

G = 9.81  # m/s^2
_PAD_S = 1.2  # simulated margin before and after each sequence so the first and last steps are whole
_REACH = 0.998  # stance hip-ankle distance kept below this fraction of thigh + shank
_SWING_TO_HELD_S = 0.35  # time for a foot to travel between the floor and a held (lifted) pose
_HELD_MIN_HEIGHT = 0.1  # m, lowest toe height of a held foot
_HELD_AFTER_S = 0.9  # an air spell longer than this holds the foot up in between (no gait swings this long)

#: Canonical skills. Each has a synonym list in ``SYNONYMS``; the first synonym is the canonical text.
SKILLS: tuple[str, ...] = (
    "walk",
    "run",
    "hop_left",
    "hop_right",
    "jump_forward",
    "turn_left",
    "turn_right",
    "walk_backward",
    "sidestep_left",
    "sidestep_right",
    "stand",
)

#: Skill -> texts a segment of that skill may carry (no text belongs to two skills).
SYNONYMS: dict[str, tuple[str, ...]] = {
    "walk": ("walk", "walk forward", "stroll", "walk slowly", "walk fast", "walk briskly"),
    "run": ("run", "jog", "run forward", "jog forward", "run fast"),
    "hop_left": ("hop on left leg", "hop on the left leg", "hop on left foot"),
    "hop_right": ("hop on right leg", "hop on the right leg", "hop on right foot"),
    "jump_forward": ("jump forward", "jump", "leap forward"),
    "turn_left": ("turn left", "walk and turn left", "turn left while walking"),
    "turn_right": ("turn right", "walk and turn right", "turn right while walking"),
    "walk_backward": ("walk backwards", "walk backward", "move backwards"),
    "sidestep_left": ("sidestep left", "side step to the left", "step sideways to the left"),
    "sidestep_right": ("sidestep right", "side step to the right", "step sideways to the right"),
    "stand": ("stand still", "stand", "stand idle"),
}

#: Texts that only describe some speeds: text -> (min, max) speed in m/s; other texts fit any speed.
TEXT_SPEED_RANGE: dict[str, tuple[float, float]] = {
    "stroll": (0.0, 1.15),
    "walk slowly": (0.0, 1.05),
    "walk fast": (1.35, math.inf),
    "walk briskly": (1.35, math.inf),
    "jog": (0.0, 3.1),
    "jog forward": (0.0, 3.1),
    "run fast": (3.4, math.inf),
}

#: Text -> canonical skill (inverse of ``SYNONYMS``).
TEXT_TO_SKILL: dict[str, str] = {text: skill for skill, texts in SYNONYMS.items() for text in texts}

# Allowed transitions (both directions). Jumps start and end standing; running is entered from walking.
_TRANSITIONS: tuple[tuple[str, str], ...] = (
    ("stand", "walk"),
    ("stand", "walk_backward"),
    ("stand", "sidestep_left"),
    ("stand", "sidestep_right"),
    ("stand", "hop_left"),
    ("stand", "hop_right"),
    ("stand", "jump_forward"),
    ("stand", "turn_left"),
    ("stand", "turn_right"),
    ("walk", "run"),
    ("walk", "turn_left"),
    ("walk", "turn_right"),
    ("walk", "hop_left"),
    ("walk", "hop_right"),
    ("walk", "sidestep_left"),
    ("walk", "sidestep_right"),
    ("turn_left", "turn_right"),
    ("sidestep_left", "sidestep_right"),
    ("walk_backward", "sidestep_left"),
    ("walk_backward", "sidestep_right"),
)
#: Skill -> skills it may cross-fade into (the transition graph, symmetric).
NEIGHBOURS: dict[str, tuple[str, ...]] = {
    s: tuple(sorted({b for a, b in _TRANSITIONS if a == s} | {a for a, b in _TRANSITIONS if b == s}))
    for s in SKILLS
}
# Stand and walk connect most skills, so their blocks are shorter to keep the frame counts balanced.
_HUB_SHARE = {"stand": 0.45, "walk": 0.6}
_CANONICAL_WEIGHT = 3.0  # the canonical text is drawn this many times as often as each other synonym


def texts_for(skill: str, speed: float) -> tuple[str, ...]:
    """Synonyms of ``skill`` that fit a segment moving at ``speed`` m/s (see ``TEXT_SPEED_RANGE``)."""

    def fits(text: str) -> bool:
        low, high = TEXT_SPEED_RANGE.get(text, (0.0, math.inf))
        return low <= speed <= high

    return tuple(t for t in SYNONYMS[skill] if fits(t))


@dataclass(frozen=True)
class LocomotionConfig:
    """Settings of the procedural locomotion dataset (defaults: about 50k frames, ~20% transitions)."""

    num_sequences: int = 120
    """Number of sequences (one ``.npz`` file each)."""
    seconds_per_sequence: float = 14.0
    """Length of each sequence in seconds, at 30 fps."""
    seed: int = 0
    """Seed; the dataset is a pure function of the config."""
    skills: tuple[str, ...] = SKILLS
    """Skills to generate (a subset of ``SKILLS``); transitions to skills outside it are skipped."""
    block_seconds: tuple[float, float] = (2.2, 3.8)
    """Range of the time a skill runs at full weight, in seconds (stand and walk blocks are shorter)."""
    transition_seconds: tuple[float, float] = (0.3, 0.6)
    """Range of the cross-fade between two skills, in seconds; labelled with both skills."""
    height_range: tuple[float, float] = (1.55, 1.90)
    """Body height range in metres; one body per sequence."""
    start_half_size: float = 3.0
    """Sequences start at a uniform point of the square [-s, s]^2 (metres) with a uniform heading."""
    name: str = "latentrl-procedural-locomotion"
    """Dataset name written to ``meta.json``."""

    def validate(self) -> None:
        """Raise ``ConfigError`` naming the first invalid field."""
        for skill in self.skills:
            if skill not in SKILLS:
                raise ConfigError(f"LocomotionConfig.skills: unknown skill '{skill}'{closest(skill, SKILLS)}; "
                                  f"expected some of {', '.join(SKILLS)}")
        if not self.skills:
            raise ConfigError("LocomotionConfig.skills: empty, expected at least one skill")
        if self.num_sequences < 1:
            raise ConfigError(f"LocomotionConfig.num_sequences: {self.num_sequences}, expected >= 1")
        if self.seconds_per_sequence < 1.0:
            raise ConfigError(f"LocomotionConfig.seconds_per_sequence: {self.seconds_per_sequence}, expected >= 1")
        for name, lo_min in (("block_seconds", 0.5), ("transition_seconds", 0.1), ("height_range", 1.0)):
            lo, hi = getattr(self, name)
            if not lo_min <= lo <= hi:
                raise ConfigError(f"LocomotionConfig.{name}: ({lo}, {hi}), expected {lo_min} <= low <= high")


# --- small math helpers -----------------------------------------------------------------------------------


def _frac(x: np.ndarray) -> np.ndarray:
    return x - np.floor(x)


def _smoothstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def _smootherstep(x: np.ndarray) -> np.ndarray:
    x = np.clip(x, 0.0, 1.0)
    return x * x * x * (x * (6.0 * x - 15.0) + 10.0)


def _window(phase: np.ndarray, start: float, end: float) -> np.ndarray:
    """True where the fractional phase lies in [start, end) (cycles)."""
    p = _frac(phase)
    return (p >= start) & (p < end)


def _hermite(x: np.ndarray, knots: Sequence[tuple[float, float, float]]) -> np.ndarray:
    """C1 cubic through keyframes ``(x_k, value_k, slope_k)`` (slope = d value / d x); clamps outside."""
    kx = np.array([k[0] for k in knots])
    kv = np.array([k[1] for k in knots])
    km = np.array([k[2] for k in knots])
    x = np.clip(x, kx[0], kx[-1])
    i = np.clip(np.searchsorted(kx, x, side="right") - 1, 0, len(kx) - 2)
    h = kx[i + 1] - kx[i]
    s = (x - kx[i]) / h
    s2, s3 = s * s, s * s * s
    return ((2 * s3 - 3 * s2 + 1) * kv[i] + (s3 - 2 * s2 + s) * h * km[i]
            + (3 * s2 - 2 * s3) * kv[i + 1] + (s3 - s2) * h * km[i + 1])


def _spring_mass_dz(step: np.ndarray, duty: float, period: float, base: float) -> np.ndarray:
    """Pelvis height offset (m) over one step: a sine dip in stance, a ballistic arc in flight.

    ``step`` is the step phase (0 at touch-down), ``duty`` the stance fraction of the step and ``period`` the
    step duration (s). The dip depth is chosen so the vertical velocity is continuous at touch-down and
    take-off (spring-mass running / hopping), and the flight is a parabola under gravity.
    """
    t_stance, t_flight = duty * period, (1.0 - duty) * period
    v_off = G * t_flight / 2.0
    dip = v_off * t_stance / math.pi
    s = _frac(step)
    in_stance = s < duty
    stance = base - dip * np.sin(math.pi * np.minimum(s, duty) / duty)
    tf = (s - duty) * period
    flight = base + v_off * tf - 0.5 * G * tf * tf
    return np.where(in_stance, stance, flight)


def _drift_params(rng: np.random.Generator, amplitude: float) -> tuple[float, ...]:
    """Two slow random sinusoids (amplitude rad/s) that make straight skills wander in heading."""
    a = amplitude * rng.uniform(0.3, 1.0, 2)
    f = rng.uniform(0.08, 0.3, 2)
    p = rng.uniform(0.0, 2 * math.pi, 2)
    return (a[0], f[0], p[0], a[1], f[1], p[1])


def _drift(t: np.ndarray, d: tuple[float, ...]) -> np.ndarray:
    return d[0] * np.sin(2 * math.pi * d[1] * t + d[2]) + d[3] * np.sin(2 * math.pi * d[4] * t + d[5])


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) index ranges where ``mask`` is True."""
    padded = np.concatenate(([False], mask, [False])).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return list(zip(edges[0::2].tolist(), edges[1::2].tolist()))


# --- skills: parameters and channels ----------------------------------------------------------------------

#: Blended per-frame channels and their neutral (standing) values; angles in radians, lengths in metres.
_CHANNEL_DEFAULTS: dict[str, float] = {
    "v_fwd": 0.0,  # root speed along the heading (m/s)
    "v_side": 0.0,  # root speed to the body's right (m/s)
    "yaw_rate": 0.0,  # heading rate, counter-clockwise seen from above (rad/s)
    "dz": -0.002,  # pelvis height relative to the rest pelvis height (m)
    "sway": 0.0,  # pelvis offset to the body's right (m)
    "surge": 0.0,  # pelvis offset forward (m)
    "pelvis_yaw": 0.0,
    "pelvis_roll": 0.0,  # + leans right
    "pelvis_pitch": 0.0,  # + tilts back
    "trunk_yaw": 0.0,  # summed over spine1-3
    "trunk_roll": 0.0,
    "trunk_pitch": 0.0,
    "shoulder_l": math.radians(3),  # flexion, + swings the arm forward
    "shoulder_r": math.radians(3),
    "arm_abd": math.radians(5),  # abduction, + moves the arms away from the body
    "elbow_l": math.radians(12),  # flexion
    "elbow_r": math.radians(12),
    "stance_width": 0.0,  # lateral distance of each toe joint from the root line (m); 0.06 H when standing
    "foot_shift": 0.0,  # forward shift of footprints from the nominal spot (m)
    "toe_out": math.radians(7),
    "clearance": 0.06,  # toe lift during swing (m)
    "swing_peak": 0.5,  # where in the swing (fraction) the lift peaks
    "heel_rise": 0.0,  # foot pitch at toe-off (heel up)
    "heel_strike": 0.0,  # toes-up foot pitch at a heel-first landing
    "rocker_s": 0.0,  # heel-first landing: time to roll from heel to flat foot (s)
    "toe_land": 0.0,  # heel-up foot pitch at a toe-first landing
    "tuck_hip": math.radians(30),  # hip and knee flexion of a leg held off the floor
    "tuck_knee": math.radians(100),
}


def _neutral(n: int, body: Body) -> dict[str, np.ndarray]:
    ch = {k: np.full(n, v) for k, v in _CHANNEL_DEFAULTS.items()}
    ch["stance_width"][:] = 0.06 * body.height
    return ch


def _cadence_scale(body: Body) -> float:
    """Froude scaling of step frequency with leg length, relative to a 1.75 m body."""
    return math.sqrt(0.5 * 1.75 / body.rest_joints[1, 2])


def _sample_params(skill: str, rng: np.random.Generator, body: Body) -> dict:
    """Per-block skill parameters (SI units); ``f`` is the gait-cycle frequency in cycles/s."""
    scale = _cadence_scale(body)
    if skill in ("walk", "turn_left", "turn_right"):
        turn = {"walk": 0.0, "turn_left": 1.0, "turn_right": -1.0}[skill]
        v = rng.uniform(0.8, 1.6) if turn == 0 else rng.uniform(0.8, 1.2)
        k = (v - 0.8) / 0.8
        steps = np.clip((1.7 + 0.4 * k) * scale + rng.normal(0, 0.03), 1.7, 2.1)
        yaw = turn * math.radians(rng.uniform(30, 90))
        drift = _drift_params(rng, math.radians(8 if turn == 0 else 3))
        return dict(v_fwd=v, v_side=0.0, k=k, f=steps / 2, yaw_rate=yaw, drift=drift, rocker=0.10,
                    toe_off=0.62 - 0.03 * k, width=0.035 * body.height, shift=-(0.07 + 0.02 * k) * body.height)
    if skill == "walk_backward":
        v = rng.uniform(0.5, 1.0)
        steps = np.clip((1.5 + 0.3 * (v - 0.5) / 0.5) * scale, 1.45, 1.9)
        return dict(v_fwd=-v, v_side=0.0, k=(v - 0.5) / 0.5, f=steps / 2, yaw_rate=0.0, rocker=0.0,
                    drift=_drift_params(rng, math.radians(4)), toe_off=0.62, width=0.04 * body.height)
    if skill in ("sidestep_left", "sidestep_right"):
        v = rng.uniform(0.25, 0.4) * (-1.0 if skill == "sidestep_left" else 1.0)
        steps = rng.uniform(1.5, 1.9) * scale
        return dict(v_fwd=0.0, v_side=v, k=0.0, f=steps / 2, yaw_rate=0.0, rocker=0.0,
                    drift=_drift_params(rng, 0.0), toe_off=0.68, width=0.10 * body.height)
    if skill == "run":
        v = rng.uniform(2.5, 4.0)
        k = (v - 2.5) / 1.5
        steps = np.clip((2.6 + 0.4 * k) * scale + rng.normal(0, 0.03), 2.6, 3.0)
        return dict(v_fwd=v, k=k, f=steps / 2, duty=0.36 - 0.06 * k, drift=_drift_params(rng, math.radians(6)),
                    shift=-0.08 * body.height)
    if skill in ("hop_left", "hop_right"):
        f = rng.uniform(1.8, 2.2)
        t_flight_max = 0.55 / f
        apex = rng.uniform(0.05, min(0.15, G * t_flight_max**2 / 8))
        t_flight = math.sqrt(8 * apex / G)
        return dict(v_fwd=rng.uniform(0.0, 1.0), f=f, apex=apex, duty=1.0 - t_flight * f,
                    drift=_drift_params(rng, math.radians(4)))
    if skill == "jump_forward":
        apex = rng.uniform(0.2, 0.35)
        t_flight = math.sqrt(8 * apex / G)
        return dict(f=1.0 / rng.uniform(1.8, 2.1), apex=apex, t_flight=t_flight,
                    v_jump=rng.uniform(0.6, 1.1) / t_flight, jumps=int(rng.integers(1, 3)))
    if skill == "stand":
        return dict(f=0.0, sway=rng.uniform(0.004, 0.012), sway_f=rng.uniform(0.2, 0.3),
                    sway_ph=rng.uniform(0, 2 * math.pi, 2), breath_f=rng.uniform(0.2, 0.3),
                    width=rng.uniform(0.05, 0.065) * body.height)
    raise ValueError(skill)


_ChannelFn = Callable[[np.ndarray, np.ndarray, dict, Body], tuple[dict, np.ndarray]]


def _walk_like(phase: np.ndarray, t: np.ndarray, p: dict, body: Body) -> tuple[dict, np.ndarray]:
    """Walking forwards, backwards, turning or sidestepping: left heel strike at phase 0, right at 0.5."""
    ch = _neutral(len(phase), body)
    k = p["k"]
    ang = 2 * math.pi * phase
    fwd = float(np.sign(p["v_fwd"]))  # +1 forwards, -1 backwards, 0 sideways
    swing_sign = fwd if fwd != 0 else 1.0
    ch["v_fwd"][:] = p["v_fwd"]
    ch["v_side"][:] = p["v_side"]
    ch["yaw_rate"] = p["yaw_rate"] + _drift(t, p["drift"])
    # pelvis lowest just after each heel strike, highest in mid single support (inverted pendulum)
    ch["dz"] = -(0.008 + 0.012 * k) + (0.006 + 0.01 * k) * np.cos(4 * math.pi * (phase - 0.3))
    ch["sway"] = -(0.022 - 0.008 * k) * np.sin(ang)  # over the stance foot: left (-x) in left stance
    yaw_amp = math.radians(3 + 4 * k) * swing_sign
    ch["pelvis_yaw"] = -yaw_amp * np.cos(ang)  # the swinging leg's hip moves forward
    ch["pelvis_roll"] = math.radians(2.5 + 2 * k) * np.sin(ang + 0.3)  # swing side drops
    ch["pelvis_pitch"] = -math.radians(2 + 2 * k) - math.radians(1) * np.cos(4 * math.pi * (phase - 0.1))
    ch["trunk_yaw"] = 1.5 * yaw_amp * np.cos(ang)  # thorax counter-rotates against the pelvis
    ch["trunk_roll"] = -0.6 * ch["pelvis_roll"]
    ch["trunk_pitch"][:] = -math.radians(1 + 3 * k) if fwd >= 0 else -math.radians(3)
    arm = math.radians(10 + 18 * k if fwd > 0 else (10 if fwd < 0 else 4)) * swing_sign * np.cos(ang)
    ch["shoulder_r"] = math.radians(3) + arm  # right arm forward when the left leg is forward
    ch["shoulder_l"] = math.radians(3) - arm
    elbow_gain = math.radians(6 + 10 * k)
    ch["elbow_r"] = math.radians(14 + 8 * k) + elbow_gain * (0.5 + 0.5 * np.cos(ang) * swing_sign)
    ch["elbow_l"] = math.radians(14 + 8 * k) + elbow_gain * (0.5 - 0.5 * np.cos(ang) * swing_sign)
    ch["arm_abd"][:] = math.radians(6 if fwd != 0 else 9)
    ch["stance_width"][:] = p["width"]
    ch["toe_out"][:] = math.radians(6)
    ch["clearance"][:] = 0.05 + 0.03 * k if fwd > 0 else 0.05
    ch["swing_peak"][:] = 0.2 if fwd > 0 else 0.4  # toe lifts right after toe-off, low in mid-swing
    ch["heel_rise"][:] = math.radians(40 + 15 * k) if fwd > 0 else math.radians(5 if fwd < 0 else 10)
    ch["foot_shift"][:] = p.get("shift", 0.0)
    if fwd > 0:
        ch["heel_strike"][:] = math.radians(12 + 6 * k)
        ch["rocker_s"][:] = p["rocker"] / p["f"]
    ch["toe_land"][:] = 0.0 if fwd > 0 else math.radians(18 if fwd < 0 else 6)
    r, off = p["rocker"], p["toe_off"]
    contact = np.stack((_window(phase, r, off), _window(phase - 0.5, r, off)), axis=-1)
    return ch, contact


def _run(phase: np.ndarray, t: np.ndarray, p: dict, body: Body) -> tuple[dict, np.ndarray]:
    """Running with a flight phase: left foot strike at phase 0, right at 0.5; spring-mass pelvis height."""
    ch = _neutral(len(phase), body)
    k, duty = p["k"], p["duty"]
    ang = 2 * math.pi * phase
    ch["v_fwd"][:] = p["v_fwd"]
    ch["yaw_rate"] = _drift(t, p["drift"])
    ch["dz"] = _spring_mass_dz(2 * phase, 2 * duty, 0.5 / p["f"], base=-(0.025 + 0.025 * k))
    ch["sway"] = -0.01 * np.sin(ang)
    yaw_amp = math.radians(5 + 3 * k)
    ch["pelvis_yaw"] = -yaw_amp * np.cos(ang)
    ch["pelvis_roll"] = math.radians(4) * np.sin(ang + 0.3)
    ch["pelvis_pitch"][:] = -math.radians(6 + 3 * k)
    ch["trunk_yaw"] = 1.6 * yaw_amp * np.cos(ang)
    ch["trunk_roll"] = -0.7 * ch["pelvis_roll"]
    ch["trunk_pitch"][:] = -math.radians(4 + 4 * k)
    arm = math.radians(28 + 12 * k) * np.cos(ang)
    ch["shoulder_r"] = math.radians(5) + arm
    ch["shoulder_l"] = math.radians(5) - arm
    ch["elbow_r"] = math.radians(80 + 10 * k) + math.radians(10) * np.cos(ang)
    ch["elbow_l"] = math.radians(80 + 10 * k) - math.radians(10) * np.cos(ang)
    ch["arm_abd"][:] = math.radians(10)
    ch["stance_width"][:] = 0.025 * body.height
    ch["toe_out"][:] = math.radians(4)
    ch["clearance"][:] = 0.17 + 0.12 * k
    ch["swing_peak"][:] = 0.3  # the heel kicks up behind the body
    ch["foot_shift"][:] = p["shift"]
    ch["heel_rise"][:] = math.radians(50 + 10 * k)
    ch["toe_land"][:] = math.radians(6)
    contact = np.stack((_window(phase, 0.0, duty), _window(phase - 0.5, 0.0, duty)), axis=-1)
    return ch, contact


def _hop(phase: np.ndarray, t: np.ndarray, p: dict, body: Body, side: float) -> tuple[dict, np.ndarray]:
    """Hopping on one leg (``side`` -1 left, +1 right), one hop per cycle; the other leg is held up."""
    ch = _neutral(len(phase), body)
    ph = _frac(phase)
    ang = 2 * math.pi * ph
    ch["v_fwd"][:] = p["v_fwd"]
    ch["yaw_rate"] = _drift(t, p["drift"])
    ch["dz"] = _spring_mass_dz(ph, p["duty"], 1.0 / p["f"], base=-0.035)
    ch["sway"][:] = side * 0.035  # pelvis over the stance foot
    ch["pelvis_roll"][:] = -side * math.radians(4)  # the unsupported side drops
    ch["trunk_roll"][:] = side * math.radians(6)  # the trunk leans over the stance leg
    ch["pelvis_pitch"][:] = -math.radians(6)
    ch["trunk_pitch"] = -math.radians(6) - math.radians(4) * np.cos(ang)
    lift = math.radians(12) * np.sin(ang - 0.6)
    ch["shoulder_l"] = math.radians(10) + lift
    ch["shoulder_r"] = math.radians(10) + lift
    ch["arm_abd"] = math.radians(22) + math.radians(6) * np.sin(ang)
    ch["elbow_l"][:] = math.radians(35)
    ch["elbow_r"][:] = math.radians(35)
    ch["stance_width"][:] = 0.02 * body.height
    ch["toe_out"][:] = math.radians(5)
    ch["clearance"][:] = 0.03 + 1.2 * p["apex"]
    ch["heel_rise"][:] = math.radians(28)
    ch["toe_land"][:] = math.radians(14)
    stance = _window(phase, 0.0, p["duty"])
    never = np.zeros_like(stance)
    contact = np.stack((stance, never) if side < 0 else (never, stance), axis=-1)
    return ch, contact


def _jump_times(p: dict) -> dict[str, float]:
    """Event times (s) within one jump cycle: stand, crouch, push, flight, absorb, recover, stand."""
    crouch = 0.08
    bottom = crouch + 0.30
    takeoff = bottom + 0.20
    land = takeoff + p["t_flight"]
    absorbed = land + 0.15
    return dict(crouch=crouch, bottom=bottom, takeoff=takeoff, land=land, absorbed=absorbed,
                recovered=absorbed + 0.40, period=1.0 / p["f"])


def _jump(phase: np.ndarray, t: np.ndarray, p: dict, body: Body) -> tuple[dict, np.ndarray]:
    """Standing broad jump: crouch, push, ballistic flight, landing absorption, recovery (keyframed)."""
    ch = _neutral(len(phase), body)
    e = _jump_times(p)
    tau = _frac(phase) * e["period"]
    v_off = G * p["t_flight"] / 2.0  # vertical take-off speed for the sampled flight time
    base = _CHANNEL_DEFAULTS["dz"]
    push, absorb = e["takeoff"] - e["bottom"], e["absorbed"] - e["land"]
    ch["dz"] = _hermite(tau, [  # constant acceleration in push and absorption, exact parabola in flight
        (0.0, base, 0.0), (e["crouch"], base, 0.0), (e["bottom"], -v_off * push / 2, 0.0),
        (e["takeoff"], 0.0, v_off), (e["land"], 0.0, -v_off), (e["absorbed"], -v_off * absorb / 2, 0.0),
        (e["recovered"], base, 0.0), (e["period"], base, 0.0)])
    v = p["v_jump"]
    ch["v_fwd"] = _hermite(tau, [(0.0, 0.0, 0.0), (e["bottom"], 0.0, 0.0), (e["takeoff"], v, 0.0),
                                 (e["land"], v, 0.0), (e["absorbed"] + 0.1, 0.0, 0.0), (e["period"], 0.0, 0.0)])
    ch["surge"] = _hermite(tau, [(0.0, 0.0, 0.0), (e["crouch"], 0.0, 0.0), (e["bottom"], -0.06, 0.0),
                                 (e["takeoff"], 0.0, 0.0), (e["period"], 0.0, 0.0)])
    mid_air = 0.5 * (e["takeoff"] + e["land"])
    deg = math.radians
    lean = _hermite(tau, [(0.0, 0.0, 0.0), (e["crouch"], 0.0, 0.0), (e["bottom"], deg(35), 0.0),
                          (e["takeoff"], deg(8), 0.0), (mid_air, deg(3), 0.0), (e["land"], deg(8), 0.0),
                          (e["absorbed"], deg(28), 0.0), (e["recovered"], 0.0, 0.0), (e["period"], 0.0, 0.0)])
    ch["pelvis_pitch"] = -0.45 * lean
    ch["trunk_pitch"] = -0.55 * lean
    arms = _hermite(tau, [(0.0, deg(3), 0.0), (e["crouch"], deg(3), 0.0), (e["bottom"], deg(-40), 0.0),
                          (e["takeoff"], deg(85), 0.0), (mid_air, deg(70), 0.0), (e["land"], deg(45), 0.0),
                          (e["absorbed"], deg(25), 0.0), (e["recovered"], deg(3), 0.0), (e["period"], deg(3), 0.0)])
    elbows = _hermite(tau, [(0.0, deg(12), 0.0), (e["bottom"], deg(20), 0.0), (e["takeoff"], deg(25), 0.0),
                            (e["land"], deg(30), 0.0), (e["recovered"], deg(12), 0.0), (e["period"], deg(12), 0.0)])
    ch["shoulder_l"], ch["shoulder_r"] = arms, arms.copy()
    ch["elbow_l"], ch["elbow_r"] = elbows, elbows.copy()
    ch["arm_abd"][:] = deg(8)
    ch["stance_width"][:] = 0.055 * body.height
    ch["clearance"][:] = 0.12
    ch["heel_rise"][:] = deg(35)
    ch["toe_land"][:] = deg(15)
    on = (tau < e["takeoff"]) | (tau >= e["land"])
    return ch, np.stack((on, on), axis=-1)


def _stand(phase: np.ndarray, t: np.ndarray, p: dict, body: Body) -> tuple[dict, np.ndarray]:
    """Quiet standing: about 1 cm of postural sway at 0.2-0.3 Hz and breathing in the chest."""
    ch = _neutral(len(phase), body)
    w = 2 * math.pi * p["sway_f"]
    ch["sway"] = p["sway"] * np.sin(w * t + p["sway_ph"][0])
    ch["surge"] = 0.6 * p["sway"] * np.sin(0.7 * w * t + p["sway_ph"][1])
    ch["trunk_pitch"] = math.radians(1.0) * np.sin(2 * math.pi * p["breath_f"] * t)
    ch["stance_width"][:] = p["width"]
    on = np.ones(len(phase), dtype=bool)
    return ch, np.stack((on, on), axis=-1)


_SKILL_FNS: dict[str, _ChannelFn] = {
    "walk": _walk_like,
    "turn_left": _walk_like,
    "turn_right": _walk_like,
    "walk_backward": _walk_like,
    "sidestep_left": _walk_like,
    "sidestep_right": _walk_like,
    "run": _run,
    "hop_left": lambda ph, t, p, b: _hop(ph, t, p, b, -1.0),
    "hop_right": lambda ph, t, p, b: _hop(ph, t, p, b, 1.0),
    "jump_forward": _jump,
    "stand": _stand,
}


def _block_speed(skill: str, p: dict) -> float:
    """Nominal speed (m/s): picks speed-specific texts and tells speed-ups from slow-downs."""
    if skill == "jump_forward":
        return 0.0
    return abs(p.get("v_fwd", 0.0)) + abs(p.get("v_side", 0.0))


# --- planning: skill blocks, weights, phase ---------------------------------------------------------------


@dataclass
class _Block:
    """One skill at full weight for ``core`` frames, cross-faded with its neighbours (padded timeline)."""

    skill: str
    params: dict
    text: str
    core: int  # frames at full weight
    blend_in: int  # frames of the cross-fade from the previous block
    blend_out: int  # frames of the cross-fade into the next block
    start: int = 0  # first frame with weight > 0
    end: int = 0  # one past the last frame with weight > 0
    phase_offset: float = 0.0  # added to the shared phase (jumps align their cycle with the blend)


def _choose(rng: np.random.Generator, options: Sequence[str], counts: dict[str, float]) -> str | None:
    """Draw a skill, strongly preferring those with the fewest frames so far (balanced dataset)."""
    if not options:
        return None
    c = np.array([counts[s] for s in options], dtype=float)
    w = np.exp(-(c - c.min()) / (5.0 * FPS))
    return options[int(rng.choice(len(options), p=w / w.sum()))]


def _pick_text(rng: np.random.Generator, skill: str, speed: float) -> str:
    """A synonym fitting ``speed``; the canonical text (DART's evaluation prompt) is drawn 3x as often."""
    texts = texts_for(skill, speed)
    weights = np.array([_CANONICAL_WEIGHT if t == SYNONYMS[skill][0] else 1.0 for t in texts])
    return texts[int(rng.choice(len(texts), p=weights / weights.sum()))]


def _plan_blocks(
    cfg: LocomotionConfig, rng: np.random.Generator, body: Body, counts: dict[str, float], total: int
) -> list[_Block]:
    """Chain skill blocks along the transition graph until ``total`` frames are filled."""
    skills = tuple(cfg.skills)
    skill = _choose(rng, [s for s in skills if s != "jump_forward"] or list(skills), counts)
    blocks: list[_Block] = []
    used = 0  # frames laid out up to the end of the latest block's core
    while True:
        p = _sample_params(skill, rng, body)
        blend_in = blocks[-1].blend_out if blocks else 0
        blend_out = round(rng.uniform(*cfg.transition_seconds) * FPS)
        if skill == "jump_forward":  # whole jumps between the blend centres, starting and ending in stance
            core = round((p["jumps"] - 0.04) / p["f"] * FPS) - (blend_in + blend_out) // 2
        else:
            core = round(rng.uniform(*cfg.block_seconds) * _HUB_SHARE.get(skill, 1.0) * FPS)
        text = _pick_text(rng, skill, _block_speed(skill, p))
        block = _Block(skill, p, text, core, blend_in, blend_out)
        blocks.append(block)
        used += blend_in + core
        counts[skill] += blend_in + core
        nxt = _choose(rng, [s for s in NEIGHBOURS[skill] if s in skills], counts)
        if nxt is None or total - used < blend_out + FPS:  # nothing to go to, or too little time left
            block.core += max(total - used, 0)
            block.blend_out = 0
            break
        skill = nxt
    start = 0
    for block in blocks:
        block.start, block.end = start, start + block.blend_in + block.core + block.blend_out
        start = block.end - block.blend_out
    return blocks


def _cycle_rate(blocks: Sequence[_Block], weights: np.ndarray) -> np.ndarray:
    """(T,) gait-cycle frequency (cycles/s): the weighted rate of the stepping skills.

    Standing has no gait, so it does not pull the rate of the skill it fades with (a walk slowing towards a
    stand keeps its cadence); across a pure stand the rate moves linearly to the next skill's, and a jump
    after a stand starts on its own rate, which the jump's cycle alignment relies on.
    """
    stepping = np.array([b.skill != "stand" for b in blocks])
    if not stepping.any():
        return np.ones(weights.shape[1])
    rates = np.array([b.params["f"] for b in blocks])
    wsum = weights[stepping].sum(axis=0)
    known = wsum > 1e-9
    frames = np.arange(weights.shape[1])
    rate = (rates[stepping] @ weights[stepping])[known] / wsum[known]
    return np.interp(frames, frames[known], rate)


_MOTION_CHANNELS = ("v_fwd", "v_side", "yaw_rate")


def _weights(ramps: Sequence[tuple[int, int]], total: int) -> np.ndarray:
    """(B, T) block weights; block i fades into block i+1 with a smoothstep over ``ramps[i]`` = [a, b).

    Stick-breaking (block i keeps ``prod_{j<i} rise_j * (1 - rise_i)``), so the weights sum to one even
    where two ramps overlap.
    """
    w = np.empty((len(ramps) + 1, total))
    frames = np.arange(total)
    remaining = np.ones(total)
    for i, (a, b) in enumerate(ramps):
        rise = _smoothstep((frames - a + 0.5) / max(b - a, 1))
        w[i] = remaining * (1.0 - rise)
        remaining = remaining * rise
    w[-1] = remaining
    return w


def _motion_ramps(blocks: Sequence[_Block], switches: Sequence[int], total: int) -> list[tuple[int, int]]:
    """Frames over which the root velocity fades from each block to the next.

    Stance lengths follow the contact schedule, so the speed must match the schedule that is stepping: a
    speed-up (a start from standing, walk to run) ramps after the contact switch, beginning with the first
    new step; a slow-down ramps before it, so the longer stances of the slower skill start at its speed.
    """
    ramps = []
    for a, b, switch in zip(blocks[:-1], blocks[1:], switches):
        if _block_speed(b.skill, b.params) >= _block_speed(a.skill, a.params):
            ramps.append((switch, min(switch + a.blend_out, total)))
        else:
            ramps.append((max(switch - a.blend_out, 0), switch))
    return ramps


def _evaluate_blocks(blocks: Sequence[_Block], phase: np.ndarray, t: np.ndarray, body: Body):
    """Each block's channels and (T, 2) contact schedule, evaluated on the whole timeline."""
    return [_SKILL_FNS[b.skill](phase + b.phase_offset, t, b.params, body) for b in blocks]


def _blend_channels(evaluated: Sequence[tuple[dict, np.ndarray]], weights: np.ndarray,
                    motion_weights: np.ndarray) -> dict[str, np.ndarray]:
    """Weighted sum of the blocks' channels; root-motion channels use ``motion_weights``."""
    ch = {}
    for k in _CHANNEL_DEFAULTS:
        w = motion_weights if k in _MOTION_CHANNELS else weights
        ch[k] = sum(wi * block_ch[k] for wi, (block_ch, _) in zip(w, evaluated))
    return ch


# --- contacts ---------------------------------------------------------------------------------------------


def _leading_run(mask: np.ndarray) -> int:
    """Length of the run of True values at the start of ``mask``."""
    return len(mask) if mask.all() else int(np.argmin(mask))


def _switch_frame(current: np.ndarray, incoming: np.ndarray, lo: int, hi: int) -> int:
    """Frame in the cross-fade [lo, hi) at which the contact schedule switches.

    Near the middle of the cross-fade, preferring frames where both schedules agree on which feet are down.
    """
    if hi <= lo:
        return lo
    frames = np.arange(lo, hi)
    cost = np.abs(frames - 0.5 * (lo + hi - 1)) / (hi - lo) + 0.5 * np.sum(
        current[frames] != incoming[frames], axis=-1
    )
    return int(frames[np.argmin(cost)])


def _clean_contacts(mask: np.ndarray, min_frames: int = 4) -> np.ndarray:
    """Fill interior air gaps and drop contacts shorter than ``min_frames`` (switching leftovers)."""
    mask = mask.copy()
    for a, b in _runs(~mask):
        if a > 0 and b < len(mask) and b - a < min_frames:
            mask[a:b] = True
    for a, b in _runs(mask):
        if b - a < min_frames and a > 0 and b < len(mask):
            mask[a:b] = False
    return mask


def _compose_contacts(blocks: Sequence[_Block], schedules: Sequence[np.ndarray]) -> tuple[np.ndarray, list[int]]:
    """(T, 2) bool foot contacts, each block's schedule from its switch frame on, and the switch frames.

    A foot in the air under the old schedule but down under the new one finishes its swing first (lands at
    the old schedule's touch-down), so a walk that stops ends with a closing step rather than a foot slapped
    down mid-swing; a foot the old schedule never puts down (a hop's held leg) comes down in
    ``_SWING_TO_HELD_S``.
    """
    contact = schedules[0].copy()
    switches = []
    for prev, block, incoming in zip(blocks[:-1], blocks[1:], schedules[1:]):
        switch = _switch_frame(contact, incoming, block.start, prev.end)
        switches.append(switch)
        for leg in range(2):
            new = incoming[switch:, leg].copy()
            if new[0] and not contact[switch, leg]:
                air = _leading_run(~contact[switch:, leg])
                new[: air if air <= FPS // 2 else round(_SWING_TO_HELD_S * FPS)] = False
            contact[switch:, leg] = new
    return np.stack([_clean_contacts(contact[:, leg]) for leg in range(2)], axis=-1), switches


# --- feet -------------------------------------------------------------------------------------------------


@dataclass
class _Feet:
    """Foot targets for both legs (index 0 left, 1 right) on the padded timeline."""

    toe: np.ndarray  # (T, 2, 3) toe-base joint targets, world, metres
    yaw: np.ndarray  # (T, 2) foot heading, rad, counter-clockwise from the rest facing (+y)
    pitch: np.ndarray  # (T, 2) foot pitch about its lateral axis, rad, + lifts the toes
    grounded: np.ndarray  # (T, 2) bool: toe locked on its footprint or heel pivoting on the floor


def _rot2(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def _footprints(contact: np.ndarray, root_xy: np.ndarray, heading: np.ndarray, ch: dict, body: Body, side: float):
    """(start, end, toe_xy, yaw) per stance: the nominal foot spot under the root at mid-stance.

    Long stances (a stop, standing) use the root 0.3 s after touch-down, about where a normal stance has its
    middle, so the last step of a stop is an ordinary step and the closing step lands beside it.
    """
    prints = []
    frames = np.arange(len(contact))
    for a, b in _runs(contact):
        ref = min((a + b - 1) / 2, a + 0.3 * FPS)  # fractional: at 4 m/s half a frame is 7 cm
        at = round(ref)
        xy = np.array([np.interp(ref, frames, root_xy[:, 0]), np.interp(ref, frames, root_xy[:, 1])])
        yaw = float(np.interp(ref, frames, heading))
        offset = np.array([side * ch["stance_width"][at], body.ankle_to_toe[1] + ch["foot_shift"][at]])
        prints.append((a, b, xy + _rot2(yaw) @ offset, yaw - side * ch["toe_out"][at]))
    return prints


def _stance_pitch(n: int, toe_land: float, heel_rise: float, lands: bool, lifts: bool) -> np.ndarray:
    """(n,) foot pitch (rad) over a stance of ``n`` frames, pivoting about the locked toe joint.

    A toe-first landing starts heel-up by ``toe_land`` and lowers the heel over at most 0.15 s; the heel
    rises to ``heel_rise`` over the last 0.3 s (at most 40% of the stance) before lift-off.
    """
    i = np.arange(n)
    pitch = np.zeros(n)
    land = min(round(0.15 * FPS), int(0.3 * n)) if lands else 0
    if land:
        pitch[:land] -= toe_land * (1.0 - _smoothstep(i[:land] / land))
    rise = min(round(0.3 * FPS), int(0.4 * n)) if lifts else 0
    if rise:
        pitch[n - rise:] -= heel_rise * _smoothstep((i[n - rise:] - (n - rise) + 1) / rise)
    return pitch


def _heel_roll(feet: _Feet, leg: int, a: int, frames: int, toe_xy: np.ndarray, yaw: float, strike: float,
               body: Body) -> None:
    """Fill the ``frames`` before touch-down ``a``: a heel-first landing rolling about the heel to flat."""
    heel = np.append(toe_xy - _rot2(yaw) @ body.heel_to_toe[:2], 0.0)
    pitch = strike * (1.0 - _smoothstep(np.arange(frames) / frames))
    feet.toe[a - frames:a, leg] = heel + rot_z(np.full(frames, yaw)) @ rot_x(pitch) @ body.heel_to_toe
    feet.yaw[a - frames:a, leg], feet.pitch[a - frames:a, leg] = yaw, pitch
    feet.grounded[a - frames:a, leg] = True


def _plant_feet(contact: np.ndarray, root_xy: np.ndarray, heading: np.ndarray, ch: dict, body: Body) -> _Feet:
    """Grounded foot targets: toes locked on their footprints, and heel-first landings rolling onto them."""
    total = len(contact)
    feet = _Feet(np.zeros((total, 2, 3)), np.zeros((total, 2)), np.zeros((total, 2)), np.zeros((total, 2), bool))
    for leg, side in ((0, -1.0), (1, 1.0)):
        prev_end = 0
        for a, b, xy, yaw in _footprints(contact[:, leg], root_xy, heading, ch, body, side):
            feet.toe[a:b, leg] = (xy[0], xy[1], TOE_HEIGHT_M)
            feet.yaw[a:b, leg], feet.grounded[a:b, leg] = yaw, True
            feet.pitch[a:b, leg] = _stance_pitch(b - a, ch["toe_land"][a], ch["heel_rise"][b - 1], a > 0, b < total)
            strike = ch["heel_strike"][a]
            roll = min(round(ch["rocker_s"][a] * FPS), int(0.3 * (a - prev_end))) if a > 0 and strike > 0.01 else 0
            if roll:
                _heel_roll(feet, leg, a, roll, xy, yaw, strike, body)
            prev_end = b
    return feet


def _hip(pelvis: np.ndarray, pelvis_rot: np.ndarray, body: Body, leg: int) -> np.ndarray:
    """(T, 3) world position of hip joint ``leg`` (0 left, 1 right) for a (T, 3) pelvis with (T, 3, 3) rotation."""
    return pelvis + pelvis_rot @ body.hip_offsets[leg]


def _held_feet(pelvis: np.ndarray, pelvis_rot: np.ndarray, heading: np.ndarray, ch: dict, body: Body):
    """(T, 2, 3) toe targets and (T,) pitch of a leg held off the floor (hip and knee flexed, toes down)."""
    alpha, kappa = ch["tuck_hip"], ch["tuck_knee"]
    ankle_fwd = body.thigh * np.sin(alpha) + body.shank * np.sin(alpha - kappa)
    ankle_down = body.thigh * np.cos(alpha) + body.shank * np.cos(alpha - kappa)
    pitch = np.full(len(heading), -0.3)
    foot = (rot_x(pitch) @ body.ankle_to_toe)  # (T, 3) in the heading frame
    toes = np.zeros((len(heading), 2, 3))
    for leg in range(2):
        hip = _hip(pelvis, pelvis_rot, body, leg)
        local = np.stack((np.zeros_like(alpha), ankle_fwd, -ankle_down), axis=-1) + foot
        toes[:, leg] = hip + (rot_z(heading) @ local[..., None])[..., 0]
    toes[..., 2] = np.maximum(toes[..., 2], _HELD_MIN_HEIGHT)  # guard for deep crouches
    return toes, pitch


def _swing_arc(tau: np.ndarray, peak: float) -> np.ndarray:
    """Unit-height lift over a swing, zero at both ends, peaking at ``tau = peak``: tau (1 - tau)^((1-p)/p)."""
    power = (1.0 - peak) / peak
    return tau * (1.0 - tau) ** power / (peak * (1.0 - peak) ** power)


def _air_spells(grounded: np.ndarray) -> list[tuple[int, int, bool, bool]]:
    """(start, end, from_floor, to_floor) per air spell of one foot.

    A spell longer than ``_HELD_AFTER_S`` is a leg held up (the free leg of a hop); it is split into a rise
    to the held pose and a descent from it, with the held pose in between.
    """
    total = len(grounded)
    spells = []
    for a, b in _runs(~grounded):
        if b - a > _HELD_AFTER_S * FPS:
            spells += [(a, (a + b) // 2, a > 0, False), ((a + b) // 2, b, False, b < total)]
        else:
            spells.append((a, b, a > 0, b < total))
    return spells


def _swing_feet(feet: _Feet, held: np.ndarray, held_pitch: np.ndarray, heading: np.ndarray,
                pelvis_z: np.ndarray, ch: dict) -> None:
    """Fill the air frames of ``feet``: arcs from lift-off to the next landing pose, or to / from a held pose.

    Horizontally the toe eases from footprint to footprint (zero speed at both ends, travel done before the
    final descent). Vertically it adds an early-peaking clearance arc (the heel kicks up) and the pelvis'
    excursion from its straight line over the spell, so feet rise and fall with the body in flight.
    """
    span = round(_SWING_TO_HELD_S * FPS)
    for leg in range(2):
        for a, b, prev, nxt in _air_spells(feet.grounded[:, leg]):
            frames = np.arange(a, b)
            if prev and nxt:
                tau = (frames - a + 1) / (b - a + 1)
            elif prev or nxt:  # to or from the held pose, which is then reached or left in ``span`` frames
                tau = np.minimum((frames - a + 1) / (span + 1), 1.0) if prev else np.maximum(
                    1.0 - (b - frames) / (span + 1), 0.0)
            else:
                tau = np.zeros(len(frames))
            start = feet.toe[a - 1, leg] if prev else held[frames, leg]
            end = feet.toe[b, leg] if nxt else held[frames, leg]
            along = _smootherstep(tau / 0.88)[:, None]
            toe = start + (end - start) * along
            mid = (a + b) // 2
            lift = ch["clearance"][mid] * _swing_arc(tau, ch["swing_peak"][mid])
            if prev and nxt:
                lift += pelvis_z[frames] - (pelvis_z[a - 1] * (1 - tau) + pelvis_z[b] * tau)
            rise = _smoothstep((tau - 0.3) / 0.7)  # towards the landing pose late in the swing
            toe[:, 2] = start[..., 2] + (end[..., 2] - start[..., 2]) * rise + lift
            feet.toe[a:b, leg] = toe
            p0 = feet.pitch[a - 1, leg] if prev else held_pitch[frames]
            p1 = feet.pitch[b, leg] if nxt else held_pitch[frames]
            feet.pitch[a:b, leg] = np.where(tau < 0.5, p0 * (1 - _smoothstep(2 * tau)), p1 * _smoothstep(2 * tau - 1))
            y0 = feet.yaw[a - 1, leg] if prev else heading[frames]
            y1 = feet.yaw[b, leg] if nxt else heading[frames]
            feet.yaw[a:b, leg] = y0 + np.angle(np.exp(1j * (y1 - y0))) * along[:, 0]


def _ankle_targets(feet: _Feet, leg: int, body: Body) -> tuple[np.ndarray, np.ndarray]:
    """(T, 3) ankle targets and (T, 3, 3) foot rotations that put the toe joint on its target."""
    foot_rot = rot_z(feet.yaw[:, leg]) @ rot_x(feet.pitch[:, leg])
    return feet.toe[:, leg] - foot_rot @ body.ankle_to_toe, foot_rot


def _smooth_cover(need: np.ndarray, radius: int = 3, sigma: float = 1.5) -> np.ndarray:
    """A smooth curve >= ``need``: dilate by ``radius`` frames, Gaussian-smooth, then clip from below."""
    padded = np.pad(need, radius, mode="edge")
    dilated = np.lib.stride_tricks.sliding_window_view(padded, 2 * radius + 1).max(axis=-1)
    x = np.arange(-3 * round(sigma), 3 * round(sigma) + 1)
    kernel = np.exp(-0.5 * (x / sigma) ** 2)
    smooth = np.convolve(np.pad(dilated, len(x) // 2, mode="edge"), kernel / kernel.sum(), mode="valid")
    return np.maximum(smooth, need)


def _reach_drop(pelvis: np.ndarray, pelvis_rot: np.ndarray, feet: _Feet, body: Body) -> np.ndarray:
    """(T,) metres to lower the pelvis so every grounded foot is within ``_REACH`` of its leg length."""
    reach = _REACH * (body.thigh + body.shank)
    need = np.zeros(len(pelvis))
    for leg in range(2):
        hip = _hip(pelvis, pelvis_rot, body, leg)
        ankle, _ = _ankle_targets(feet, leg, body)
        horizontal = np.linalg.norm((hip - ankle)[:, :2], axis=-1)
        allowed = np.sqrt(np.maximum(reach**2 - horizontal**2, 0.0))
        drop = np.where(feet.grounded[:, leg], hip[:, 2] - ankle[:, 2] - allowed, 0.0)
        need = np.maximum(need, drop)
    return _smooth_cover(np.clip(need, 0.0, 0.3))


# --- pose -------------------------------------------------------------------------------------------------


def _local_rotations(
    body: Body, pelvis: np.ndarray, pelvis_rot: np.ndarray, ch: dict, feet: _Feet
) -> np.ndarray:
    """(T, 22, 3, 3) local joint rotations: upper body from the channels, legs by IK to the foot targets."""
    total = len(pelvis)
    local = np.tile(np.eye(3), (total, 22, 1, 1))
    local[:, 0] = pelvis_rot
    for joint, share in ((3, 0.3), (6, 0.35), (9, 0.35)):
        local[:, joint] = yaw_roll_pitch(share * ch["trunk_yaw"], share * ch["trunk_roll"], share * ch["trunk_pitch"])
    thorax_yaw = ch["pelvis_yaw"] + ch["trunk_yaw"]
    thorax_roll = ch["pelvis_roll"] + ch["trunk_roll"]
    thorax_pitch = ch["pelvis_pitch"] + ch["trunk_pitch"]
    for joint in (12, 15):  # neck and head share the work of keeping the gaze level and ahead
        local[:, joint] = yaw_roll_pitch(-0.5 * thorax_yaw, -0.5 * thorax_roll, -0.4 * thorax_pitch)
    local[:, 16] = rot_y(ch["arm_abd"]) @ rot_x(ch["shoulder_l"])
    local[:, 17] = rot_y(-ch["arm_abd"]) @ rot_x(ch["shoulder_r"])
    local[:, 18] = rot_x(ch["elbow_l"])
    local[:, 19] = rot_x(ch["elbow_r"])
    pelvis_fwd = pelvis_rot[:, :, 1] * np.array([1.0, 1.0, 0.0])
    for leg, (hip_j, knee_j, ankle_j, toe_j) in enumerate(((1, 4, 7, 10), (2, 5, 8, 11))):
        ankle, foot_rot = _ankle_targets(feet, leg, body)
        hip = _hip(pelvis, pelvis_rot, body, leg)
        pole = rot_z(feet.yaw[:, leg])[:, :, 1] + pelvis_fwd  # knee over the toes
        thigh, shank, hinge = two_bone_ik(hip, ankle, pole, body.thigh, body.shank)
        local[:, hip_j], local[:, knee_j], local[:, ankle_j] = leg_rotations(pelvis_rot, thigh, shank, hinge, foot_rot)
        local[:, toe_j] = rot_x(0.8 * np.clip(-feet.pitch[:, leg], 0.0, 0.6))  # toes stay flat as the heel rises
    return local


# --- one sequence -----------------------------------------------------------------------------------------


def _schedule(cfg: LocomotionConfig, rng: np.random.Generator, body: Body, counts: dict[str, float],
              total: int, pad: int) -> tuple[list[_Block], dict[str, np.ndarray], np.ndarray]:
    """Steps 1-2: skill blocks, blended (T,) channels and (T, 2) foot contacts on the padded timeline."""
    t = np.arange(total) / FPS
    blocks = _plan_blocks(cfg, rng, body, counts, total)
    weights = _weights([(b.start, a.end) for a, b in zip(blocks[:-1], blocks[1:])], total)
    phase = rng.uniform() + np.cumsum(_cycle_rate(blocks, weights)) / FPS
    for b in blocks:
        if b.skill == "jump_forward":  # jump phase 0 (start of the standing lead-in) at the blend centre
            b.phase_offset = -phase[b.start + b.blend_in // 2] if b.blend_in else 0.9 - phase[pad]
    evaluated = _evaluate_blocks(blocks, phase, t, body)
    contact, switches = _compose_contacts(blocks, [c for _, c in evaluated])
    motion_ramps = _motion_ramps(blocks, switches, total)
    for a, b, (start, end) in zip(blocks[:-1], blocks[1:], motion_ramps):  # label the whole speed change
        a.end, b.start = max(a.end, end), min(b.start, start)
    ch = _blend_channels(evaluated, weights, _weights(motion_ramps, total))
    lean = -0.6 * np.arctan(ch["v_fwd"] * ch["yaw_rate"] / G)  # lean into turns
    ch["pelvis_roll"] += 0.5 * lean
    ch["trunk_roll"] += 0.5 * lean
    return blocks, ch, contact


def _trajectories(cfg: LocomotionConfig, rng: np.random.Generator, body: Body, ch: dict,
                  contact: np.ndarray) -> tuple[np.ndarray, np.ndarray, _Feet]:
    """Steps 3-4: (T, 3) pelvis position and (T, 3, 3) orientation, world, and the foot targets."""
    heading = rng.uniform(0, 2 * math.pi) + np.cumsum(ch["yaw_rate"]) / FPS
    c, s = np.cos(heading), np.sin(heading)
    vel = np.stack((c * ch["v_side"] - s * ch["v_fwd"], s * ch["v_side"] + c * ch["v_fwd"]), axis=-1)
    root_xy = rng.uniform(-cfg.start_half_size, cfg.start_half_size, 2) + np.cumsum(vel, axis=0) / FPS
    offset = np.stack((c * ch["sway"] - s * ch["surge"], s * ch["sway"] + c * ch["surge"]), axis=-1)
    pelvis = np.concatenate((root_xy + offset, (body.pelvis_height + ch["dz"])[:, None]), axis=-1)
    pelvis_rot = yaw_roll_pitch(heading + ch["pelvis_yaw"], ch["pelvis_roll"], ch["pelvis_pitch"])
    feet = _plant_feet(contact, root_xy, heading, ch, body)
    pelvis[:, 2] -= _reach_drop(pelvis, pelvis_rot, feet, body)
    held, held_pitch = _held_feet(pelvis, pelvis_rot, heading, ch, body)
    _swing_feet(feet, held, held_pitch, heading, pelvis[:, 2], ch)
    return pelvis, pelvis_rot, feet


def _simulate(cfg: LocomotionConfig, index: int, counts: dict[str, float]) -> dict[str, np.ndarray]:
    """One sequence in the motion-text format (fields of ``motion_text.FIELDS``)."""
    rng = np.random.default_rng([cfg.seed, index])
    body = make_body(rng.uniform(*cfg.height_range))
    pad, frames = round(_PAD_S * FPS), round(cfg.seconds_per_sequence * FPS)
    blocks, ch, contact = _schedule(cfg, rng, body, counts, frames + 2 * pad, pad)
    pelvis, pelvis_rot, feet = _trajectories(cfg, rng, body, ch, contact)
    keep = slice(pad, pad + frames)  # step 5 on the visible frames only
    local = _local_rotations(body, pelvis[keep], pelvis_rot[keep], {k: v[keep] for k, v in ch.items()},
                             _Feet(feet.toe[keep], feet.yaw[keep], feet.pitch[keep], feet.grounded[keep]))
    poses = matrix_to_axis_angle_np(local).astype(np.float32)
    rest = body.rest_joints.astype(np.float32)
    transl = (pelvis[keep] - body.rest_joints[0]).astype(np.float32)
    # joints from the stored (float32) values, so they match a reader's forward kinematics exactly
    joints = forward_kinematics_np(rest.astype(np.float64), axis_angle_to_matrix_np(poses.astype(np.float64)),
                                   transl.astype(np.float64))
    segments = [(max(b.start, pad) - pad, min(b.end, pad + frames) - pad, b.text) for b in blocks
                if min(b.end, pad + frames) > max(b.start, pad)]
    return {
        "fps": np.array(FPS, dtype=np.float32),
        "transl": transl,
        "pelvis_delta": rest[0].copy(),
        "rest_joints": rest,
        "poses": poses,
        "joints": joints.astype(np.float32),
        "seg_start": np.array([s[0] for s in segments], dtype=np.int32),
        "seg_end": np.array([s[1] for s in segments], dtype=np.int32),
        "seg_text": np.array([s[2] for s in segments], dtype=str),
    }


# --- public API -------------------------------------------------------------------------------------------


def generate_sequences(cfg: LocomotionConfig) -> list[dict[str, np.ndarray]]:
    """Generate every sequence in memory: a list of dicts with the motion-text fields (float32/int32/str)."""
    cfg.validate()
    counts = {s: 0.0 for s in cfg.skills}
    return [_simulate(cfg, i, counts) for i in range(cfg.num_sequences)]


def generate_dataset(cfg: LocomotionConfig, out_dir: str | Path, overwrite: bool = False) -> list[Path]:
    """Write ``seq_00000.npz``... and ``meta.json`` into ``out_dir``; returns the sequence paths.

    Refuses a folder that already holds ``.npz`` files unless ``overwrite`` (which first deletes them and
    ``meta.json``), so stale sequences of an earlier, larger run never mix into the dataset.
    """
    from latentrl.errors import DataError

    out_dir = Path(out_dir)
    old = sorted(out_dir.glob("*.npz")) if out_dir.is_dir() else []
    if old and not overwrite:
        raise DataError(f"{out_dir}: already holds {len(old)} .npz files, expected an empty folder "
                        "(or pass overwrite=True)")
    for path in old + [out_dir / "meta.json"]:
        path.unlink(missing_ok=True)
    started = time.perf_counter()
    seqs = generate_sequences(cfg)
    seconds = time.perf_counter() - started
    paths = [write_sequence(out_dir / f"seq_{i:05d}.npz", seq, check_fk=False) for i, seq in enumerate(seqs)]
    stats = dataset_statistics(seqs)
    write_meta(out_dir, {
        "name": cfg.name,
        "generator": "latentrl.datasets.locomotion",
        "licence": "MIT (procedurally generated by latentrl; contains no recorded motion)",
        "seed": cfg.seed,
        "fps": FPS,
        "config": asdict(cfg),
        "num_sequences": len(paths),
        "frames": stats["frames"],
        "transition_frames": stats["transition_frames"],
        "frames_per_skill": {k: v["frames"] for k, v in stats["skills"].items()},
        "frames_per_text": stats["texts"],
        "generation_seconds": round(seconds, 2),
    })
    return paths


def foot_skate(joints: np.ndarray, horizontal: bool = False) -> np.ndarray:
    """(T-1,) contact-weighted foot displacement per frame pair (m), DART's ``calc_skate`` before averaging.

    ``joints`` (T, 22, 3) world, z up. Each foot joint (10, 11) moves ``|d|`` between frames and is weighted by
    ``2 - 2**clamp(max(h_t, h_t-1) / 0.03, 0, 1)`` (h = its height above the floor); the two feet are averaged.
    ``horizontal`` measures only the xy displacement (sliding), leaving out lift-off and touch-down.
    """
    feet = joints[:, list(FOOT_JOINTS)]
    delta = np.diff(feet[..., :2] if horizontal else feet, axis=0)
    height = np.maximum(feet[1:, :, 2], feet[:-1, :, 2])
    weight = 2.0 - 2.0 ** np.clip(height / 0.03, 0.0, 1.0)
    return (np.linalg.norm(delta, axis=-1) * weight).mean(axis=-1)


_STAT_KEYS = ("frames", "pure", "pairs", "speed", "skate", "skate_xy", "floor")


def dataset_statistics(seqs: Sequence[dict[str, np.ndarray]]) -> dict:
    """Frames per skill and text, the transition share, and per-skill speed, skate and floor metrics.

    Speeds and metrics use frames labelled with a single skill (not transitions): ``speed_m_s`` is the mean
    horizontal pelvis speed, ``skate_cm_s`` DART's contact-weighted skate (x fps, in cm/s), ``skate_xy_cm_s``
    the same on horizontal displacement only, and ``floor_cm`` the mean |lowest foot joint height| (DART's
    floor distance, in cm).
    """
    acc: dict[str, dict[str, float]] = {}
    texts: dict[str, int] = {}
    total = transitions = 0
    for seq in seqs:
        num = len(seq["transl"])
        labels = np.zeros(num, dtype=int)
        owner = np.full(num, "", dtype=object)
        for a, b, text in zip(seq["seg_start"], seq["seg_end"], seq["seg_text"]):
            skill = TEXT_TO_SKILL.get(str(text), str(text))
            labels[a:b] += 1
            owner[a:b] = skill
            texts[str(text)] = texts.get(str(text), 0) + int(b - a)
            acc.setdefault(skill, dict.fromkeys(_STAT_KEYS, 0.0))
            acc[skill]["frames"] += int(b - a)
        total += num
        transitions += int(np.sum(labels > 1))
        joints = seq["joints"].astype(np.float64)
        pure = labels == 1
        pair = pure[1:] & pure[:-1] & (owner[1:] == owner[:-1])
        speed = np.linalg.norm(np.diff(joints[:, 0, :2], axis=0), axis=-1) * FPS
        skate, skate_xy = foot_skate(joints), foot_skate(joints, horizontal=True)
        floor = np.abs(joints[:, list(FOOT_JOINTS), 2].min(axis=-1))
        for skill in set(owner[pure]):
            m, mp = pure & (owner == skill), pair & (owner[1:] == skill)
            a = acc[skill]
            a["pure"] += int(m.sum())
            a["floor"] += float(floor[m].sum())
            a["pairs"] += int(mp.sum())
            a["speed"] += float(speed[mp].sum())
            a["skate"] += float(skate[mp].sum())
            a["skate_xy"] += float(skate_xy[mp].sum())
    skills = {}
    for skill, a in sorted(acc.items(), key=lambda kv: SKILLS.index(kv[0]) if kv[0] in SKILLS else 99):
        pairs, pure = max(a["pairs"], 1), max(a["pure"], 1)
        skills[skill] = {
            "frames": int(a["frames"]),
            "single_label_frames": int(a["pure"]),
            "speed_m_s": round(a["speed"] / pairs, 3),
            "skate_cm_s": round(100 * FPS * a["skate"] / pairs, 3),
            "skate_xy_cm_s": round(100 * FPS * a["skate_xy"] / pairs, 3),
            "floor_cm": round(100 * a["floor"] / pure, 3),
        }
    return {"frames": total, "transition_frames": transitions,
            "transition_fraction": round(transitions / max(total, 1), 3), "skills": skills, "texts": texts}
