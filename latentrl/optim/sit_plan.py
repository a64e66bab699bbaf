"""The planned sit and get-up: the noise of each posture change chosen so that the pelvis ends where the task asks.

Why: a sit policy learns the approach (the body at the seat, its back to it) but never holds a seat, because
``sit down`` does not know the seat's height: the model sits at a height by chance (docs/scenes.md, "The planned
sit"). DART sits by optimizing the noise toward the seat (its scene demos), and so does this. When a sit env's
approach ends, it predicts the next ``primitives`` primitives from the env's own state with the texts the env will
use (its settle steps, then ``sit down``), placed exactly as the env places them
(``MotionModel.differentiable_step(post_process=True)``), and scores each plan by the pelvis's distance from its
seated point (over the seat, within ``slack`` of its centre, ``SEATED_PELVIS_ABOVE_SEAT_M`` above its top) on the
plan's last ``hold`` frames, the seat's collision cost, the feet's floor distance and skate, and the noise prior.
It first draws ``samples`` N(0, I) plans in one batched pass without gradients and keeps the best (the model's own
sits, at whatever height each lands), then moves all its primitives' noises ``steps`` Adam steps (DART's unit
gradient per plan, learning rate decaying to 0). The plan is executed primitive by primitive instead of the
policy's actions; the env's prediction and the plan agree to the bit, so the body ends where the plan does. With
``getup_primitives`` > 0 the stand-up and the walk away are planned the same way, ``getup_primitives`` at a time:
the pelvis at the env's standing height on the plan's last primitive, and in the walk away also ``leave_distance``
from the seat. With ``approach`` > 0 the approach's end is planned too: once the pelvis is within ``approach`` metres
of the sit-down spot, ``approach_primitives`` of the walk text at a time bring it within ``slack`` of the spot with
the body turned to the sitter's facing (a policy's own approach to a seat it must sit on with its back may loop
metres away to turn). A plan is dropped when its env changes phase (or leaves the approach's range) and made again
when it ran out.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import torch

from latentrl.envs.goal import body_forward
from latentrl.errors import LatentRLError
from latentrl.evaluation.metrics import foot_floor_distance_cm, foot_skate_cm_s
from latentrl.motion.representation import FUTURE_LENGTH
from latentrl.motion.skeleton import FPS, PELVIS
from latentrl.optim.descent import descend
from latentrl.optim.losses import pseudo_huber
from latentrl.optim.refine import inputs_rows, predict, scene_rows
from latentrl.rewards.terms import noise_prior
from latentrl.scenes.contact import collision_cost


@dataclass
class SitPlanSettings:
    """How the sit is planned (``latentrl eval --sit-plan STEPS``; docs/scenes.md)."""

    steps: int = 20
    """Adam steps on the best drawn plan (0 with ``samples`` 0: off)."""
    samples: int = 32
    """N(0, I) plans drawn first, scored without gradients; the best is where the optimizer starts (0: zero noise)."""
    primitives: int = 9
    """The sit plan's length (8 frames each: 2.4 s, the motion bench's sit check)."""
    getup_primitives: int = 3
    """The stand-up's and the walk away's plan length (0: the policy stands up and walks away)."""
    approach: float = 0.0
    """Metres from the sit-down spot within which the approach's end is planned too (0: the policy approaches)."""
    approach_primitives: int = 5
    """The approach plan's length. Why 5: a half turn at the spot takes 4-5 primitives of ``walk``."""
    facing: float = 0.5
    """Weight of the approach plan's turn error (1 - the cosine between the body's forward axis and the sitter's
    facing, on its last primitive)."""
    hold: int = 24
    """The plan's last frames in which the pelvis is asked to be at its seated point. Why more than the env's
    ``hold_frames`` (15): a plan whose loss averages over exactly 15 frames often holds 12-14 of them."""
    lr: float = 0.6
    """Adam's learning rate (decaying to 0). Why this high: from the end of an approach the pelvis must move
    0.4-0.7 m back to the seat: of 19 plans from the ends of approaches to five seats (0.2-0.6 m), 40 steps at
    0.1 (with ``hold`` 15) seated 5 in their prediction, at 0.6 (``hold`` 24) 17."""
    slack: float = 0.1
    """Metres from the seat centre within which the pelvis's xy costs nothing (the env's ``sit_radius`` is 0.3; a
    seat is 0.5 m wide). Why: a body that arrives at the edge of its approach disc sits down beside the seat's
    centre, and moving it all the way costs optimizer steps the sit does not need."""
    collision: float = 1.0
    """Weight of the seat's collision cost in sit and get-up plans (metres summed over joints: a seated pelvis 1 cm
    inside its skin costs 0.01, a knee through the seat's front 0.1-0.2; at 0.1 sits from a planned approach put a
    knee 15-23 cm into the seat)."""
    approach_collision: float = 10.0
    """Weight of the seat's collision cost in approach plans (no joint belongs in the seat on the way to it)."""
    floor: float = 1.0
    """Weight of the feet's floor distance (m): the feet stay on the floor in front of the seat."""
    skate: float = 1.0
    """Weight of the feet's skate (m/s)."""
    prior: float = 0.1
    """Weight of the noise-shell penalty (the ``prior`` reward term), per primitive."""
    seed: int = 0
    """Seed of the drawn plans (each planning call seeds its own generator from it and the number of calls before)."""

    @classmethod
    def of(cls, steps: int, samples: int | None = None, getup: int | None = None,
           approach: float | None = None) -> SitPlanSettings:
        """The settings of these, None taking its default (flags, a policy's stored ones)."""
        chosen = {"samples": samples, "getup_primitives": getup, "approach": approach}
        return cls(steps=steps, **{k: v for k, v in chosen.items() if v is not None})

    def check(self) -> None:
        """One-line :class:`LatentRLError` for a value out of range."""
        if not 0 <= self.steps <= 1000:
            raise LatentRLError(f"sit plan steps: expected 0-1000, got {self.steps}")
        if not 0 <= self.samples <= 1024:
            raise LatentRLError(f"sit plan samples: expected 0-1024, got {self.samples}")
        if not 1 <= self.primitives <= 32:
            raise LatentRLError(f"sit plan primitives: expected 1-32, got {self.primitives}")
        if not 0 <= self.getup_primitives <= 32:
            raise LatentRLError(f"sit plan getup primitives: expected 0-32, got {self.getup_primitives}")
        if not 0 <= self.approach <= 5:
            raise LatentRLError(f"sit plan approach: expected metres in [0, 5], got {self.approach}")
        if not 1 <= self.approach_primitives <= 32:
            raise LatentRLError(f"sit plan approach primitives: expected 1-32, got {self.approach_primitives}")
        if not 1 <= self.hold <= 8 * self.primitives:
            raise LatentRLError(f"sit plan hold: expected 1-{8 * self.primitives} frames, got {self.hold}")
        if not 0 < self.lr <= 10:
            raise LatentRLError(f"sit plan lr: expected a learning rate in (0, 10], got {self.lr}")
        if not 0 <= self.slack <= 1:
            raise LatentRLError(f"sit plan slack: expected metres in [0, 1], got {self.slack}")
        for name in ("collision", "approach_collision", "floor", "skate", "prior", "facing"):
            value = getattr(self, name)
            if not 0 <= value <= 1000:
                raise LatentRLError(f"sit plan {name}: expected a weight in [0, 1000], got {value}")


UPRIGHT_MARGIN_M = 0.03
"""A get-up plan asks the pelvis this much above the env's standing bar (so that the executed motion clears it)."""
LEAVE_MARGIN_M = 0.1
"""A walk-away plan asks the pelvis this much beyond the env's ``leave_distance`` from the seat centre."""


class PlanGoals(NamedTuple):
    """What the plans of M envs aim at.

    (M,) phase (0 approach, 1 sit, 2 stand, 3 leave), (M, 3) seated point, (M,) upright pelvis z, (M,) distance from
    the seat centre to leave to, (M, 3) sit-down spot and (M, 2) the sitter's facing (xy unit vector).
    """

    phase: torch.Tensor
    seated: torch.Tensor
    upright: torch.Tensor
    leave: torch.Tensor
    spot: torch.Tensor
    facing: torch.Tensor

    def rows(self, idx: torch.Tensor) -> PlanGoals:
        """The goals of rows ``idx``."""
        return PlanGoals(*(t[idx] for t in self))


def seated_points(env) -> torch.Tensor:
    """(N, 3) each env's seated pelvis point: over its seat centre, at the env's seated height."""
    return torch.cat((env.seat[:, :2], env.seated_height()[:, None]), dim=1)


def plan_goals(env, idx: torch.Tensor) -> PlanGoals:
    """The goals of envs ``idx`` in their current phases."""
    leave = torch.full((idx.numel(),), env.cfg.leave_distance + LEAVE_MARGIN_M, device=env.device)
    return PlanGoals(env.phase[idx], seated_points(env)[idx], env.upright_height()[idx] + UPRIGHT_MARGIN_M, leave,
                     env.goal_world[idx], env.facing()[idx])


def goal_loss(joints: torch.Tensor, goals: PlanGoals, settings: SitPlanSettings) -> torch.Tensor:
    """(B,) the pseudo-Huber distance of each plan's pelvis from its phase's goal, averaged over its last frames.

    Approach: within ``slack`` (xy) of the sit-down spot on the last primitive, plus ``facing`` times the turn
    still to make. Sit: within ``slack`` (xy) of the seated point and at its height on the last ``hold`` frames.
    Stand and leave: at least the upright height on the last primitive, and in the walk away at least
    ``goals.leave`` from the seat.
    """
    seat = goals.seated[:, None]
    sit = joints[:, -settings.hold:, PELVIS]  # (B, H, 3)
    off_xy = ((sit[..., :2] - seat[..., :2]).norm(dim=-1) - settings.slack).clamp(min=0.0)
    sit_d2 = off_xy.square() + (sit[..., 2] - seat[..., 2]).square()
    up = joints[:, -FUTURE_LENGTH:, PELVIS]
    low = (goals.upright[:, None] - up[..., 2]).clamp(min=0.0)
    near = (goals.leave[:, None] - (up[..., :2] - seat[..., :2]).norm(dim=-1)).clamp(min=0.0)
    up_d2 = low.square() + (goals.phase == 3).float()[:, None] * near.square()
    sitting = goals.phase == 1
    loss = torch.where(sitting, pseudo_huber(sit_d2).mean(dim=1), pseudo_huber(up_d2).mean(dim=1))
    approaching = goals.phase == 0
    if bool(approaching.any()):  # the turn reads the body's axes: only for approach plans (the planner's batches)
        last = joints[:, -FUTURE_LENGTH:]
        off_spot = ((up[..., :2] - goals.spot[:, None, :2]).norm(dim=-1) - settings.slack).clamp(min=0.0)
        forward = body_forward(last.reshape(-1, *last.shape[2:]))[0][:, :2].reshape(*last.shape[:2], 2)
        turn = 1.0 - (forward * goals.facing[:, None]).sum(dim=-1)
        approach = pseudo_huber(off_spot.square()).mean(dim=1) + settings.facing * turn.mean(dim=1)
        loss = torch.where(approaching, approach, loss)
    return loss


def plan_loss(joints: torch.Tensor, noise: torch.Tensor, goals: PlanGoals, scene, floor: float,
              settings: SitPlanSettings) -> torch.Tensor:
    """(B,) a plan's loss: joints (B, T, 22, 3), noise (S, B, 1, D), the envs' goals and seats."""
    loss = goal_loss(joints, goals, settings)
    if settings.collision or settings.approach_collision:
        weight = torch.where(goals.phase == 0, settings.approach_collision, settings.collision)
        loss = loss + weight * collision_cost(joints, scene)
    if settings.floor:
        loss = loss + settings.floor * foot_floor_distance_cm(joints, floor) / 100.0
    if settings.skate:
        loss = loss + settings.skate * foot_skate_cm_s(joints, float(FPS), floor) / 100.0
    if settings.prior:
        loss = loss - settings.prior * noise_prior(noise.flatten(2)).mean(dim=0)
    return loss


def plan_sits(env, idx: torch.Tensor, settings: SitPlanSettings, calls: int = 0, length: int | None = None
              ) -> torch.Tensor:
    """(S, M, 1, D) the planned noises of envs ``idx`` (M,) from their current state, toward their phases' goals.

    ``length``: primitives S (None: ``settings.primitives``); ``calls``: how many plans this planner made before
    (so that each call's draws are its own).
    """
    model, bound = env.motion, float(env.action_bound)
    if not hasattr(model, "differentiable_step"):
        raise LatentRLError(f"sit plan: the motion model {type(model).__name__} has no differentiable_step")
    inputs = inputs_rows(env.step_inputs(), idx)
    s = settings.primitives if length is None else length
    texts = env.text_table.embeddings[env.plan_texts(idx, s)]  # (S, M, E)
    scene = scene_rows(env.scene.batch, idx)
    goals = plan_goals(env, idx)
    floor = float(env.floor_height)
    m = idx.numel()
    shape = (s, m, *model.latent_shape)
    best = torch.zeros(shape, device=env.device)
    if settings.samples:
        g = torch.Generator().manual_seed(settings.seed * 1_000_003 + calls)
        draws = torch.randn(settings.samples, *shape, generator=g).to(env.device).clamp(-bound, bound)
        rows = torch.arange(m, device=env.device).repeat(settings.samples)
        z = draws.transpose(0, 1).reshape(s, settings.samples * m, *shape[2:])  # draw k of env j: column k*m + j
        with torch.no_grad():
            joints = predict(model, inputs_rows(inputs, rows), z, texts[:, rows])
            losses = plan_loss(joints, z, goals.rows(rows), scene_rows(scene, rows), floor, settings)
        pick = losses.reshape(settings.samples, m).argmin(dim=0)
        best = draws[pick, :, torch.arange(m, device=env.device)].transpose(0, 1).contiguous()  # (S, M, 1, D)
    if not settings.steps:
        return best

    def loss_of(z: torch.Tensor) -> torch.Tensor:
        return plan_loss(predict(model, inputs, z, texts), z, goals, scene, floor, settings)

    return descend(best, loss_of, settings.steps, settings.lr, bound, env_dim=1)[0]


class SitPlanner:
    """A sit env's policy function with planned sits: ``SitPlanner(env, act, settings)(obs) -> action``.

    Keeps each env's plan, its phase and how much of it ran; a plan is dropped when its env changes phase (or is
    reset, or walks out of the approach's range), and made again when it ran out with the env still in a planned
    phase.
    """

    def __init__(self, env, act: Callable[[torch.Tensor], torch.Tensor], settings: SitPlanSettings):
        settings.check()
        if not hasattr(env, "plan_texts"):
            raise LatentRLError(f"sit plan: {type(env).__name__} has no sit phase (a sit task env plans its sits)")
        self.env, self.act, self.settings = env, act, settings
        n = env.num_envs
        s = max(settings.primitives, settings.getup_primitives, settings.approach_primitives)
        self.plan = torch.zeros(s, n, *env.motion.latent_shape, device=env.device)
        self.cursor = torch.zeros(n, dtype=torch.long, device=env.device)
        self.length = torch.zeros(n, dtype=torch.long, device=env.device)  # cursor >= length: no plan left
        self.phase = torch.zeros(n, dtype=torch.long, device=env.device)  # the phase each plan was made in
        self.ended = torch.zeros(n, dtype=torch.bool, device=env.device)  # got up, not reset since: nothing to plan
        self.calls = 0
        self.planned = 0
        """Plans made so far."""

    def __call__(self, obs: torch.Tensor) -> torch.Tensor:
        """The policy's action, or the next primitive of the env's plan where its phase is planned."""
        action = self.act(obs)
        env, settings = self.env, self.settings
        given = torch.as_tensor(action, device=env.device).detach().to(torch.float32)
        n = given.shape[0]
        phase = env.phase.to(env.device)
        planned = (phase == 1) | ((phase >= 2) & (settings.getup_primitives > 0))
        if settings.approach > 0:
            pelvis = env.history_world()[:, -1, PELVIS, :2]
            near = (pelvis - env.goal_world[:, :2]).norm(dim=-1) < settings.approach
            planned |= (phase == 0) & near
        self.ended = (self.ended | env.got_up.to(env.device)) & (phase != 0)  # an evaluation steps ended envs on
        active = planned & ~self.ended & torch.isfinite(given).all(dim=1)  # a NaN action: the env's own check
        self.length = torch.where(active & (phase == self.phase), self.length, torch.zeros_like(self.length))
        kinds = ((phase == 0, settings.approach_primitives), (phase == 1, settings.primitives),
                 (phase >= 2, settings.getup_primitives))
        for kind, length in kinds:
            need = active & (self.cursor >= self.length) & kind
            if not bool(need.any()):
                continue
            idx = need.nonzero().squeeze(1)
            self.plan[:length, idx] = plan_sits(env, idx, settings, self.calls, length)
            self.cursor[idx], self.length[idx], self.phase[idx] = 0, length, phase[idx]
            self.calls += 1
            self.planned += idx.numel()
        if not bool(active.any()):
            return action
        idx = active.nonzero().squeeze(1)
        out = given.clone()
        out[idx] = self.plan[self.cursor[idx], idx].reshape(idx.numel(), -1)
        self.cursor[idx] += 1
        return out.reshape(n, -1)


def sit_planning(env, act: Callable[[torch.Tensor], torch.Tensor], settings: SitPlanSettings
                 ) -> Callable[[torch.Tensor], torch.Tensor]:
    """``act`` (obs -> action) with the sits planned on ``env``'s state: an evaluation's policy function."""
    return SitPlanner(env, act, settings)
