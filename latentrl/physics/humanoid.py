"""The MuJoCo humanoid, generated in code from latentrl's SMPL-22 rest skeleton (no SMPL files).

One MuJoCo body per SMPL joint, placed at latentrl's anthropometric rest joints
(:func:`latentrl.datasets.body.rest_joints`: Drillis & Contini segment lengths as reproduced by Winter), so
that all hinge angles at zero give exactly latentrl's rest pose and a motion's joint rotations (SMPL
convention: each relative to its parent, from that rest pose) become hinge angles directly.

- **Root:** a free joint on the pelvis.
- **Joints:** three hinges per body joint (never ``ball`` joints, which transfer badly between simulators),
  applied in the order :data:`AXIS_ORDER` gives: ``R = R_a(q0) R_b(q1) R_c(q2)``. Legs, spine and head use
  x-y-z (flexion, abduction, twist); the arms, which hang along z, use x-z-y so the middle hinge is the
  bone's twist, far from its +-90 degree singularity in everyday poses.
- **Geometry:** capsules between joint centres, a sphere for the head, boxes for the feet (rear foot and toes)
  whose soles touch z = 0 at rest. Radii are fractions of body height (:data:`RADIUS`), our estimates from
  segment girths; only the floor collides with the body (no self-collision).
- **Masses:** segment mass fractions from de Leva (1996), "Adjustments to Zatsiorsky-Seluyanov's segment
  inertia parameters", J. Biomechanics 29(9):1223-1230, Table 4 (male): head+neck 6.94 %, trunk 43.46 %
  (upper 15.96, middle 16.33, lower 11.17), upper arm 2.71, forearm 1.62, hand 0.61, thigh 14.16,
  shank 4.33, foot 1.37. Where SMPL has more bodies than de Leva has segments we split (:data:`MASS_PERCENT`):
  the middle trunk evenly over spine1/spine2, 1 % of the upper trunk to each collar, 1 % of head+neck to the
  neck, the foot 80/20 between rear foot and toes. Each geom carries its segment's mass; MuJoCo derives
  the inertia from the shape. Total mass defaults to a body-mass index of 22.9 kg/m2 (70.1 kg at 1.75 m).
- **Actuators:** PD position servos ``tau = kp (target - q) - kv dq`` per hinge, gains (:data:`GAINS`)
  in the range PHC uses for its SMPL humanoid (legs 800/80, torso 1000/100, shoulders and elbows 500/50,
  wrists 300/30, N m/rad and N m s/rad at 70 kg), scaled by mass / 70 kg; torques clipped to
  :data:`TORQUE_LIMIT`. Each hinge has armature :data:`ARMATURE` (reflected rotor inertia), which keeps the
  light hands and toes stable at the 300 Hz step.
- **Contacts:** friction 1.0; contacts twice as stiff as MuJoCo's default (``solref`` 0.01 s, ``solimp``
  0.95-0.99), which keeps a loaded sole within a few millimetres of the floor.
- **Integration:** 300 Hz (:data:`PHYSICS_HZ`, ten steps per 30 fps frame), ``implicitfast`` (the servo
  damping is integrated implicitly).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from latentrl.datasets.body import TOE_HEIGHT_M, rest_joints
from latentrl.errors import ConfigError
from latentrl.motion.skeleton import JOINT_NAMES, NUM_JOINTS, PARENTS, children

PHYSICS_HZ = 300
"""Physics steps per second."""
BMI_KG_M2 = 22.9
"""Default body-mass index: mass = BMI * height^2 (70.1 kg at 1.75 m)."""
GRAVITY = 9.81
ARMATURE = 0.02
"""Armature of every hinge, kg m^2."""

MASS_PERCENT: dict[str, float] = {
    "pelvis": 11.17, "spine1": 16.33 / 2, "spine2": 16.33 / 2, "spine3": 15.96 - 2.0, "collar": 1.0,
    "neck": 1.0, "head": 6.94 - 1.0, "hip": 14.16, "knee": 4.33, "ankle": 1.37 * 0.8, "foot": 1.37 * 0.2,
    "shoulder": 2.71, "elbow": 1.62, "wrist": 0.61,
}
"""Percent of body mass carried by the body of each SMPL joint kind (de Leva 1996, split as the docstring says)."""

RADIUS: dict[str, float] = {
    "pelvis": 0.055, "spine1": 0.06, "spine2": 0.065, "spine3": 0.065, "collar": 0.03, "neck": 0.03,
    "head": 0.058, "hip": 0.04, "knee": 0.029, "shoulder": 0.026, "elbow": 0.021, "wrist": 0.02,
}
"""Capsule (sphere for the head) radius as a fraction of body height."""

FOOT_HALF_WIDTH = 0.025
"""Half the foot's width as a fraction of body height (foot breadth about 0.055 H)."""
FOOT_LENGTH = 0.152
"""Heel to toe tip as a fraction of body height (Drillis & Contini)."""
HEEL_BACK = 0.03
"""Heel behind the ankle centre as a fraction of body height (as latentrl.datasets.body places it)."""

GAINS: dict[str, tuple[float, float]] = {
    "hip": (800.0, 80.0), "knee": (800.0, 80.0), "ankle": (800.0, 80.0), "foot": (300.0, 30.0),
    "spine1": (1000.0, 100.0), "spine2": (1000.0, 100.0), "spine3": (1000.0, 100.0),
    "neck": (500.0, 50.0), "head": (300.0, 30.0), "collar": (500.0, 50.0), "shoulder": (500.0, 50.0),
    "elbow": (500.0, 50.0), "wrist": (300.0, 30.0),
}
"""(kp N m/rad, kv N m s/rad) per joint kind at 70 kg."""

TORQUE_LIMIT: dict[str, float] = {
    "hip": 400.0, "knee": 400.0, "ankle": 300.0, "foot": 100.0, "spine1": 400.0, "spine2": 400.0,
    "spine3": 400.0, "neck": 150.0, "head": 100.0, "collar": 150.0, "shoulder": 150.0, "elbow": 150.0,
    "wrist": 60.0,
}
"""Largest servo torque per hinge, N m at 70 kg (scaled by mass like the gains)."""

ARM_KINDS = ("collar", "shoulder", "elbow", "wrist")
AXIS_ORDER: tuple[str, ...] = tuple(
    "" if j == 0 else ("xzy" if any(k in JOINT_NAMES[j] for k in ARM_KINDS) else "xyz") for j in range(NUM_JOINTS)
)
"""Hinge axes of each body joint in application order ('' for the pelvis, which has the free joint)."""

BODY_JOINTS = tuple(range(1, NUM_JOINTS))
"""The 21 SMPL joints with hinges (all but the pelvis)."""


def kind(joint: int) -> str:
    """The joint's name without its side ('left_hip' -> 'hip')."""
    return JOINT_NAMES[joint].removeprefix("left_").removeprefix("right_")


def default_mass(height: float) -> float:
    """Body mass (kg) for ``height`` (m) at :data:`BMI_KG_M2`."""
    return BMI_KG_M2 * float(height) ** 2


@dataclass(frozen=True)
class Humanoid:
    """A generated humanoid: its size, rest skeleton and MJCF text.

    Attributes:
        height: body height, metres.
        mass: total mass, kg.
        rest_joints: (22, 3) rest joint positions (pelvis entry = standing pelvis), metres, z up, facing +y.
        xml: the MJCF model.
    """

    height: float
    mass: float
    rest_joints: np.ndarray
    xml: str = field(repr=False)

    def model(self):
        """A compiled ``mujoco.MjModel`` of this humanoid."""
        from latentrl.physics import require_mujoco

        return require_mujoco().MjModel.from_xml_string(self.xml)


def build_humanoid(height: float = 1.75, mass: float | None = None) -> Humanoid:
    """The humanoid with latentrl's rest skeleton at ``height`` metres and ``mass`` kg (default: BMI 22.9)."""
    height = float(height)
    if not 1.0 <= height <= 2.5:  # also refuses nan
        raise ConfigError(f"humanoid height must be in [1.0, 2.5] m, got {height}")
    mass = default_mass(height) if mass is None else float(mass)
    if not 20.0 <= mass <= 250.0:
        raise ConfigError(f"humanoid mass must be in [20, 250] kg, got {mass}")
    rest = rest_joints(height)
    return Humanoid(height, mass, rest, _mjcf(rest, height, mass))


def _f(values) -> str:
    return " ".join(f"{float(v):.6g}" for v in np.atleast_1d(values))


def foot_box(j: int, rest: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """Centre (relative to joint ``j``, rest axes) and half sizes of the box of an ankle (rear foot) or foot (toes)."""
    ankle = rest[j] if kind(j) == "ankle" else rest[PARENTS[j]]
    toe = rest[j] if kind(j) == "foot" else rest[children(j)[0]]
    heel = ankle[1] - HEEL_BACK * h
    y0, y1 = (heel, toe[1]) if kind(j) == "ankle" else (toe[1], heel + FOOT_LENGTH * h)
    top = ankle[2] if kind(j) == "ankle" else 2.0 * TOE_HEIGHT_M
    center = np.array([rest[j][0], (y0 + y1) / 2, top / 2]) - rest[j]
    return center, np.array([FOOT_HALF_WIDTH * h, (y1 - y0) / 2, top / 2])


SOLE_JOINTS = (7, 8, 10, 11)
"""The joints whose bodies carry the foot boxes: ankles (rear feet) and feet (toes)."""


def sole_points(rest: np.ndarray, h: float) -> np.ndarray:
    """(4, 4, 3): the four bottom corners of each foot box of :data:`SOLE_JOINTS`, relative to the joint, rest axes."""
    out = np.empty((len(SOLE_JOINTS), 4, 3))
    for i, j in enumerate(SOLE_JOINTS):
        center, size = foot_box(j, rest, h)
        for c, (sx, sy) in enumerate(((-1, -1), (-1, 1), (1, -1), (1, 1))):
            out[i, c] = center + np.array([sx * size[0], sy * size[1], -size[2]])
    return out


def _geoms(j: int, rest: np.ndarray, h: float, mass: float) -> list[str]:
    """The geoms of joint ``j``'s body, in its frame (origin at the joint, axes of the rest pose)."""
    k = kind(j)
    m = mass * MASS_PERCENT[k] / 100.0
    here = rest[j]
    name = JOINT_NAMES[j]
    if k in ("ankle", "foot"):
        center, size = foot_box(j, rest, h)
        return [f'<geom name="{name}" type="box" pos="{_f(center)}" size="{_f(size)}" mass="{m:.6g}"/>']
    r = RADIUS[k] * h
    if k == "head":
        return [f'<geom name="{name}" type="sphere" pos="0 0 {0.035 * h:.6g}" size="{r:.6g}" mass="{m:.6g}"/>']
    if k == "wrist":
        elbow = rest[PARENTS[j]]
        end = (here - elbow) / np.linalg.norm(here - elbow) * 0.08 * h
        return [f'<geom name="{name}" type="capsule" fromto="0 0 0 {_f(end)}" size="{r:.6g}" mass="{m:.6g}"/>']
    if k == "pelvis":
        ends = (rest[1] - here, rest[2] - here)
    elif k == "spine3":
        ends = (np.zeros(3), rest[12] - here)
    else:
        ends = (np.zeros(3), rest[children(j)[0]] - here)
    return [f'<geom name="{name}" type="capsule" fromto="{_f(ends[0])} {_f(ends[1])}" size="{r:.6g}" '
            f'mass="{m:.6g}"/>']


def _body(j: int, rest: np.ndarray, h: float, mass: float, depth: int) -> list[str]:
    pad = "  " * depth
    name = JOINT_NAMES[j]
    pos = rest[j] if j == 0 else rest[j] - rest[PARENTS[j]]
    lines = [f'{pad}<body name="{name}" pos="{_f(pos)}">']
    if j == 0:
        lines.append(f'{pad}  <freejoint name="root"/>')
    for axis in AXIS_ORDER[j]:
        vec = {"x": "1 0 0", "y": "0 1 0", "z": "0 0 1"}[axis]
        lines.append(f'{pad}  <joint name="{name}_{axis}" type="hinge" axis="{vec}" armature="{ARMATURE}"/>')
    lines += [f"{pad}  {g}" for g in _geoms(j, rest, h, mass)]
    for c in children(j):
        lines += _body(c, rest, h, mass, depth + 1)
    lines.append(f"{pad}</body>")
    return lines


def _mjcf(rest: np.ndarray, h: float, mass: float) -> str:
    scale = mass / 70.0
    actuators = []
    for j in BODY_JOINTS:
        kp, kv = GAINS[kind(j)]
        limit = TORQUE_LIMIT[kind(j)] * scale
        for axis in AXIS_ORDER[j]:
            actuators.append(f'    <position name="{JOINT_NAMES[j]}_{axis}" joint="{JOINT_NAMES[j]}_{axis}" '
                             f'kp="{kp * scale:.6g}" kv="{kv * scale:.6g}" forcerange="{-limit:.6g} {limit:.6g}"/>')
    body = "\n".join(_body(0, rest, h, mass, 2))
    return f"""<mujoco model="latentrl_humanoid">
  <compiler angle="radian" autolimits="true"/>
  <option timestep="{1.0 / PHYSICS_HZ:.9g}" integrator="implicitfast" gravity="0 0 {-GRAVITY}"/>
  <default>
    <geom contype="1" conaffinity="0" friction="1.0 0.02 0.01" solref="0.01 1" solimp="0.95 0.99 0.001"
          rgba="0.7 0.6 0.5 1"/>
  </default>
  <worldbody>
    <light pos="0 0 4" dir="0 0 -1"/>
    <geom name="floor" type="plane" size="0 0 0.05" contype="0" conaffinity="1" rgba="0.8 0.8 0.8 1"/>
{body}
  </worldbody>
  <actuator>
{chr(10).join(actuators)}
  </actuator>
</mujoco>
"""
