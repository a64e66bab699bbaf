"""The closed loop: the motion model plans, physics executes, the last two *simulated* frames are the next history.

This is CLoSD's loop with DART's 2-frame history.

Each primitive: the model samples 8 frames from the current history; the tracker
(:mod:`latentrl.physics.tracker`) executes them on the humanoid, continuing from the simulator's state; the
simulated frames' features (joints, rotations and their deltas, :func:`simulated_features`) are
canonicalized as usual and replace the history, with the world transform taken from the simulation. So the
plan adapts to what physics did (a foot that could not slide, a body the assist held back) instead of
continuing from where the model believed it was.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import torch

from latentrl.motion.canonical import features_to_world, world_to_canonical
from latentrl.motion.representation import HISTORY_LENGTH, compute_features, joints_of
from latentrl.motion.rollout import MotionModel, RolloutState
from latentrl.motion.skeleton import FPS, NUM_JOINTS
from latentrl.physics.humanoid import Humanoid
from latentrl.physics.reference import build_reference, contact_heights, features_rotations, local_rotations
from latentrl.physics.tracker import ASSIST_HZ, Simulator, track


@dataclass
class ClosedLoopResult:
    """A closed-loop rollout of one character.

    Attributes:
        planned: (2 + 8 S, 22, 3) the model's plans as it placed them (seed frames first), world metres.
        simulated: (2 + 8 S, 22, 3) what the humanoid did, world metres.
        features: (2 + 8 S, 276) world features of the simulated motion.
        soles: (2 + 8 S, 4, 3) each foot box's sole (:meth:`Simulator.soles`; seed frames: the first simulated pose's).
        histories: S (2, 22, 3) world joints of the history each primitive was planned from (as the model got it).
        falls: frames at which the tracker counted a fall.
        assist_force: (2 + 8 S,) mean |assist force| per frame, N.
        mass: body mass, kg.
    """

    planned: np.ndarray
    simulated: np.ndarray
    features: np.ndarray
    soles: np.ndarray | None = None
    histories: list[np.ndarray] = field(default_factory=list)
    falls: list[int] = field(default_factory=list)
    assist_force: np.ndarray | None = None
    mass: float = 0.0


def simulated_features(joints: np.ndarray, local: np.ndarray, pelvis_delta: np.ndarray) -> np.ndarray:
    """(T, 276) world features of simulated frames: (T, 22, 3) joints, (T, 22, 3, 3) local rotations, T >= 2.

    The last frame's deltas continue the motion at its final velocity (there is no next frame yet).
    """
    joints = np.asarray(joints, dtype=np.float64)
    local = np.asarray(local, dtype=np.float64)
    next_joints = 2 * joints[-1] - joints[-2]
    glob = local[:, 0]
    next_local = local[-1].copy()
    next_local[0] = glob[-1] @ glob[-2].T @ glob[-1]
    joints = np.concatenate((joints, next_joints[None]))
    local = np.concatenate((local, next_local[None]))
    transl = joints[:, 0] - np.asarray(pelvis_delta, dtype=np.float64)
    return compute_features(torch.as_tensor(transl), torch.as_tensor(local), torch.as_tensor(joints)).numpy()


def closed_loop(model: MotionModel, humanoid: Humanoid, texts: Sequence[str], noise: torch.Tensor | None = None,
                generator: torch.Generator | None = None, assist_hz: float | None = ASSIST_HZ,
                state: RolloutState | None = None) -> ClosedLoopResult:
    """Plan with ``model`` and execute on ``humanoid``, one primitive per entry of ``texts`` (see the module docstring).

    Args:
        model: the motion model (with a seed history and ``pelvis_delta``).
        humanoid: the body (its rest skeleton should be the model's, e.g. ``build_humanoid`` at the data's height).
        texts: the prompt of each primitive.
        noise: (S, 1, 1, D) latent noise per primitive (the RL action); N(0, I) from ``generator`` if None.
        assist_hz: the tracker's root assist (None: none).
        state: the start (default: one of the model's seed histories, as a kinematic rollout starts).
    """
    pelvis_delta = model.pelvis_delta.detach().cpu().double().numpy()
    state = state or model.initial_state(1, generator)
    seed = features_to_world(state.history, state.world, model.pelvis_delta)[0].detach().cpu().double().numpy()
    planned = [seed[:, 144:210].reshape(-1, NUM_JOINTS, 3)]
    plan_feats = [seed]
    sim = Simulator(humanoid)
    first = build_reference(planned[0], seed, FPS, humanoid)
    sim.set_state(first.root_pos[-1], first.root_rot[-1], first.angles[-1], first.root_vel[-1],
                  first.root_angvel[-1], first.angle_vel[-1])
    sim_joints = [planned[0][:-1], sim.joints()[None]]
    sim_local = [features_rotations(seed[:-1]), _local(sim)[None]]
    sim_soles = [np.repeat(sim.soles()[None], HISTORY_LENGTH, axis=0)]
    assist = [np.zeros(HISTORY_LENGTH)]
    histories, falls = [], []
    frame = HISTORY_LENGTH
    for step, text in enumerate(texts):
        histories.append(history_joints(state))
        emb = model.encode_text([text])
        x_t = noise[step] if noise is not None else torch.randn(
            1, *model.latent_shape, generator=generator,
            device=generator.device if generator is not None else "cpu").to(model.device)
        out = model.rollout_step(state, emb, x_t)
        plan = features_to_world(out.future, out.placement, model.pelvis_delta)[0].detach().cpu().double().numpy()
        planned.append(plan[:, 144:210].reshape(-1, NUM_JOINTS, 3))
        plan_feats.append(plan)
        last = simulated_features(np.concatenate(sim_joints)[-2:], np.concatenate(sim_local)[-2:], pelvis_delta)
        window_joints = np.concatenate((np.concatenate(sim_joints)[-1:], planned[-1]))
        window_feats = np.concatenate((last[-1:], plan))
        contact = contact_heights(np.concatenate(planned))
        ref = build_reference(window_joints, window_feats, FPS, humanoid, contact)
        result = track(humanoid, ref, assist_hz, simulator=sim, start_state=False)
        sim_joints.append(result.joints[1:])
        sim_local.append(result.rotations[1:])
        sim_soles.append(result.soles[1:])
        assist.append(result.assist_force[1:])
        falls += [frame + f - 1 for f in result.falls]
        frame += len(plan)
        feats = simulated_features(np.concatenate(sim_joints)[-2:], np.concatenate(sim_local)[-2:], pelvis_delta)
        world_feats = torch.as_tensor(feats[None], dtype=torch.float32, device=model.device)
        history, world = world_to_canonical(world_feats, model.pelvis_delta)
        state = RolloutState(history, world, torch.zeros(1, dtype=torch.bool, device=model.device))
    joints = np.concatenate(sim_joints)
    local = np.concatenate(sim_local)
    return ClosedLoopResult(planned=np.concatenate(planned), simulated=joints,
                            features=simulated_features(joints, local, pelvis_delta), histories=histories,
                            soles=np.concatenate(sim_soles), falls=falls, assist_force=np.concatenate(assist),
                            mass=humanoid.mass)


def _local(sim: Simulator) -> np.ndarray:
    """(22, 3, 3) local rotations of the simulated body now."""
    return local_rotations(sim.world_rotations()[None])[0]


def history_joints(state: RolloutState) -> np.ndarray:
    """(2, 22, 3) world joints of a rollout state's history (for checking what the model was given)."""
    return state.world.apply(joints_of(state.history))[0].detach().cpu().double().numpy()


class PrimitiveExecutor:
    """Executes one planned primitive at a time on the humanoid and returns the next history.

    The same step as :func:`closed_loop`, for a caller that plans elsewhere (an env driven by a policy,
    ``latentrl eval --physics``): it keeps the simulator and everything it did between primitives.

    Args:
        humanoid: the body.
        seed_joints, seed_features: (2, 22, 3) and (2, 276) world joints and features of the start history.
        pelvis_delta: (3,) the model's pelvis offset (``MotionModel.pelvis_delta``).
        assist_hz: the tracker's root assist (None: none).
    """

    def __init__(self, humanoid: Humanoid, seed_joints: np.ndarray, seed_features: np.ndarray,
                 pelvis_delta: np.ndarray, assist_hz: float | None = ASSIST_HZ):
        self.humanoid, self.assist_hz = humanoid, assist_hz
        self.pelvis_delta = np.asarray(pelvis_delta, dtype=np.float64)
        seed_joints = np.asarray(seed_joints, dtype=np.float64)
        seed_features = np.asarray(seed_features, dtype=np.float64)
        self.sim = Simulator(humanoid)
        first = build_reference(seed_joints, seed_features, FPS, humanoid)
        self.sim.set_state(first.root_pos[-1], first.root_rot[-1], first.angles[-1], first.root_vel[-1],
                           first.root_angvel[-1], first.angle_vel[-1])
        self.planned = [seed_joints]
        self.joints = [seed_joints[:-1], self.sim.joints()[None]]
        self.local = [features_rotations(seed_features[:-1]), _local(self.sim)[None]]
        self.assist = [np.zeros(HISTORY_LENGTH)]
        self.falls: list[int] = []
        self.frames = HISTORY_LENGTH

    def execute(self, plan_joints: np.ndarray, plan_features: np.ndarray) -> np.ndarray:
        """Track (F, 22, 3) world joints / (F, 276) world features; returns the (2, 276) simulated history."""
        plan_joints = np.asarray(plan_joints, dtype=np.float64)
        plan_features = np.asarray(plan_features, dtype=np.float64)
        self.planned.append(plan_joints)
        joints, local = np.concatenate(self.joints), np.concatenate(self.local)
        last = simulated_features(joints[-2:], local[-2:], self.pelvis_delta)
        ref = build_reference(np.concatenate((joints[-1:], plan_joints)),
                              np.concatenate((last[-1:], plan_features)), FPS, self.humanoid,
                              contact_heights(np.concatenate(self.planned)))
        result = track(self.humanoid, ref, self.assist_hz, simulator=self.sim, start_state=False)
        self.joints.append(result.joints[1:])
        self.local.append(result.rotations[1:])
        self.assist.append(result.assist_force[1:])
        self.falls += [self.frames + f - 1 for f in result.falls]
        self.frames += len(plan_joints)
        return simulated_features(np.concatenate(self.joints)[-2:], np.concatenate(self.local)[-2:],
                                  self.pelvis_delta)

    @property
    def simulated(self) -> np.ndarray:
        """(T, 22, 3) world joints the humanoid went through (seed frames first)."""
        return np.concatenate(self.joints)

    @property
    def assist_force(self) -> np.ndarray:
        """(T,) mean |assist force| per frame, N."""
        return np.concatenate(self.assist)
