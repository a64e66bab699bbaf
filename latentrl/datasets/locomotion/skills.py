"""Per-skill gait channels: parameters drawn per block and the channels as functions of the gait phase."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from latentrl.datasets.body import (
    Body,
)
from latentrl.datasets.locomotion.config import G

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


def _drift_params(rng: np.random.Generator, amplitude: float, strength: tuple[float, float] = (0.3, 1.0),
                  hz: tuple[float, float] = (0.08, 0.3)) -> tuple[float, ...]:
    """Two random sinusoids for the yaw rate: each ``amplitude * U(strength)`` rad/s at ``U(hz)`` Hz.

    The defaults are a slow drift that makes straight skills wander in heading.
    """
    a = amplitude * rng.uniform(*strength, 2)
    f = rng.uniform(*hz, 2)
    p = rng.uniform(0.0, 2 * math.pi, 2)
    return (a[0], f[0], p[0], a[1], f[1], p[1])


class _Steering:
    """A yaw rate that holds a random value and switches to a new one at random times (rad/s of ``t``).

    Why: a policy steers walk, run and hop only through the diffusion noise, and the noise can only
    pick among futures the data holds for the same 2-frame history. Smooth sinusoidal wander (the
    previous design) is predictable from the history, and the trained model ignored the noise for
    heading (5-95 % yaw spread over 32 frames: walk 14 deg, run 11, hop 1). Here the yaw rate holds
    each value for 0.25-0.9 s and then eases to a new uniform draw in +-``amplitude`` within
    ``ramp_s``, so whether the next primitive turns left, right or not at all is not in its history;
    a quarter of the holds are straight (zero), so straight lines stay common.
    """

    def __init__(self, rng: np.random.Generator, amplitude: float, hold_s: tuple[float, float] = (0.25, 0.9),
                 ramp_s: float = 0.2, horizon_s: float = 60.0):
        holds = rng.uniform(*hold_s, int(horizon_s / hold_s[0]) + 2)
        self.knots = np.concatenate(([-1e9], np.cumsum(holds) - holds[0]))
        values = amplitude * rng.uniform(-1.0, 1.0, len(self.knots))
        values[rng.random(len(values)) < 0.25] = 0.0
        self.values = values
        self.ramp_s = ramp_s

    def __call__(self, t: np.ndarray) -> np.ndarray:
        i = np.clip(np.searchsorted(self.knots, t, side="right") - 1, 0, len(self.knots) - 1)
        prev = self.values[np.maximum(i - 1, 0)]
        ease = _smoothstep((t - self.knots[i]) / self.ramp_s)
        return prev + (self.values[i] - prev) * ease


def _wander_params(rng: np.random.Generator, amplitude: float) -> tuple[float, ...]:
    """Heading wander (``steering: wander``): two random sinusoids of 0.25-0.8 Hz, each up to ``amplitude``.

    The first shipped default model's data. Predictable from a 2-frame history, which is why the
    trained model hardly let its noise steer (see :class:`_Steering`).
    """
    return _drift_params(rng, amplitude, strength=(0.0, 1.0), hz=(0.25, 0.8))


def _drift(t: np.ndarray, d) -> np.ndarray:
    if isinstance(d, _Steering):
        return d(t)
    return d[0] * np.sin(2 * math.pi * d[1] * t + d[2]) + d[3] * np.sin(2 * math.pi * d[4] * t + d[5])


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) index ranges where ``mask`` is True."""
    padded = np.concatenate(([False], mask, [False])).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return list(zip(edges[0::2].tolist(), edges[1::2].tolist()))


#: Largest yaw rate (deg/s) of the random steering in walk, run and hop blocks.
WALK_STEER_DEG_S, RUN_STEER_DEG_S, HOP_STEER_DEG_S = 80.0, 60.0, 55.0

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
    "stair": 0.0,  # +1 climbing, -1 descending stairs: the swing rises early / descends late
    "reach_l": 0.0,  # weight of the left hand's target (0: the arm follows the channels above)
    "reach_r": 0.0,
    "reach_lx": 0.0,  # left hand target from the left shoulder, heading frame (x right, y forward, z up; m)
    "reach_ly": 0.0,
    "reach_lz": 0.0,
    "reach_rx": 0.0,
    "reach_ry": 0.0,
    "reach_rz": 0.0,
}


def _neutral(n: int, body: Body) -> dict[str, np.ndarray]:
    ch = {k: np.full(n, v) for k, v in _CHANNEL_DEFAULTS.items()}
    ch["stance_width"][:] = 0.06 * body.height
    return ch


def _cadence_scale(body: Body) -> float:
    """Froude scaling of step frequency with leg length, relative to a 1.75 m body."""
    return math.sqrt(0.5 * 1.75 / body.rest_joints[1, 2])


def _heading_change(rng: np.random.Generator, steering: str, max_deg_s: float, wander_deg_s: float):
    """Yaw-rate process of a straight skill: ``random_hold`` (:class:`_Steering`) or the sinusoid ``wander``."""
    if steering == "random_hold":
        return _Steering(rng, math.radians(max_deg_s))
    return _wander_params(rng, math.radians(wander_deg_s))


def _sample_params(skill: str, rng: np.random.Generator, body: Body, steering: str = "wander",
                   flights: str = "high", prev: tuple[str, dict] | None = None) -> dict:
    """Per-block skill parameters (SI units); ``f`` is the gait-cycle frequency in cycles/s.

    ``steering`` and ``flights`` are ``LocomotionConfig``'s (see there); the defaults reproduce the
    data of the first shipped default model. ``prev`` is the previous block's skill and parameters
    (a getting-up starts from the posture before it).
    """
    if skill in _POSTURE_SKILLS or skill == "crouch_walk":
        return _posture_params(skill, rng, body, prev)
    if skill in STAIR_SKILLS:
        return _stair_params(skill, rng, body)
    if skill in _GESTURE_SKILLS:
        return _gesture_params(skill, rng, body)
    low = flights == "low"
    scale = _cadence_scale(body)
    if skill in ("walk", "turn_left", "turn_right"):
        turn = {"walk": 0.0, "turn_left": 1.0, "turn_right": -1.0}[skill]
        v = rng.uniform(0.8, 1.6) if turn == 0 else rng.uniform(0.8, 1.2)
        k = (v - 0.8) / 0.8
        steps = np.clip((1.7 + 0.4 * k) * scale + rng.normal(0, 0.03), 1.7, 2.1)
        yaw = turn * math.radians(rng.uniform(30, 90))
        drift = (_heading_change(rng, steering, WALK_STEER_DEG_S, 25) if turn == 0
                 else _drift_params(rng, math.radians(3)))
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
        duty = 0.45 - 0.05 * k if low else 0.36 - 0.06 * k
        return dict(v_fwd=v, k=k, f=steps / 2, duty=duty, drift=_heading_change(rng, steering, RUN_STEER_DEG_S, 20),
                    shift=-0.08 * body.height)
    if skill in ("hop_left", "hop_right"):
        f = rng.uniform(1.8, 2.2)
        t_flight_max = 0.55 / f
        apex = rng.uniform(*((0.03, min(0.07, G * t_flight_max**2 / 8)) if low
                             else (0.05, min(0.15, G * t_flight_max**2 / 8))))
        t_flight = math.sqrt(8 * apex / G)
        return dict(v_fwd=rng.uniform(0.0, 1.0), f=f, apex=apex, duty=1.0 - t_flight * f,
                    drift=_heading_change(rng, steering, HOP_STEER_DEG_S, 18),
                    clearance=(0.005 + 0.3 * apex) if low else (0.03 + 1.2 * apex),
                    heel_rise=math.radians(15 if low else 28), toe_land=math.radians(6 if low else 14))
    if skill == "jump_forward":
        apex = rng.uniform(*((0.05, 0.10) if low else (0.2, 0.35)))
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
    ch["clearance"][:] = p["clearance"]
    ch["heel_rise"][:] = p["heel_rise"]
    ch["toe_land"][:] = p["toe_land"]
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


# --- postures: crouching, sitting on a seat, getting up -------------------------------------------------

#: Pelvis joint height above the seat surface while seated (m): the seat height is this much below it.
SEATED_PELVIS_ABOVE_SEAT_M = 0.09
#: Range of the seat heights (m) of ``sit_down``.
SEAT_HEIGHT_RANGE = (0.2, 0.6)
#: Range of the crouch depth (m): how far ``crouch`` lowers the pelvis below its standing height.
CROUCH_DROP_RANGE = (0.28, 0.40)
#: Skills whose channels are keyframed from the block's own start (``params["t0"]``): both feet stay down.
_POSTURE_SKILLS = ("crouch", "sit_down", "stand_up")
#: Channels a posture sets; the rest keep their standing values.
_POSE_KEYS = ("dz", "surge", "pelvis_pitch", "trunk_pitch", "shoulder_l", "shoulder_r", "elbow_l", "elbow_r",
              "arm_abd")
_ARM_KEYS = ("shoulder_l", "shoulder_r", "elbow_l", "elbow_r", "arm_abd")


def _standing_pose() -> dict[str, float]:
    return {k: _CHANNEL_DEFAULTS[k] for k in _POSE_KEYS}


def _crouch_pose(rng: np.random.Generator, drop_range: tuple[float, float] = CROUCH_DROP_RANGE) -> dict[str, float]:
    """A held crouch: pelvis ``drop_range`` lower and back, pelvis tipped and trunk leaning forward, arms in front."""
    deg = math.radians
    shoulder, elbow = deg(rng.uniform(15, 35)), deg(rng.uniform(30, 60))
    return dict(dz=-rng.uniform(*drop_range), surge=-rng.uniform(0.04, 0.10), pelvis_pitch=-deg(rng.uniform(20, 35)),
                trunk_pitch=-deg(rng.uniform(5, 15)), shoulder_l=shoulder, shoulder_r=shoulder, elbow_l=elbow,
                elbow_r=elbow, arm_abd=deg(rng.uniform(6, 12)))


def _seated_pose(rng: np.random.Generator, body: Body, seat: float) -> dict[str, float]:
    """Seated on a seat ``seat`` m high: pelvis joint ``SEATED_PELVIS_ABOVE_SEAT_M`` above it, back over the seat.

    The pelvis moves back from the planted feet by most of a thigh length, less where a high seat would
    otherwise stretch the leg beyond 93 % of its length (the feet must stay planted).
    """
    deg = math.radians
    pelvis_z = seat + SEATED_PELVIS_ABOVE_SEAT_M
    hip_z = pelvis_z + body.hip_offsets[0, 2]
    ankle_z = body.rest_joints[7, 2]
    lateral = abs(body.hip_offsets[0, 0])
    vertical = hip_z - ankle_z
    room = (0.93 * (body.thigh + body.shank)) ** 2 - vertical**2 - lateral**2
    back = min(rng.uniform(0.75, 0.95) * body.thigh, math.sqrt(max(room, 0.0)))
    shoulder, elbow = deg(rng.uniform(15, 30)), deg(rng.uniform(50, 80))
    return dict(dz=pelvis_z - body.pelvis_height, surge=-back, pelvis_pitch=deg(rng.uniform(-5, 5)),
                trunk_pitch=-deg(rng.uniform(0, 10)), shoulder_l=shoulder, shoulder_r=shoulder, elbow_l=elbow,
                elbow_r=elbow, arm_abd=deg(rng.uniform(6, 10)))


def _sway_params(rng: np.random.Generator, amplitude: tuple[float, float]) -> dict:
    return dict(sway=rng.uniform(*amplitude), sway_f=rng.uniform(0.2, 0.3), sway_ph=rng.uniform(0, 2 * math.pi, 2),
                breath_f=rng.uniform(0.2, 0.3))


def _posture_params(skill: str, rng: np.random.Generator, body: Body, prev: tuple[str, dict] | None) -> dict:
    """Parameters of crouch, crouch walk, sit down and stand up.

    A posture goes from ``from`` to ``to`` (channel values, ``_POSE_KEYS``) over ``duration`` seconds from
    ``t0`` (set by the planner: the end of the cross-fade into the block, so the movement carries this
    block's text alone), with a forward ``lean`` that peaks midway; ``lag`` delays the pelvis against the
    lean (getting up leans first, then rises). ``hold`` is the shortest time the block keeps its end pose.
    """
    deg = math.radians
    prev_skill, prev_params = prev if prev is not None else ("", {})
    if skill == "crouch_walk":
        v = rng.uniform(0.4, 0.8)
        steps = rng.uniform(1.4, 1.8) * _cadence_scale(body)
        return dict(v_fwd=v, v_side=0.0, k=0.0, f=steps / 2, yaw_rate=0.0, rocker=0.05, toe_off=0.64,
                    drift=_drift_params(rng, deg(10)), width=0.05 * body.height, shift=-0.04 * body.height,
                    drop=rng.uniform(0.27, 0.36), back=rng.uniform(0.03, 0.08), lean=deg(rng.uniform(10, 20)))
    p = dict(f=0.0, width=rng.uniform(0.05, 0.065) * body.height, **_sway_params(rng, (0.002, 0.006)))
    if skill == "crouch":
        low = prev_skill == "crouch_walk"  # already low: the cross-fade alone changes the depth
        p.update(to=_crouch_pose(rng), duration=rng.uniform(0.6, 1.0), lag=0.0, lean=-deg(rng.uniform(5, 15)),
                 hold=0.8, width=rng.uniform(0.06, 0.08) * body.height)
        p["from"] = dict(p["to"]) if low else _standing_pose()
    elif skill == "sit_down":
        seat = rng.uniform(*SEAT_HEIGHT_RANGE)
        p.update(seat=seat, to=_seated_pose(rng, body, seat), duration=rng.uniform(0.9, 1.4), lag=0.0,
                 lean=-deg(rng.uniform(25, 40)), hold=0.8)
        p["from"] = _standing_pose()
    elif skill == "stand_up":
        seated = prev_skill == "sit_down"
        start = dict(prev_params["to"]) if prev_skill in ("crouch", "sit_down") else _crouch_pose(rng)
        p.update(duration=rng.uniform(0.9, 1.4) if seated else rng.uniform(0.6, 1.0), lag=0.25,
                 lean=-deg(rng.uniform(25, 40) if seated else rng.uniform(10, 20)), hold=0.3, to=_standing_pose())
        p["from"] = start
    else:
        raise ValueError(skill)
    return p


def _posture(phase: np.ndarray, t: np.ndarray, p: dict, body: Body) -> tuple[dict, np.ndarray]:
    """A posture change on planted feet (crouch, sit down, stand up), then its end pose with a little sway."""
    ch = _neutral(len(t), body)
    tau = (t - p["t0"]) / p["duration"]
    body_s = _smootherstep((tau - p["lag"]) / (1.0 - p["lag"]))
    arms_s = _smootherstep(tau)
    for k in _POSE_KEYS:
        s = arms_s if k in _ARM_KEYS else body_s
        ch[k] = p["from"][k] + (p["to"][k] - p["from"][k]) * s
    bump = np.sin(math.pi * np.clip(tau, 0.0, 1.0)) ** 2  # zero slope at both ends
    ch["pelvis_pitch"] = ch["pelvis_pitch"] + 0.5 * p["lean"] * bump
    ch["trunk_pitch"] = ch["trunk_pitch"] + 0.5 * p["lean"] * bump
    w = 2 * math.pi * p["sway_f"]
    ch["sway"] = p["sway"] * np.sin(w * t + p["sway_ph"][0])
    ch["trunk_pitch"] = ch["trunk_pitch"] + math.radians(1.0) * np.sin(2 * math.pi * p["breath_f"] * t)
    ch["stance_width"][:] = p["width"]
    on = np.ones(len(t), dtype=bool)
    return ch, np.stack((on, on), axis=-1)


def _crouch_walk(phase: np.ndarray, t: np.ndarray, p: dict, body: Body) -> tuple[dict, np.ndarray]:
    """Walking with the pelvis ``drop`` lower: shorter, flatter steps, trunk forward, arms held in front."""
    ch, contact = _walk_like(phase, t, p, body)
    ch["dz"] = ch["dz"] - p["drop"]
    ch["surge"][:] = -p["back"]
    ch["pelvis_pitch"] = ch["pelvis_pitch"] - 0.6 * p["lean"]
    ch["trunk_pitch"] = ch["trunk_pitch"] - 0.4 * p["lean"]
    ch["shoulder_l"] = ch["shoulder_l"] + math.radians(15)
    ch["shoulder_r"] = ch["shoulder_r"] + math.radians(15)
    ch["elbow_l"] = ch["elbow_l"] + math.radians(25)
    ch["elbow_r"] = ch["elbow_r"] + math.radians(25)
    ch["clearance"][:] = 0.04
    ch["heel_rise"] = 0.5 * ch["heel_rise"]
    ch["heel_strike"] = 0.5 * ch["heel_strike"]
    return ch, contact


# --- stairs -----------------------------------------------------------------------------------------------

#: Range of the stair risers (m) and treads (m) of ``stairs_up`` and ``stairs_down``.
RISER_RANGE = (0.10, 0.20)
TREAD_RANGE = (0.28, 0.34)
#: Skills that walk a flight of stairs (straight, one tread per step; geometry in ``feet._stairs``).
STAIR_SKILLS = ("stairs_up", "stairs_down")


def _stair_params(skill: str, rng: np.random.Generator, body: Body) -> dict:
    """A flight walked straight at one tread per step: the speed is the tread depth times the step rate."""
    tread, riser = rng.uniform(*TREAD_RANGE), rng.uniform(*RISER_RANGE)
    steps = rng.uniform(1.3, 1.7) * _cadence_scale(body)
    up = skill == "stairs_up"
    return dict(v_fwd=tread * steps, v_side=0.0, k=0.0, f=steps / 2, yaw_rate=0.0, rocker=0.0, toe_off=0.62,
                drift=(0.0, 0.0, 0.0, 0.0, 0.0, 0.0), width=0.045 * body.height, shift=-0.04 * body.height,
                tread=tread, riser=riser if up else -riser)


def _stairs_walk(phase: np.ndarray, t: np.ndarray, p: dict, body: Body) -> tuple[dict, np.ndarray]:
    """Walking a flight: flat-footed landings (no heel strike), the trunk forward going up, upright going down."""
    ch, contact = _walk_like(phase, t, p, body)
    up = p["riser"] > 0
    ch["heel_strike"][:] = 0.0
    ch["rocker_s"][:] = 0.0
    ch["toe_land"][:] = 0.0
    ch["heel_rise"][:] = math.radians(15 if up else 8)
    ch["clearance"][:] = 0.05
    ch["swing_peak"][:] = 0.45  # the toe stays up until it is over its tread
    ch["trunk_pitch"][:] = -math.radians(8 if up else 3)
    ch["stair"][:] = 1.0 if up else -1.0
    return ch, contact


# --- hands: reach, wave, pick up ---------------------------------------------------------------------------

#: Skills that move a hand to a target (``feet._arm_ik`` places it); both feet stay planted.
_GESTURE_SKILLS = ("reach_left", "reach_right", "wave", "pick_up")
#: Skills keyframed from their block's ``t0`` (the end of the cross-fade into them).
_KEYFRAMED = _POSTURE_SKILLS + _GESTURE_SKILLS
#: Reach targets lie this fraction of the arm's length (shoulder to wrist) from the shoulder, at most.
REACH_RANGE = (0.6, 0.95)
#: Reach directions: forward, up, down and to the side (of the reaching hand).
REACH_DIRECTIONS = ("forward", "up", "down", "side")


def arm_length(body: Body) -> float:
    """Shoulder to wrist with the arm straight (m)."""
    r = body.rest_joints
    return float(np.linalg.norm(r[18] - r[16]) + np.linalg.norm(r[20] - r[18]))


def _gesture_params(skill: str, rng: np.random.Generator, body: Body) -> dict:
    """A hand gesture from standing: lean (for low targets), move the hand in, hold, return.

    ``offset`` is the hand target from its shoulder in the heading frame (m); ``duration`` covers the
    move in (``move``), the hold (``hold_s``) and the move back; the body's ``to`` pose is held meanwhile.
    """
    deg = math.radians
    arm = arm_length(body)
    hand = {"reach_left": 0, "reach_right": 1, "pick_up": int(rng.random() < 0.7),
            "wave": int(rng.random() < 0.75)}[skill]
    out = 1.0 if hand else -1.0  # the hand's side: body right is +x
    pose = _standing_pose()
    direction = ""
    if skill in ("reach_left", "reach_right"):
        direction = REACH_DIRECTIONS[int(rng.integers(len(REACH_DIRECTIONS)))]
        dist = rng.uniform(*REACH_RANGE) * arm
        azimuth = {"forward": rng.uniform(-10, 25), "up": rng.uniform(-10, 30), "down": rng.uniform(-10, 25),
                   "side": rng.uniform(60, 95)}[direction]  # degrees from forward towards the hand's side
        elevation = {"forward": rng.uniform(-20, 20), "up": rng.uniform(45, 80), "down": rng.uniform(-75, -45),
                     "side": rng.uniform(-20, 30)}[direction]
        a, e = deg(azimuth), deg(elevation)
        offset = dist * np.array([out * math.sin(a) * math.cos(e), math.cos(a) * math.cos(e), math.sin(e)])
        if direction == "down":  # bend to reach low
            pose.update(dz=-rng.uniform(0.05, 0.2), pelvis_pitch=-deg(rng.uniform(15, 30)),
                        trunk_pitch=-deg(rng.uniform(10, 25)), surge=-0.04)
        move, hold = rng.uniform(0.6, 1.0), rng.uniform(0.4, 0.9)
    elif skill == "pick_up":
        offset = np.array([out * rng.uniform(0.0, 0.1), rng.uniform(0.05, 0.2), -1.0])
        offset *= rng.uniform(0.9, REACH_RANGE[1]) * arm / np.linalg.norm(offset)  # down, as far as it goes
        pose.update(dz=-rng.uniform(0.42, 0.50), surge=-rng.uniform(0.10, 0.16),
                    pelvis_pitch=-deg(rng.uniform(40, 50)), trunk_pitch=-deg(rng.uniform(35, 45)))
        move, hold = rng.uniform(0.9, 1.3), rng.uniform(0.3, 0.6)
    else:  # wave: the hand raised beside the head, swinging side to side
        offset = np.array([out * rng.uniform(0.15, 0.3), rng.uniform(0.05, 0.2), rng.uniform(0.35, 0.45)])
        move, hold = rng.uniform(0.5, 0.8), rng.uniform(1.2, 2.2)
    return dict(f=0.0, width=rng.uniform(0.05, 0.065) * body.height, hand=hand, offset=offset, to=pose,
                direction=direction, move=move, hold_s=hold, duration=2 * move + hold, hold=0.3,
                wave_hz=rng.uniform(1.5, 2.5), wave_amp=rng.uniform(0.08, 0.14) * out * (skill == "wave"),
                **_sway_params(rng, (0.002, 0.006)))


def _gesture(phase: np.ndarray, t: np.ndarray, p: dict, body: Body) -> tuple[dict, np.ndarray]:
    """Standing while one hand goes to ``offset`` from its shoulder (weight ``reach_*``) and back."""
    ch = _neutral(len(t), body)
    tau = t - p["t0"]
    w = _smootherstep(tau / p["move"]) * (1.0 - _smootherstep((tau - p["move"] - p["hold_s"]) / p["move"]))
    stand = _standing_pose()
    for k in _POSE_KEYS:
        if k not in _ARM_KEYS:
            ch[k] = stand[k] + (p["to"][k] - stand[k]) * w
    side = "r" if p["hand"] else "l"
    ch[f"reach_{side}"] = w
    offset = np.broadcast_to(p["offset"], (len(t), 3)).copy()
    if p["wave_amp"]:  # a wave swings the hand sideways
        offset[:, 0] += p["wave_amp"] * np.sin(2 * math.pi * p["wave_hz"] * np.maximum(tau - p["move"], 0.0))
    for i, axis in enumerate("xyz"):
        ch[f"reach_{side}{axis}"] = offset[:, i]
    wsw = 2 * math.pi * p["sway_f"]
    ch["sway"] = p["sway"] * np.sin(wsw * t + p["sway_ph"][0])
    ch["stance_width"][:] = p["width"]
    on = np.ones(len(t), dtype=bool)
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
    "crouch": _posture,
    "crouch_walk": _crouch_walk,
    "sit_down": _posture,
    "stand_up": _posture,
    "stairs_up": _stairs_walk,
    "stairs_down": _stairs_walk,
    "reach_left": _gesture,
    "reach_right": _gesture,
    "wave": _gesture,
    "pick_up": _gesture,
}


def _block_speed(skill: str, p: dict) -> float:
    """Nominal speed (m/s): picks speed-specific texts and tells speed-ups from slow-downs."""
    if skill == "jump_forward":
        return 0.0
    return abs(p.get("v_fwd", 0.0)) + abs(p.get("v_side", 0.0))


