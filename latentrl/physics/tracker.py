"""The tracker that needs no training: PD servos on the reference's hinge angles plus a reported root assist.

Every motion frame (30 fps) the servos get the next frame's hinge angles as targets, with the reference's
angle velocity folded in (target + kv/kp * velocity makes the servo's ``-kv dq`` a ``kv (dq_ref - dq)``).
A residual root assist, as in Residual Force Control (Yuan & Kitani 2020) but hand-set instead of learned,
pulls the pelvis toward the reference at every physics step, a critically damped spring of ``assist_hz``:
a force ``F = m w^2 (p_ref - p) + 2 m w (v_ref - v)`` and a torque
``T = I w^2 rotvec(R_ref R^T) + 2 I w (w_ref - w_pelvis)`` with ``w = 2 pi assist_hz``, ``m`` the body mass and
``I = m`` x :data:`ASSIST_INERTIA_M2`. The ``-2 m w v`` and ``-2 I w w_pelvis`` parts are the free joint's
damping, which MuJoCo integrates implicitly (the light pelvis would make an explicit damper unstable at 300 Hz);
the rest is applied to the pelvis as an external wrench. Nothing of it is hidden: its impulse per second of
motion and that as a percent of body weight are in every result.

A **fall** is a frame where the mean joint distance to the reference exceeds 0.5 m (PHC's failure test); the
simulation is then put back on the reference at that frame and continues, so a fall costs one count.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from latentrl.errors import ConfigError
from latentrl.motion.skeleton import JOINT_NAMES, NUM_JOINTS
from latentrl.physics import require_mujoco
from latentrl.physics.humanoid import (
    AXIS_ORDER,
    BODY_JOINTS,
    GAINS,
    GRAVITY,
    SOLE_JOINTS,
    Humanoid,
    kind,
    sole_points,
)
from latentrl.physics.reference import Reference, local_rotations

ASSIST_HZ = 2.0
"""Default natural frequency of the root assist, Hz."""
ASSIST_INERTIA_M2 = 0.1
"""Rotational inertia of the assist per kg of body mass, m^2 (a standing adult about a horizontal axis)."""
FALL_DISTANCE_M = 0.5
"""Mean joint distance to the reference (m) beyond which a frame counts as a fall."""


@dataclass
class TrackResult:
    """A simulated motion and what it took.

    Attributes:
        joints: (T, 22, 3) simulated joint positions (body origins), metres.
        rotations: (T, 22, 3, 3) simulated local rotations (entry 0 = pelvis orientation).
        soles: (T, 4, 3) each foot box's sole centre x, y and lowest corner z (:meth:`Simulator.soles`), metres.
        fps: frames per second (the reference's).
        falls: frames at which a fall was counted.
        assist_force: (T,) mean |assist force| over each frame's physics steps, N (0 for frame 0).
        assist_vector: (T, 3) mean assist force vector over each frame's physics steps, world axes, N.
        assist_torque: (T,) the same as ``assist_force`` for the assist torque, N m.
        mass: body mass, kg.
        sim_seconds: wall-clock seconds spent in physics and control.
    """

    joints: np.ndarray
    rotations: np.ndarray
    soles: np.ndarray
    fps: float
    falls: list[int] = field(default_factory=list)
    assist_force: np.ndarray | None = None
    assist_torque: np.ndarray | None = None
    assist_vector: np.ndarray | None = None
    mass: float = 0.0
    sim_seconds: float = 0.0

    @property
    def seconds(self) -> float:
        """Length of the motion, seconds (frames - 1 transitions)."""
        return max(len(self.joints) - 1, 1) / self.fps

    def assist_summary(self) -> dict[str, float]:
        """The assist per second of motion (N s/s, N m s/s), as percent of body weight, its peak and direction.

        ``mean_lift_N`` and ``mean_horizontal_N`` are the mean force vector's upward part and horizontal size:
        whether the assist mostly carries the body or pushes it along.
        """
        force = np.asarray(self.assist_force[1:]) if self.assist_force is not None else np.zeros(1)
        torque = np.asarray(self.assist_torque[1:]) if self.assist_torque is not None else np.zeros(1)
        mean_force = float(force.mean()) if force.size else 0.0
        vec = np.asarray(self.assist_vector[1:]) if self.assist_vector is not None else np.zeros((1, 3))
        return {
            "force_Ns_per_s": mean_force,
            "force_percent_body_weight": 100.0 * mean_force / (self.mass * GRAVITY),
            "peak_force_N": float(force.max()) if force.size else 0.0,
            "mean_lift_N": float(vec[:, 2].mean()) if len(vec) else 0.0,
            "mean_horizontal_N": float(np.linalg.norm(vec[:, :2].mean(0))) if len(vec) else 0.0,
            "torque_Nms_per_s": float(torque.mean()) if torque.size else 0.0,
        }


class Simulator:
    """One humanoid in MuJoCo with index maps between SMPL joints and MuJoCo's state vectors."""

    def __init__(self, humanoid: Humanoid):
        mj = require_mujoco()
        self.mj = mj
        self.humanoid = humanoid
        self.model = humanoid.model()
        self.data = mj.MjData(self.model)
        m = self.model
        names = [f"{JOINT_NAMES[j]}_{a}" for j in BODY_JOINTS for a in AXIS_ORDER[j]]
        self.qpos_index = np.array([m.joint(n).qposadr[0] for n in names])
        self.dof_index = np.array([m.joint(n).dofadr[0] for n in names])
        self.actuator_index = np.array([m.actuator(n).id for n in names])
        self.body_index = np.array([m.body(JOINT_NAMES[j]).id for j in range(NUM_JOINTS)])
        self.pelvis = int(self.body_index[0])
        self.sole_offsets = sole_points(humanoid.rest_joints, humanoid.height)
        kp = np.array([GAINS[kind(j)][0] for j in BODY_JOINTS for _ in AXIS_ORDER[j]])
        kv = np.array([GAINS[kind(j)][1] for j in BODY_JOINTS for _ in AXIS_ORDER[j]])
        self.lead = kv / kp
        """Seconds of reference velocity folded into each servo target."""

    def set_state(self, root_pos, root_rot, angles, root_vel=None, root_angvel=None, angle_vel=None) -> None:
        """Put the body in a pose (world root, (3, 3) orientation, (63,) hinge angles) with the given velocities."""
        d = self.data
        d.qpos[:] = 0.0
        d.qvel[:] = 0.0
        d.qpos[0:3] = root_pos
        quat = np.zeros(4)
        self.mj.mju_mat2Quat(quat, np.asarray(root_rot, dtype=np.float64).reshape(9))
        d.qpos[3:7] = quat
        d.qpos[self.qpos_index] = angles
        if root_vel is not None:
            d.qvel[0:3] = root_vel
        if root_angvel is not None:  # the free joint's angular velocity is in the body frame
            d.qvel[3:6] = np.asarray(root_rot).T @ root_angvel
        if angle_vel is not None:
            d.qvel[self.dof_index] = angle_vel
        d.ctrl[self.actuator_index] = angles
        d.xfrc_applied[:] = 0.0
        self.mj.mj_forward(self.model, d)

    def set_assist(self, hz: float | None) -> tuple[float, float, float, float]:
        """Root assist at ``hz`` (None or 0: off): sets the free joint's damping, returns (kp_f, kd_f, kp_t, kd_t)."""
        if not hz:
            self.model.dof_damping[0:6] = 0.0
            return 0.0, 0.0, 0.0, 0.0
        w = 2 * np.pi * hz
        mass = self.humanoid.mass
        inertia = mass * ASSIST_INERTIA_M2
        gains = (mass * w * w, 2 * mass * w, inertia * w * w, 2 * inertia * w)
        self.model.dof_damping[0:3] = gains[1]
        self.model.dof_damping[3:6] = gains[3]
        return gains

    def joints(self) -> np.ndarray:
        """(22, 3) world joint positions now."""
        return self.data.xpos[self.body_index].copy()

    def world_rotations(self) -> np.ndarray:
        """(22, 3, 3) world rotations of the 22 bodies now."""
        return self.data.xmat[self.body_index].reshape(NUM_JOINTS, 3, 3).copy()

    def soles(self) -> np.ndarray:
        """(4, 3) per foot box (left, right rear foot; left, right toes): its sole's centre x, y and lowest corner z.

        The centre is what slides, the lowest corner what touches: CLoSD's metrics at the soles read both.
        """
        ids = self.body_index[list(SOLE_JOINTS)]
        rot = self.data.xmat[ids].reshape(-1, 3, 3)
        corners = self.data.xpos[ids][:, None] + np.einsum("jab,jcb->jca", rot, self.sole_offsets)
        return np.concatenate((corners[..., :2].mean(1), corners[..., 2].min(1)[:, None]), axis=-1)


def _rotvec(r: np.ndarray) -> np.ndarray:
    """(3, 3) rotation -> axis-angle vector (radians)."""
    cos = np.clip((np.trace(r) - 1) / 2, -1.0, 1.0)
    angle = np.arccos(cos)
    v = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    s = np.sin(angle)
    if s < 1e-6:
        return v / 2  # small angle; an error near pi cannot arise within one physics step of a tracked pose
    return v * angle / (2 * s)


def _rot_slerp(a: np.ndarray, b: np.ndarray, w: float) -> np.ndarray:
    """The rotation a fraction ``w`` of the way from (3, 3) ``a`` to ``b``."""
    step = _rotvec(b @ a.T) * w
    angle = np.linalg.norm(step)
    if angle < 1e-12:
        return a
    k = step / angle
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return (np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx) @ a


def track(humanoid: Humanoid, ref: Reference, assist_hz: float | None = ASSIST_HZ,
          simulator: Simulator | None = None, start_state: bool = True) -> TrackResult:
    """Execute ``ref`` on ``humanoid`` from the reference's first frame; see the module docstring.

    ``assist_hz``: the root assist's natural frequency, None or 0 for none. ``simulator`` reuses a
    :class:`Simulator` (the closed loop does); ``start_state=False`` continues from its current state instead
    of placing the body on frame 0.
    """
    if assist_hz is not None and not 0.0 <= assist_hz <= 50.0:  # also refuses nan
        raise ConfigError(f"assist frequency must be in [0, 50] Hz, got {assist_hz}")
    sim = Simulator(humanoid) if simulator is None else simulator
    mj, m, d = sim.mj, sim.model, sim.data
    kp_f, kd_f, kp_t, kd_t = sim.set_assist(assist_hz)
    frames = ref.frames
    steps = max(1, round(1.0 / (ref.fps * m.opt.timestep)))
    if start_state:
        sim.set_state(ref.root_pos[0], ref.root_rot[0], ref.angles[0], ref.root_vel[0], ref.root_angvel[0],
                      ref.angle_vel[0])
    joints = np.empty((frames, NUM_JOINTS, 3))
    world = np.empty((frames, NUM_JOINTS, 3, 3))
    soles = np.empty((frames, len(SOLE_JOINTS), 3))
    force_log = np.zeros(frames)
    force_vec = np.zeros((frames, 3))
    torque_log = np.zeros(frames)
    falls: list[int] = []
    joints[0], world[0], soles[0] = sim.joints(), sim.world_rotations(), sim.soles()
    t0 = time.perf_counter()
    for t in range(1, frames):
        d.ctrl[sim.actuator_index] = ref.angles[t] + sim.lead * ref.angle_vel[t]
        f_sum = tau_sum = 0.0
        for s in range(steps):
            w = (s + 1) / steps  # the reference between frames t-1 and t
            if kp_f:
                p_ref = (1 - w) * ref.root_pos[t - 1] + w * ref.root_pos[t]
                v_ref = (1 - w) * ref.root_vel[t - 1] + w * ref.root_vel[t]
                r_ref = _rot_slerp(ref.root_rot[t - 1], ref.root_rot[t], w)
                w_ref = (1 - w) * ref.root_angvel[t - 1] + w * ref.root_angvel[t]
                r = d.xmat[sim.pelvis].reshape(3, 3)
                spring_f = kp_f * (p_ref - d.qpos[0:3]) + kd_f * v_ref
                spring_t = kp_t * _rotvec(r_ref @ r.T) + kd_t * w_ref
                d.xfrc_applied[sim.pelvis, 0:3] = spring_f
                d.xfrc_applied[sim.pelvis, 3:6] = spring_t
                applied = spring_f - kd_f * d.qvel[0:3]
                force_vec[t] += applied / steps
                f_sum += float(np.linalg.norm(applied))
                tau_sum += float(np.linalg.norm(spring_t - kd_t * (r @ d.qvel[3:6])))
            mj.mj_step(m, d)
        force_log[t], torque_log[t] = f_sum / steps, tau_sum / steps
        joints[t], world[t], soles[t] = sim.joints(), sim.world_rotations(), sim.soles()
        if np.linalg.norm(joints[t] - ref.joints[t], axis=-1).mean() > FALL_DISTANCE_M or not np.isfinite(d.qpos).all():
            falls.append(t)
            sim.set_state(ref.root_pos[t], ref.root_rot[t], ref.angles[t], ref.root_vel[t], ref.root_angvel[t],
                          ref.angle_vel[t])
    d.xfrc_applied[:] = 0.0
    return TrackResult(joints=joints, rotations=local_rotations(world), soles=soles, fps=ref.fps, falls=falls,
                       assist_force=force_log, assist_vector=force_vec, assist_torque=torque_log, mass=humanoid.mass,
                       sim_seconds=time.perf_counter() - t0)
