"""Closed-loop refinement: a few optimizer steps on the noise a policy picks, before each env step.

Why: a ReachJoint policy steers toward a goal seconds ahead, but lands tens of centimetres off, while the
optimizer lands a joint on its target to the centimetre yet knows nothing beyond the frames it rolls out
(docs/joint_goals.md). Each env step, this predicts the next ``horizon`` primitives from the env's own state,
placed exactly as the env places them (floor snap and foot lock included:
``MotionModel.differentiable_step(post_process=True)``), and moves the noise so that every goal due within
them lands: a receding horizon, as model-predictive control does. The policy's action is the start of the
first primitive's noise (the next ones start at zero); only the first is executed, and the next step plans
again from where the body really is. The current goal, when beyond the horizon, gets a *pace* target at its end,
on the straight line from the joint to its target at the pace that arrives on time (pelvis, hands, head;
not the feet, which step). A foot's target is a footstep: the foot on the floor at its frame, held there the
frames after, and never low over the floor off its stone the frames before (:func:`landing_loss`).
Envs with nothing to refine keep the policy's action.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import NamedTuple

import torch

from latentrl.constants import CONTACT_HEIGHT_M
from latentrl.envs.reach_joint import JOINTS
from latentrl.errors import LatentRLError
from latentrl.motion.representation import FUTURE_LENGTH
from latentrl.motion.rollout import RolloutState
from latentrl.motion.skeleton import FOOT_JOINTS, FPS
from latentrl.optim.descent import descend
from latentrl.optim.losses import pseudo_huber, regularizers, target_squared
from latentrl.optim.problems import Targets
from latentrl.rewards.terms import noise_prior

STARTS = ("policy", "zeros", "auto")
"""Where a step's refinement starts (:attr:`RefineSettings.start`)."""
FOOT_HOLD = 2
"""Frames after a footstep's frame in which the foot is also held on its stone (xy), unless
:attr:`RefineSettings.land` holds it down longer."""
LANDING_FRAMES = 8
"""Frames before a footstep's frame in which a foot low over the floor is pulled onto its stone (``landing_loss``)."""
FOOT_DOWN_M = 0.02
"""A footstep asks its foot joint to be this high above the floor at its frame: on the floor (a toe base planted
sits 0-2 cm up; the evaluation's touchdown is below 3 cm)."""


@dataclass
class RefineSettings:
    """How much to refine (``latentrl eval --refine STEPS``; docs/joint_goals.md)."""

    steps: int = 8
    """Adam steps per env step (0: the policy's action unchanged)."""
    start: str = "policy"
    """Where each step's refinement starts: ``policy`` (its action), ``zeros`` (zero noise; for joints the
    policy was not trained on, whose actions start it off worse: docs/joint_goals.md) or ``auto`` (the policy's
    action where the current goal's joint is one of :attr:`policy_joints`, zero noise elsewhere)."""
    policy_joints: tuple[str, ...] = ("pelvis",)
    """With ``start="auto"``: the joints the policy was trained on (its ``env.reach_joint.joints``)."""
    horizon: int = 3
    """Primitives predicted (8 frames each); the first is executed."""
    lr: float = 0.1
    pace: float = 0.5
    """Weight of the pace target of a goal beyond the horizon (0: off)."""
    prior: float = 0.1
    """Weight of the noise-shell penalty (the ``prior`` reward term), per primitive."""
    land: int = 0
    """Frames after a footstep's frame in which its foot is held down on its stone, x, y and the floor
    (``--refine-land``), in place of the :data:`FOOT_HOLD` frames held in x and y (0). Why: a foot that cannot be
    down by its frame (the first step from rest, due a third of a second after the start) then comes down on its
    stone as soon as it can, not past or short of it (docs/joint_goals.md: with 6 and 64 steps 574 of
    ``stepping_stones``' 576 footsteps in 32 episodes land, against 568 with 0)."""
    skate: float = 0.0
    """Weight of DART's foot skate (m/s) over the predicted frames and the last history frame (``--refine-skate``).
    At 1 the shipped pelvis policy's skate fell from 7-9 to 4-6.5 cm/s, its pelvis_near error rose from 2.0 to
    2.4 cm and its hand targets failed more often (docs/joint_goals.md)."""

    @classmethod
    def of(cls, steps: int, horizon: int | None = None, start: str | None = None, skate: float | None = None,
           pace: float | None = None, land: int | None = None,
           policy_joints: tuple[str, ...] = ("pelvis",)) -> RefineSettings:
        """The settings of these, each None taking its default (``latentrl eval``'s flags, a policy's stored ones)."""
        chosen = {"horizon": horizon, "start": start, "skate": skate, "pace": pace, "land": land}
        return cls(steps=steps, policy_joints=policy_joints, **{k: v for k, v in chosen.items() if v is not None})

    def check(self) -> None:
        """One-line :class:`LatentRLError` for a value out of range."""
        if not 0 <= self.steps <= 1000:
            raise LatentRLError(f"refine steps: expected 0-1000, got {self.steps}")
        if not 0 <= self.land <= 16:
            raise LatentRLError(f"refine land: expected 0-16 frames, got {self.land}")
        if not 1 <= self.horizon <= 16:
            raise LatentRLError(f"refine horizon: expected 1-16 primitives, got {self.horizon}")
        if self.start not in STARTS:
            raise LatentRLError(f"refine start: expected one of {', '.join(STARTS)}, got {self.start!r}")
        unknown = [j for j in self.policy_joints if j not in JOINTS]
        if unknown:
            raise LatentRLError(f"refine policy joints: expected some of {', '.join(JOINTS)}, got {unknown[0]!r:.40}")
        if not 0 < self.lr <= 10:
            raise LatentRLError(f"refine lr: expected a learning rate in (0, 10], got {self.lr}")
        for name in ("pace", "prior", "skate"):
            value = getattr(self, name)
            if not 0 <= value <= 1000:
                raise LatentRLError(f"refine {name}: expected a weight in [0, 1000], got {value}")


class Footsteps(NamedTuple):
    """The foot goals due in the horizon.

    (N, W) frame index into the predicted frames, SMPL joint and mask; (N, W, 2) target xy.
    """

    frame: torch.Tensor
    joint: torch.Tensor
    on: torch.Tensor
    xy: torch.Tensor


def goal_targets(env, horizon_frames: int, pace: float, land: int = 0) -> tuple[Targets, Footsteps, torch.Tensor]:
    """The point targets of the goals due in the next ``horizon_frames`` frames, and a pace target beyond.

    ``land``: :attr:`RefineSettings.land` (0: each footstep's foot held on its stone in x and y for
    :data:`FOOT_HOLD` frames after its frame; else held down on it, x, y and the floor, for ``land`` frames).

    Returns the targets (frames index the predicted frames, 0 = the next step's first), the footsteps among them
    (:func:`landing_loss`) and (N,) whether an env has anything to refine.
    """
    goals = env.upcoming_goals()
    n, w = goals["joint"].shape
    offset, valid, joint = goals["offset"], goals["valid"], goals["joint"]
    dev = offset.device
    inside = valid & (offset >= 1) & (offset <= horizon_frames)
    xy = torch.tensor([1.0, 1.0, 0.0], device=dev)
    masks = torch.where(goals["planar"][..., None], xy, torch.ones(3, device=dev)).expand(n, w, 3)
    frames, points = (offset - 1).clamp(0, horizon_frames - 1), goals["target"]
    feet = (joint[..., None] == torch.tensor(FOOT_JOINTS, device=dev)).any(-1)
    # a footstep: on the floor at its frame and still on the target the frames after it
    foot = inside & feet & goals["planar"]
    down = torch.cat((points[..., :2], torch.full_like(offset[..., None], env.floor_height + FOOT_DOWN_M,
                                                       dtype=points.dtype)), -1)
    after = [((offset + d - 1).clamp(0, horizon_frames - 1), foot & (offset + d <= horizon_frames))
             for d in range(1, (land or FOOT_HOLD) + 1)]
    held, held_masks = (down, torch.ones_like(masks)) if land else (points, masks)
    # the current goal beyond the horizon: where the joint is on pace at the horizon's end (one target: a pace
    # target at every predicted primitive's end held the slow entry of pelvis_far worse, 10.8 against 4.1 cm)
    current = valid[:, 0] & (offset[:, 0] > horizon_frames) & ~feet[:, 0] & (pace > 0)
    now = env.history_world()[:, -1][torch.arange(n, device=dev), joint[:, 0]]  # (N, 3)
    on_pace = now + (points[:, 0] - now) * (horizon_frames / offset[:, 0].clamp(min=1).float())[:, None]
    targets = Targets(
        frames=torch.cat((frames, frames, *(f for f, _ in after), torch.full_like(frames[:, :1], horizon_frames - 1)),
                         1),
        joints=torch.cat((joint, joint, *(joint for _ in after), joint[:, :1]), 1),
        points=torch.cat((points, down, *(held for _ in after), on_pace[:, None]), 1),
        masks=torch.cat((masks, torch.tensor([0.0, 0.0, 1.0], device=dev).expand(n, w, 3),
                         *(held_masks for _ in after), masks[:, :1]), 1),
        weights=torch.cat((inside.float(), foot.float(), *(ok.float() for _, ok in after),
                           current.float()[:, None] * pace), 1),
    )
    return targets, Footsteps(frames, joint, foot, points[..., :2]), inside.any(dim=1) | current


def landing_loss(joints: torch.Tensor, steps: Footsteps, floor: float) -> torch.Tensor:
    """(N,) each footstep's xy distance to its stone before its frame, weighted by the foot's contact there.

    The pseudo-Huber distance at each of the :data:`LANDING_FRAMES` before, times the foot's contact weight
    (1 on the floor, 0 from 3 cm up). Why: a foot comes down over several frames, and the evaluation's
    touchdown is the first frame below 3 cm, often 2-5 frames before the goal frame, while the foot still
    moves forward by centimetres a frame. A foot low anywhere off its stone costs; the optimizer may land it
    on the stone sooner or keep it up until over it.
    """
    n = joints.shape[0]
    if not bool(steps.on.any()):
        return joints.new_zeros(n)
    rows = torch.arange(n, device=joints.device)[:, None]
    loss = joints.new_zeros(n)
    for back in range(1, LANDING_FRAMES + 1):
        f = steps.frame - back
        ok = steps.on & (f >= 0)
        at = joints[rows, f.clamp(min=0), steps.joint]  # (N, W, 3)
        weight = (1.0 - (at[..., 2] - floor) / CONTACT_HEIGHT_M).clamp(0.0, 1.0)
        d2 = (at[..., :2] - steps.xy).square().sum(-1)
        loss = loss + (ok.float() * weight * pseudo_huber(d2)).sum(dim=1)
    return loss


def predict(model, inputs: dict, noise: torch.Tensor, texts: torch.Tensor | None = None) -> torch.Tensor:
    """(N, S x 8, 22, 3) world joints of the next S primitives of noises (S, N, 1, D), placed as the env will.

    ``texts``: (S, N, E) a text embedding per primitive (a planner of text changes); None: the inputs' own text.
    """
    state, frames = inputs["state"], []
    kwargs = {k: v for k, v in inputs.items() if k != "state"}
    for s, z in enumerate(noise):
        if texts is not None:
            kwargs["text_embedding"] = texts[s]
        out = model.differentiable_step(state, noise=z, post_process=True, **kwargs)
        frames.append(out.joints_world)
        state = out.state
    return torch.cat(frames, dim=1)


def inputs_rows(inputs: dict, idx: torch.Tensor) -> dict:
    """The step inputs of envs ``idx`` (a one-scene terrain stays as it is: it answers any batch)."""
    state = inputs["state"]
    out = dict(inputs)
    out["state"] = RolloutState(state.history[idx], state.world.index(idx),
                                None if state.airborne is None else state.airborne[idx])
    out["text_embedding"] = inputs["text_embedding"][idx]
    guidance = inputs.get("guidance_scale")
    if isinstance(guidance, torch.Tensor) and guidance.dim() > 0:  # one scale per env
        out["guidance_scale"] = guidance[idx]
    terrain = inputs.get("terrain")
    if terrain is not None and terrain.num_scenes != 1:
        out["terrain"] = terrain.index(idx)
    return out


def scene_rows(scene, idx: torch.Tensor):
    """The scenes of envs ``idx`` (a one-scene batch stays as it is: it answers any batch)."""
    return scene if scene.num_scenes == 1 else scene.index(idx)


def refine(env, action: torch.Tensor, settings: RefineSettings) -> torch.Tensor:
    """The (N, D) noise to step ``env`` (a ReachJoint env, after reset) with, refined from ``action``."""
    if settings.steps == 0:
        return action
    model, horizon = env.motion, settings.horizon * FUTURE_LENGTH
    bound = float(env.action_bound)
    n = env.num_envs
    with torch.no_grad():
        targets, steps, active = goal_targets(env, horizon, settings.pace, settings.land)
    if not bool(active.any()):
        return action
    inputs = env.step_inputs()
    last = env.history_world()[:, -1:]
    if not hasattr(model, "differentiable_step"):
        raise LatentRLError(f"refine: the motion model {type(model).__name__} has no differentiable_step")
    given = torch.as_tensor(action, device=env.device).detach().to(torch.float32)
    given = given.reshape(n, *model.latent_shape).clamp(-bound, bound)
    start = torch.zeros_like(given) if settings.start == "zeros" else given
    if settings.start == "auto":
        trained = torch.tensor([JOINTS[j] for j in settings.policy_joints], device=given.device)
        own = (env.current_goal()["joint"][:, None] == trained).any(dim=1)
        start = torch.where(own[:, None, None], given, torch.zeros_like(given))
    z0 = torch.zeros(settings.horizon, *start.shape, device=start.device)
    z0[0] = start

    def loss_of(z: torch.Tensor) -> torch.Tensor:
        joints = predict(model, inputs, z)
        # the weighted sum of the goals' distances (constraint_loss's mean divides by an idle env's 0 weights)
        loss = (pseudo_huber(target_squared(joints, targets)) * targets.weights).sum(dim=1) \
            + landing_loss(joints, steps, env.floor_height) \
            - settings.prior * noise_prior(z.flatten(2)).mean(dim=0)
        if settings.skate > 0:
            seen = torch.cat((last, joints), dim=1)
            loss = loss + settings.skate * regularizers(seen, z, float(FPS), ("skate",))["skate"]
        return loss

    best = descend(z0, loss_of, settings.steps, settings.lr, bound, env_dim=1)[0][0]  # the first primitive executes
    # nothing to refine, or a non-finite policy action (the env's own check must see it): the policy's action
    keep = ~active | ~torch.isfinite(given).flatten(1).all(dim=1)
    refined = torch.where(keep[:, None, None], given, best)
    return refined.reshape(given.shape[0], -1)


def refining(env, act: Callable[[torch.Tensor], torch.Tensor], settings: RefineSettings
             ) -> Callable[[torch.Tensor], torch.Tensor]:
    """``act`` (obs -> action) followed by :func:`refine` on ``env``'s state: an evaluation's policy function."""
    settings.check()

    def refined(obs: torch.Tensor) -> torch.Tensor:
        return refine(env, act(obs), settings)

    return refined
