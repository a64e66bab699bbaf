"""The learned tracker's training env: N MuJoCo humanoids each following a reference motion (DeepMimic-style).

Each env holds one :class:`~latentrl.physics.tracker.Simulator` and steps one motion frame (1/30 s, ten
physics steps) per action. Design choices, after DeepMimic (Peng et al. 2018) and PHC (Luo et al. 2023):

- **Action:** (63,) residual hinge targets in [-1, 1], times ``action_scale`` radians, added to the stage-1
  PD target of the next reference frame (its hinge angles plus the velocity lead). A zero action is the
  untrained tracker, so training starts from something that mostly stands.
- **Observation:** (:data:`OBS_DIM`,) the body in its own pelvis frame (joint offsets, pelvis height and
  velocities, hinge angles and velocities) and the next reference frame relative to it (its joints in the
  same frame, hinge angle differences, pelvis orientation and velocity).
- **Reward:** ``sum_k w_k exp(-c_k e_k)`` over pose (squared hinge angle errors), velocity (squared hinge
  velocity errors), end effectors (squared position errors of head, wrists and toes) and root (pelvis
  position and orientation); each term is 1 when the simulated state equals the reference.
- **Reference state init:** an episode starts on a random motion at a random frame, in its reference state.
- **Early termination:** when the mean joint distance to the reference exceeds ``terminate_distance``.
- **Root assist:** stage 1's pelvis spring (:mod:`~latentrl.physics.tracker`), scaled by
  :attr:`TrackingEnv.assist_scale`, which falls linearly from 1 to ``assist_final`` over
  ``assist_anneal_steps`` env steps; its mean force is reported with every episode.

The env speaks the trainers' torch ``VectorEnv`` contract (:mod:`latentrl.ppo.contract`, SAME_STEP autoreset)
without importing :mod:`latentrl.envs`.
"""

from __future__ import annotations

from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import torch

from latentrl.motion.skeleton import NUM_JOINTS
from latentrl.physics.humanoid import GRAVITY, Humanoid
from latentrl.physics.reference import Reference, kinematic_joints
from latentrl.physics.tracker import Simulator, _rotvec

END_EFFECTORS = (10, 11, 15, 20, 21)
"""Left and right toe bases, head, left and right wrists."""
REWARD_WEIGHTS = {"pose": 0.65, "velocity": 0.1, "end_effector": 0.15, "root": 0.1}
"""DeepMimic's weights (its centre-of-mass term is the root term here)."""
REWARD_SCALES = {"pose": 2.0, "velocity": 0.01, "end_effector": 40.0, "root": 10.0}
"""Kernel scales c_k: DeepMimic's, but velocity 0.01 instead of 0.1 (summed over 63 hinge velocities, which a
300 Hz simulation makes noisier than DeepMimic's joint velocities: at 0.1 the term read 0 throughout).
The root error is |dp|^2 + 0.1 angle^2 (m^2, rad^2)."""
HINGES = 63
OBS_DIM = 66 + 1 + 6 + HINGES + HINGES + 66 + HINGES + 6 + 3
"""Observation size: see :meth:`Character.observe`."""


@dataclass
class Motion:
    """A reference and what it is measured against: the humanoid's kinematic joints and the motion's own joints."""

    ref: Reference
    kinematic: np.ndarray
    """(T, 22, 3) joints of the humanoid placed on the reference (what the reward compares)."""
    joints: np.ndarray
    """(T, 22, 3) the motion's joints (what MPJPE compares, as ``physics track`` does)."""

    @classmethod
    def of(cls, ref: Reference, humanoid: Humanoid) -> Motion:
        """The :class:`Motion` of ``ref`` on ``humanoid``."""
        return cls(ref, kinematic_joints(humanoid.rest_joints, ref), np.asarray(ref.joints, dtype=np.float64))


class Character:
    """One simulated humanoid following one :class:`Motion` frame by frame; the unit both the env and evaluation use."""

    def __init__(self, humanoid: Humanoid, assist_hz: float, action_scale: float):
        self.sim = Simulator(humanoid)
        self.gains = self.sim.set_assist(assist_hz) if assist_hz else (0.0, 0.0, 0.0, 0.0)
        self.damping = self.sim.model.dof_damping[0:6].copy()
        self.action_scale = float(action_scale)
        self.weight = humanoid.mass * GRAVITY
        self.steps = max(1, round(1.0 / (30.0 * self.sim.model.opt.timestep)))
        self.motion: Motion | None = None
        self.t = 0

    def reset_to(self, motion: Motion, t: int) -> None:
        """Put the body in ``motion``'s reference state at frame ``t`` (reference state init)."""
        r = motion.ref
        self.motion, self.t = motion, int(t)
        self.steps = max(1, round(1.0 / (r.fps * self.sim.model.opt.timestep)))
        self.sim.set_state(r.root_pos[t], r.root_rot[t], r.angles[t], r.root_vel[t], r.root_angvel[t],
                           r.angle_vel[t])

    def step(self, action: np.ndarray, assist_scale: float) -> float:
        """Advance one frame with residual ``action`` (63,) in [-1, 1]; returns the mean |assist force|, N."""
        sim, r, t = self.sim, self.motion.ref, self.t + 1
        d = sim.data
        d.ctrl[sim.actuator_index] = r.angles[t] + sim.lead * r.angle_vel[t] + self.action_scale * action
        kp_f, kd_f, kp_t, kd_t = (g * assist_scale for g in self.gains)
        sim.model.dof_damping[0:6] = self.damping * assist_scale
        force = 0.0
        if kp_f:  # stage 1's spring toward the target frame, set once per frame (2 Hz: stable over 1/30 s)
            rot = d.xmat[sim.pelvis].reshape(3, 3)
            spring_f = kp_f * (r.root_pos[t] - d.qpos[0:3]) + kd_f * r.root_vel[t]
            d.xfrc_applied[sim.pelvis, 0:3] = spring_f
            d.xfrc_applied[sim.pelvis, 3:6] = kp_t * _rotvec(r.root_rot[t] @ rot.T) + kd_t * r.root_angvel[t]
            force = float(np.linalg.norm(spring_f - kd_f * d.qvel[0:3]))
        else:
            d.xfrc_applied[sim.pelvis] = 0.0
        for _ in range(self.steps):
            sim.mj.mj_step(sim.model, d)
        self.t = t
        return force

    def error(self) -> float:
        """Mean joint distance (m) to the kinematic reference at the current frame (inf when the state diverged)."""
        j = self.sim.data.xpos[self.sim.body_index]
        if not np.isfinite(j).all():
            return float("inf")
        return float(np.linalg.norm(j - self.motion.kinematic[self.t], axis=-1).mean())

    def rewards(self) -> dict[str, float]:
        """Each reward term at the current frame, in (0, 1]."""
        sim, r, t = self.sim, self.motion.ref, self.t
        d = sim.data
        pose = float(np.sum((d.qpos[sim.qpos_index] - r.angles[t]) ** 2))
        vel = float(np.sum((d.qvel[sim.dof_index] - r.angle_vel[t]) ** 2))
        ee = list(END_EFFECTORS)
        end = float(np.sum((d.xpos[sim.body_index[ee]] - self.motion.kinematic[t, ee]) ** 2))
        angle = float(np.linalg.norm(_rotvec(r.root_rot[t] @ d.xmat[sim.pelvis].reshape(3, 3).T)))
        root = float(np.sum((d.qpos[0:3] - r.root_pos[t]) ** 2)) + 0.1 * angle**2
        errors = {"pose": pose, "velocity": vel, "end_effector": end, "root": root}
        return {k: float(np.exp(-REWARD_SCALES[k] * e)) if np.isfinite(e) else 0.0 for k, e in errors.items()}

    def observe(self) -> np.ndarray:
        """(OBS_DIM,) the body in its pelvis frame, then the next reference frame (the last one at the end) in it."""
        sim, m = self.sim, self.motion
        d = sim.data
        nxt = min(self.t + 1, m.ref.frames - 1)
        rot = d.xmat[sim.pelvis].reshape(3, 3)
        pelvis = d.xpos[sim.pelvis]
        joints = (d.xpos[sim.body_index] - pelvis) @ rot  # row vectors: rot^T v
        angles = d.qpos[sim.qpos_index]
        ref_joints = (m.kinematic[nxt] - pelvis) @ rot
        rel = rot.T @ m.ref.root_rot[nxt]
        parts = (joints.ravel(), [pelvis[2]], rot.T @ d.qvel[0:3], d.qvel[3:6], angles, 0.1 * d.qvel[sim.dof_index],
                 ref_joints.ravel(), m.ref.angles[nxt] - angles, rel[:, :2].T.ravel(), rot.T @ m.ref.root_vel[nxt])
        out = np.concatenate([np.asarray(p, dtype=np.float64).ravel() for p in parts])
        return np.nan_to_num(out, nan=0.0, posinf=1e3, neginf=-1e3).clip(-1e3, 1e3)


class TrackingEnv:
    """``num_envs`` :class:`Character` s on random motions and frames; torch tensors in and out (CPU).

    Args:
        humanoid: the simulated body.
        motions: the references to sample from (at least one, each of 2 frames or more).
        num_envs: parallel characters, stepped one after the other on this thread.
        episode_frames: frames after which an episode is truncated (also at a motion's last frame).
        terminate_distance: mean joint distance (m) to the reference that ends an episode.
        action_scale: radians of residual target per unit action.
        assist_hz, assist_final, assist_anneal_steps: the root assist and its schedule (module docstring).
    """

    def __init__(self, humanoid: Humanoid, motions: list[Motion], num_envs: int, *, episode_frames: int = 300,
                 terminate_distance: float = 0.3, action_scale: float = 0.5, assist_hz: float = 2.0,
                 assist_final: float = 0.0, assist_anneal_steps: int = 0):
        import gymnasium as gym

        self.humanoid, self.motions, self.num_envs = humanoid, motions, int(num_envs)
        self.episode_frames, self.terminate_distance = int(episode_frames), float(terminate_distance)
        self.assist_final, self.assist_anneal_steps = float(assist_final), int(assist_anneal_steps)
        self.chars = [Character(humanoid, assist_hz, action_scale) for _ in range(self.num_envs)]
        self.single_observation_space = gym.spaces.Box(-np.inf, np.inf, (OBS_DIM,), np.float32)
        self.single_action_space = gym.spaces.Box(-1.0, 1.0, (HINGES,), np.float32)
        self.metadata: dict = {}
        self.rewards = SimpleNamespace(weights=dict(REWARD_WEIGHTS))
        self.total_steps = 0
        """Env steps taken (summed over envs): the assist schedule's clock (set it when a run resumes)."""
        self.rng = np.random.default_rng(0)
        self._length = np.zeros(self.num_envs, dtype=np.int64)
        self._return = np.zeros(self.num_envs)
        self._assist = np.zeros(self.num_envs)

    @property
    def assist_scale(self) -> float:
        """The assist's share of its full strength now: 1 -> ``assist_final`` linearly over the anneal steps."""
        if self.assist_anneal_steps <= 0:
            return 1.0
        w = min(self.total_steps / self.assist_anneal_steps, 1.0)
        return (1 - w) + w * self.assist_final

    def _start(self, i: int) -> None:
        motion = self.motions[int(self.rng.integers(len(self.motions)))]
        self.chars[i].reset_to(motion, int(self.rng.integers(motion.ref.frames - 1)))
        self._length[i], self._return[i], self._assist[i] = 0, 0.0, 0.0

    def observation(self) -> torch.Tensor:
        """(N, OBS_DIM) float32 observations now."""
        return torch.as_tensor(np.stack([c.observe() for c in self.chars]), dtype=torch.float32)

    def reset(self, seed: int | None = None, options=None):
        """Every env on a random motion and frame; ``seed`` reseeds the frame sampler."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        for i in range(self.num_envs):
            self._start(i)
        return self.observation(), {}

    def step(self, actions):
        """One frame for every env; ended episodes restart at once (SAME_STEP autoreset, ``final_obs`` kept)."""
        a = np.asarray(torch.as_tensor(actions, dtype=torch.float32).cpu(), dtype=np.float64).clip(-1.0, 1.0)
        n, scale = self.num_envs, self.assist_scale
        reward = np.zeros(n)
        terms = {k: np.zeros(n) for k in REWARD_WEIGHTS}
        terminated, truncated = np.zeros(n, bool), np.zeros(n, bool)
        for i, c in enumerate(self.chars):
            self._assist[i] += c.step(a[i], scale)
            r = c.rewards()
            for k, v in r.items():
                terms[k][i] = v
            reward[i] = sum(REWARD_WEIGHTS[k] * v for k, v in r.items())
            self._length[i] += 1
            terminated[i] = c.error() > self.terminate_distance
            truncated[i] = not terminated[i] and (c.t >= c.motion.ref.frames - 1
                                                  or self._length[i] >= self.episode_frames)
        self._return += reward
        self.total_steps += n
        done = terminated | truncated
        infos: dict = {f"reward/{k}": torch.as_tensor(v, dtype=torch.float32) for k, v in terms.items()}
        if done.any():
            final = self.observation()
            ends = np.flatnonzero(done)
            infos["final_obs"], infos["_final_obs"] = final, torch.as_tensor(done)
            infos["episode"] = {"r": torch.as_tensor(self._return, dtype=torch.float32),
                                "l": torch.as_tensor(self._length.copy(), dtype=torch.int64)}
            infos["_episode"] = torch.as_tensor(done)
            infos["assist_percent_body_weight"] = 100.0 * float(
                (self._assist[ends] / self._length[ends]).mean()) / self.chars[0].weight
            for i in ends:
                self._start(int(i))
        return (self.observation(), torch.as_tensor(reward, dtype=torch.float32), torch.as_tensor(terminated),
                torch.as_tensor(truncated), infos)

    def close(self) -> None:
        """Nothing to release (MuJoCo frees its data with the objects)."""


def joints_now(char: Character) -> np.ndarray:
    """(22, 3) the character's simulated joints."""
    return char.sim.data.xpos[char.sim.body_index].reshape(NUM_JOINTS, 3).copy()
