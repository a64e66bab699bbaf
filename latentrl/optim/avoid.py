"""A scene safety filter: the policy's noise, moved only as far as it takes to keep the body off the objects.

Why: a scene policy (``reach_obstacles_default``, ``path_maze_default``) learned to keep its distance by reward,
and a fifth of its maze episodes still graze a wall (docs/scenes.md); a reward can make a collision rare, not
impossible. Each env step, this predicts the next ``horizon`` primitives from the env's own state, placed exactly
as the env places them (``MotionModel.differentiable_step(post_process=True)``): the policy's noise first, zero
noise after it. Where no joint of that plan comes within its skin radius plus ``margin`` of an object, the
policy's action goes through untouched (most steps, and every step on a flat floor). Elsewhere a few Adam steps
move the first primitive's noise until the whole plan keeps out of that band, at a cost for leaving the policy's
noise (so the goal the policy walks to stays its goal); that noise is executed and the next step plans again:
a receding horizon, as model-predictive safety filters do. Only the envs at risk are optimized. The later
primitives stay at zero noise, not optimized: a plan free to dodge in its later primitives leaves the executed
one as it was, step after step, until no first primitive can dodge (a body walked at a pillar went through it).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import torch

from latentrl.errors import LatentRLError
from latentrl.motion.skeleton import JOINT_NAMES, PELVIS
from latentrl.optim.descent import descend
from latentrl.optim.refine import inputs_rows, predict, scene_rows
from latentrl.rewards.terms import noise_prior
from latentrl.scenes.contact import collision_cost, skin_radii

GROUND_JOINTS = ("left_ankle", "right_ankle", "left_foot", "right_foot")
"""Joints that touch the terrain (a tread, a seat's top): their band is the skin alone, never ``margin`` more."""


@dataclass
class AvoidSettings:
    """How the filter acts (``latentrl eval --avoid STEPS``; docs/scenes.md)."""

    steps: int = 16
    """Adam steps for an env whose predicted plan comes too close (0: off)."""
    horizon: int = 2
    """Primitives predicted (8 frames each); the first is executed."""
    margin: float = 0.1
    """Metres beyond each joint's skin radius that the plan must keep from every object (feet and ankles: 0)."""
    anchor: float = 0.1
    """Weight of the mean squared distance of the executed noise from the policy's."""
    weight: float = 100.0
    """Weight of the band violation (metres summed over joints, averaged over frames)."""
    lr: float = 0.3
    prior: float = 0.1
    """Weight of the noise-shell penalty (the ``prior`` reward term) of the executed noise."""
    samples: int = 0
    """Other draws of a stochastic policy tried first, in one batched prediction (0: none): of those whose plan
    keeps out of the band, the one whose pelvis ends nearest the policy's own plan's is executed; only envs where
    none does are optimized."""

    @classmethod
    def of(cls, steps: int, horizon: int | None = None, margin: float | None = None,
           samples: int | None = None) -> AvoidSettings:
        """The settings of these four, each None taking its default (flags, stored ones)."""
        chosen = {"horizon": horizon, "margin": margin, "samples": samples}
        return cls(steps=steps, **{k: v for k, v in chosen.items() if v is not None})

    def check(self) -> None:
        """One-line :class:`LatentRLError` for a value out of range."""
        if not 0 <= self.steps <= 1000:
            raise LatentRLError(f"avoid steps: expected 0-1000, got {self.steps}")
        if not 0 <= self.samples <= 256:
            raise LatentRLError(f"avoid samples: expected 0-256, got {self.samples}")
        if not 1 <= self.horizon <= 16:
            raise LatentRLError(f"avoid horizon: expected 1-16 primitives, got {self.horizon}")
        if not 0 <= self.margin <= 1:
            raise LatentRLError(f"avoid margin: expected metres in [0, 1], got {self.margin}")
        if not 0 < self.lr <= 10:
            raise LatentRLError(f"avoid lr: expected a learning rate in (0, 10], got {self.lr}")
        for name in ("anchor", "weight", "prior"):
            value = getattr(self, name)
            if not 0 <= value <= 1e6:
                raise LatentRLError(f"avoid {name}: expected a weight in [0, 1e6], got {value}")


def band(joints: torch.Tensor, margin: float) -> torch.Tensor:
    """(22,) each joint's keep-out distance: its skin radius plus ``margin`` (the feet and ankles: the skin)."""
    out = skin_radii(joints).clone()
    ground = torch.tensor([name in GROUND_JOINTS for name in JOINT_NAMES], device=joints.device)
    return torch.where(ground, out, out + margin)


def _safe_sample(model, inputs: dict, scene, keep: torch.Tensor, plan: torch.Tensor, tail: torch.Tensor,
                 draws: torch.Tensor, bound: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Of ``draws`` (K, R, 1, D) for R envs at risk, each env's safe draw ending nearest ``plan`` (R, T, 22, 3).

    Returns the (R, 1, D) chosen noises and an (R,) mask of envs with a safe draw. Why: another draw of the
    policy is an action it was trained to take (its pace and gait), where an optimized noise may leave its habits.
    """
    k, r = draws.shape[:2]
    rows = torch.arange(r, device=draws.device).repeat(k)
    inputs_k = inputs_rows(inputs, rows)
    scene_k = scene_rows(scene, rows)
    z = torch.cat((draws.clamp(-bound, bound).reshape(1, k * r, *draws.shape[2:]), tail[:, rows]), dim=0)
    with torch.no_grad():
        joints = predict(model, inputs_k, z)
        unsafe = (collision_cost(joints, scene_k, keep) > 0).reshape(k, r)
        miss = (joints[:, -1, PELVIS, :2] - plan[rows, -1, PELVIS, :2]).norm(dim=-1).reshape(k, r)
    miss = miss.masked_fill(unsafe, float("inf"))
    pick = miss.argmin(dim=0)
    chosen = draws[pick, torch.arange(r, device=draws.device)].clamp(-bound, bound)
    return chosen, ~unsafe.all(dim=0)


def avoid(env, action: torch.Tensor, settings: AvoidSettings,
          sampler: Callable[[int], torch.Tensor] | None = None) -> torch.Tensor:
    """The (N, D) noise to step ``env`` with: ``action``, or near it where its plan comes too close to an object.

    ``sampler(k)``: k more (k, N, D) draws of the policy for the same observation (``settings.samples``).
    """
    if settings.steps == 0 or getattr(env, "scene", None) is None:
        return action
    model = env.motion
    if not hasattr(model, "differentiable_step"):
        raise LatentRLError(f"avoid: the motion model {type(model).__name__} has no differentiable_step")
    n, bound = env.num_envs, float(env.action_bound)
    given = torch.as_tensor(action, device=env.device).detach().to(torch.float32)
    given = given.reshape(n, *model.latent_shape)
    finite = torch.isfinite(given).flatten(1).all(dim=1)  # a non-finite action goes through: the env's check sees it
    scene = env.scene.batch
    if not bool((scene.object_counts() > 0).any()):  # an empty scene (play before a box is dropped): nothing to avoid
        return action
    inputs = env.step_inputs()
    z = torch.zeros(settings.horizon, *given.shape, device=given.device)
    z[0] = given.clamp(-bound, bound)
    with torch.no_grad():
        plan = predict(model, inputs, z)
        keep = band(plan, settings.margin)
        risk = (collision_cost(plan, scene, keep) > 0) & finite
    if not bool(risk.any()):
        return action
    idx = risk.nonzero().squeeze(1)
    out = given.clone()
    if settings.samples and sampler is not None:
        draws = torch.as_tensor(sampler(settings.samples), device=given.device).detach().to(torch.float32)
        draws = draws.reshape(settings.samples, n, *model.latent_shape)[:, idx]
        chosen, found = _safe_sample(model, inputs_rows(inputs, idx), scene_rows(scene, idx), keep, plan[idx],
                                     z[1:, idx], draws, bound)
        out[idx[found]] = chosen[found]
        idx = idx[~found]
        if idx.numel() == 0:
            return out.reshape(n, -1)
    sub_inputs = inputs_rows(inputs, idx)
    sub_scene = scene_rows(scene, idx)
    policy, tail = z[0, idx].clone(), z[1:, idx]

    def loss_of(first: torch.Tensor) -> torch.Tensor:
        joints = predict(model, sub_inputs, torch.cat((first[None], tail), dim=0))
        return settings.weight * collision_cost(joints, sub_scene, keep) \
            + settings.anchor * (first - policy).flatten(1).square().mean(dim=1) \
            - settings.prior * noise_prior(first.flatten(1))

    best = descend(policy, loss_of, settings.steps, settings.lr, bound)[0]
    out[idx] = best
    return out.reshape(n, -1)


def draws(sample: Callable[[torch.Tensor], torch.Tensor], obs: torch.Tensor) -> Callable[[int], torch.Tensor]:
    """:func:`avoid`'s ``sampler``: ``k`` calls of a stochastic policy ``sample`` (obs -> action) on ``obs``."""
    return lambda k: torch.stack([sample(obs) for _ in range(k)])


def avoiding(env, act: Callable[[torch.Tensor], torch.Tensor], settings: AvoidSettings,
             sample: Callable[[torch.Tensor], torch.Tensor] | None = None) -> Callable[[torch.Tensor], torch.Tensor]:
    """``act`` (obs -> action) followed by :func:`avoid` on ``env``'s state: an evaluation's policy function.

    ``sample``: the policy drawing its actions (``settings.samples`` of them are tried first where a plan comes
    near an object); None: ``act``'s own calls.
    """
    settings.check()
    sample = act if sample is None else sample

    def filtered(obs: torch.Tensor) -> torch.Tensor:
        return avoid(env, act(obs), settings, draws(sample, obs))

    return filtered
