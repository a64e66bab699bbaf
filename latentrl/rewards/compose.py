"""Reward composition: the inputs an env fills, the config, and the weighted sum of terms.

An env builds one :class:`RewardInputs` per step (world joints of the 2 history frames before
the step followed by the 8 new frames, the goal in force, whether it was reached) and calls a
:class:`RewardComposer`, which returns the weighted total and every term **unweighted** (what
the env reports as ``infos["reward/<term>"]``).

Terms and DART's weights (README command; the kernels in :mod:`latentrl.rewards.terms` give
the formulas):

====================  =======  ====================================================================
name                  weight   term
====================  =======  ====================================================================
``dist``              1.0      goal-distance progress of the pelvis, metres per step
``success``           1.0      1 when the goal is reached during the step
``foot_floor``        100      -(lower foot's distance to the floor beyond 3 cm), x0.1 for hop/run
``skate``             100      -(contact-weighted foot displacement), metres per frame
``orient``            0.1      moving direction vs goal direction, in [0, 1] (per env, unlike DART)
``rotation``          10.0     -(1 - cos) of the hip-axis yaw change per frame
``jerk``              0        -(largest third difference of any joint), metres per frame^3
``prior``             0        -max(0, mean square of the action (latent noise) - 1): noise far from N(0, I)
``skill``             0        -(how far the step is from its text's skill rule: speed band, single support)
``heading``           1.0      pelvis motion along the commanded heading, in [0, 1] (Joystick)
``speed``             1.0      -|pelvis speed - commanded speed|, m/s (Joystick)
``pace``              1.0      -|speed toward the waypoint - the speed that arrives on time|, m/s (TimedPath)
``timing``            1.0      on reaching a waypoint, 1 - |arrival error| / tolerance, in [0, 1] (TimedPath)
``collision``         0        -(joints' depth inside their skin radius of an object), metres (scenes)
``terrain_contact``   0        -(lower foot's distance to the terrain beyond 3 cm), x0.1 hop/run (scenes)
``clearance``         0        -(nearest joint's depth inside 0.25 m beyond its skin of an object), metres (scenes)
``joint_dist``        1.0      the goal joint's progress toward its target, metres per step (ReachJoint)
``joint_arrival``     5.0      at the goal time, exp(-joint error / 0.1 m), in [0, 1] (ReachJoint)
``pelvis_height``     1.0      -|pelvis z - the task's pelvis height target|, metres, mean over the new frames (Sit)
====================  =======  ====================================================================

Each task computes and reports only its own terms (``terms=`` of :class:`RewardComposer`; the envs'
``reward_terms``): ReachLocation and FollowPath the seven of :data:`DART_TERMS`, Joystick and TimedPath
theirs. The task terms read the extra inputs their env fills (:attr:`RewardInputs.command` ...).

Every term is one entry of :data:`REWARD_TERMS` (name -> kernel adapter, default weight, the task inputs
it reads), made by decorating its adapter with :func:`reward_term`; the table above lists them.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import torch

from latentrl.config import is_finite_number, require
from latentrl.constants import CONTACT_HEIGHT_M
from latentrl.errors import closest
from latentrl.motion.representation import HISTORY_LENGTH
from latentrl.motion.skeleton import FPS, PELVIS
from latentrl.rewards import terms
from latentrl.rewards.skills import SKILLS, skill_code
from latentrl.scenes.scene import SceneBatch

#: DART's terms (ReachLocation and FollowPath compute these), in reporting order.
DART_TERMS: tuple[str, ...] = ("dist", "success", "foot_floor", "skate", "orient", "rotation", "jerk")

#: Terms every task computes besides its own (weight 0 unless a config sets one).
COMMON_TERMS: tuple[str, ...] = ("prior", "skill")

#: Terms an env computes when it has a scene (docs/scenes.md; weight 0 unless a config sets one).
SCENE_TERMS: tuple[str, ...] = ("collision", "terrain_contact", "clearance")

@dataclass
class RewardInputs:
    """What one env step hands to the reward terms (all world coordinates, metres, z up)."""

    joints_world: torch.Tensor
    """(N, H + F, 22, 3): the H history frames before the step, then the F new frames."""
    goal_world: torch.Tensor
    """(N, 3) the goal in force during the step (before any resampling on success)."""
    reached: torch.Tensor
    """(N,) bool: the goal was reached during the step."""
    floor_scale: torch.Tensor
    """(N,) multiplier of ``foot_floor`` from each env's text (see :meth:`RewardComposer.floor_scales`)."""
    floor_height: float = 0.0
    """Floor z, metres."""
    history_length: int = HISTORY_LENGTH
    """H: how many leading frames of ``joints_world`` precede the step."""
    command: torch.Tensor | None = None
    """Joystick: (N, 3) the command in force, world unit heading (x, y) and speed (m/s)."""
    target_speed: torch.Tensor | None = None
    """TimedPath: (N,) speed toward the goal that arrives on time (distance left / time left), m/s."""
    arrival_error: torch.Tensor | None = None
    """TimedPath: (N,) arrival time - goal time of the waypoint reached in the step, seconds (0 elsewhere)."""
    actions: torch.Tensor | None = None
    """(N, D) the step's action (latent noise) after clamping to the action bound."""
    skill: torch.Tensor | None = None
    """(N,) long: each env's text as a skill code (:func:`latentrl.rewards.skills.skill_code`)."""
    scene: SceneBatch | None = None
    """The env's scenes (N rows or one), for the scene terms."""
    joint_error: torch.Tensor | None = None
    """ReachJoint: (N, 3) the goal joint's distance to its target (m) at the last frame before the step, at the
    step's last frame (the goal-time frame when that is in the step) and at the goal-time frame (NaN elsewhere)."""
    pelvis_target: torch.Tensor | None = None
    """Sit: (N,) the world z the pelvis should be at during the step (seated or standing), NaN where there is none."""

    _sdf: torch.Tensor | None = field(default=None, init=False, repr=False)
    _feet_ground: torch.Tensor | None = field(default=None, init=False, repr=False)

    def new_frames_sdf(self) -> torch.Tensor:
        """(N, F, 22) each new frame's joints' distance to the scene, computed once per step for the scene terms.

        (A plain cached field, not ``functools.cached_property``, whose lock the compiled env step cannot trace.)
        """
        if self._sdf is None:
            self._sdf = self.need("scene", "collision or clearance").sdf(self.joints_world[:, self.history_length :])
        return self._sdf

    def feet_ground(self) -> torch.Tensor | float:
        """The ground under the feet of the last history frame and the new frames, for the foot terms.

        With a scene: (N, F + 1, 2) terrain heights, one query per step shared by ``foot_floor``, ``skate``,
        ``skill`` and ``terrain_contact`` (a tread or a box top carries the foot; where nothing is underfoot the
        terrain is the floor height itself, so the terms equal the flat floor's there). Without one: the floor
        height.
        """
        if self.scene is None:
            return self.floor_height
        if self._feet_ground is None:
            feet = terms.foot_joints(self.joints_world[:, self.history_length - 1 :])
            self._feet_ground = self.scene.height(feet[..., :2])
        return self._feet_ground

    def new_feet_heights(self) -> torch.Tensor:
        """(N, F, 2) each new frame's foot joints' height over the ground under them (:meth:`feet_ground`)."""
        ground = self.feet_ground()
        z = terms.foot_joints(self.joints_world[:, self.history_length :])[..., 2]
        return z - (ground if isinstance(ground, float) else ground[:, 1:])

    def step_seconds(self) -> float:
        """Duration of the step: its new frames / 30 (8 frames = 0.267 s)."""
        return (self.joints_world.shape[1] - self.history_length) / FPS

    def need(self, name: str, term: str) -> torch.Tensor:
        """The task input ``name``, or a ValueError naming the term that needs it."""
        value = getattr(self, name)
        if value is None:
            raise ValueError(f"reward term '{term}' needs RewardInputs.{name}, which this task does not fill; "
                             f"drop '{term}' from the task's reward terms")
        return value

    def pelvis_before_after(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(N, 3) pelvis at the last history frame before the step, and at the last new frame."""
        return self.joints_world[:, self.history_length - 1, PELVIS], self.joints_world[:, -1, PELVIS]


@dataclass
class RewardConfig:
    """Reward weights and thresholds (YAML section ``env.rewards``)."""

    weights: dict[str, float] = field(default_factory=lambda: dict(DEFAULT_WEIGHTS))
    """Weight per term name; names left out keep their default (:data:`DEFAULT_WEIGHTS`)."""
    contact_threshold: float = CONTACT_HEIGHT_M
    """Foot height above the floor, metres, within which a foot counts as touching it
    (``foot_floor`` tolerance and ``skate`` ramp; DART's ``foot_floor_thresh``)."""
    floor_scale_words: tuple[str, ...] = ("hop", "run")
    """Texts containing one of these substrings get ``foot_floor`` multiplied by ``floor_scale``
    (once per matching word, as DART does)."""
    floor_scale: float = 0.1
    """The multiplier for those texts."""
    timing_tolerance: float = 1.0
    """TimedPath's ``timing`` bonus falls linearly from 1 (on time) to 0 at this arrival error, seconds."""
    skill_scale: dict[str, float] = field(default_factory=dict)
    """Multiplier of the ``skill`` term per judged family (:data:`latentrl.rewards.skills.SKILLS`), e.g.
    ``{hop_left: 10}``; families left out keep 1. The hop penalty is a share of frames (at most ~1.4 a step)
    while walk and run pay in m/s, so a multi-skill policy can need a larger weight on its hops alone."""

    def skill_multipliers(self) -> tuple[float, ...]:
        """The ``skill`` term's multiplier per judged family, in the order of ``skills.SKILLS``."""
        return tuple(float(self.skill_scale.get(name, 1.0)) for name in SKILLS)

    def validate(self) -> None:
        """Unknown term names, non-finite weights and negative thresholds are errors."""
        for name, weight in self.weights.items():
            require(
                name in REWARD_TERMS,
                "weights",
                f"unknown reward term '{name}'{closest(name, tuple(REWARD_TERMS))}; known terms: "
                f"{', '.join(REWARD_TERMS)}",
            )
            require(
                isinstance(weight, (int, float)) and math.isfinite(weight),
                f"weights.{name}",
                f"must be a finite number, got {weight!r}",
            )
        require(isinstance(self.timing_tolerance, (int, float)) and math.isfinite(self.timing_tolerance)
                and self.timing_tolerance > 0, "timing_tolerance",
                f"must be a finite number of seconds > 0, got {self.timing_tolerance!r}")
        for name, scale in self.skill_scale.items():
            require(name in SKILLS, "skill_scale",
                    f"unknown skill family '{name}'{closest(name, SKILLS)}; known: {', '.join(SKILLS)}")
            require(is_finite_number(scale) and scale >= 0, f"skill_scale.{name}",
                    f"must be a finite number >= 0, got {scale!r}")
        for name in ("contact_threshold", "floor_scale"):
            value = getattr(self, name)
            require(
                isinstance(value, (int, float)) and math.isfinite(value) and value >= 0,
                name,
                f"must be a finite number >= 0, got {value!r}",
            )


class RewardTerm(NamedTuple):
    """A reward term: ``compute(inputs, config)`` returns the (N,) unweighted value.

    ``weight`` is its default weight in :data:`REWARD_TERMS` and the weight in use in a
    :class:`RewardComposer`; ``inputs`` names the optional :class:`RewardInputs` fields it reads (a task
    that computes it must fill them).
    """

    name: str
    weight: float
    compute: Callable[[RewardInputs, RewardConfig], torch.Tensor]
    inputs: tuple[str, ...] = ()


REWARD_TERMS: dict[str, RewardTerm] = {}
"""The reward-term registry: name -> kernel, default weight and inputs, in reporting order."""


def reward_term(name: str, weight: float, inputs: tuple[str, ...] = ()) -> Callable:
    """Register the decorated ``(RewardInputs, RewardConfig) -> (N,)`` function as the reward term ``name``."""

    def add(compute: Callable[[RewardInputs, RewardConfig], torch.Tensor]) -> Callable:
        REWARD_TERMS[name] = RewardTerm(name, float(weight), compute, tuple(inputs))
        return compute

    return add


@reward_term("dist", 1.0)
def _dist(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
    """:func:`terms.goal_progress` from the pelvis before the step to the pelvis after it."""
    return terms.goal_progress(*x.pelvis_before_after(), x.goal_world)


@reward_term("success", 1.0)
def _success(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
    """:func:`terms.success` of the env's reached mask."""
    return terms.success(x.reached)


@reward_term("foot_floor", 100.0)
def _foot_floor(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
    """:func:`terms.foot_floor` over the new frames, scaled per text, against the terrain under each foot."""
    return terms.foot_floor(x.new_feet_heights(), 0.0, cfg.contact_threshold, x.floor_scale)


@reward_term("skate", 100.0)
def _skate(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
    """:func:`terms.foot_skate` from the last history frame through the new frames, heights over the terrain."""
    feet = terms.foot_joints(x.joints_world[:, x.history_length - 1 :])
    return terms.foot_skate(feet, x.feet_ground(), cfg.contact_threshold)


@reward_term("orient", 0.1)
def _orient(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
    """:func:`terms.moving_orientation` of the step's pelvis displacement."""
    return terms.moving_orientation(*x.pelvis_before_after(), x.goal_world)


@reward_term("rotation", 10.0)
def _rotation(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
    """:func:`terms.yaw_rate` from the last history frame through the new frames."""
    return terms.yaw_rate(x.joints_world[:, x.history_length - 1 :])


@reward_term("jerk", 0.0)
def _jerk(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
    """:func:`terms.jerk` over the history and new frames."""
    return terms.jerk(x.joints_world)


@reward_term("heading", 1.0, inputs=('command',))
def _heading(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
    """:func:`terms.heading_tracking` of the step's pelvis displacement against the commanded heading."""
    return terms.heading_tracking(*x.pelvis_before_after(), x.command[:, :2])


@reward_term("speed", 1.0, inputs=('command',))
def _speed(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
    """:func:`terms.speed_tracking` of the step's mean pelvis speed against the commanded speed."""
    return terms.speed_tracking(*x.pelvis_before_after(), x.command[:, 2], x.step_seconds())


@reward_term("pace", 1.0, inputs=('target_speed',))
def _pace(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
    """:func:`terms.pace_tracking` toward the goal at the env's on-time speed."""
    return terms.pace_tracking(*x.pelvis_before_after(), x.goal_world, x.target_speed,
                               x.step_seconds())


@reward_term("timing", 1.0, inputs=('arrival_error',))
def _timing(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
    """:func:`terms.arrival_timing` of the waypoint reached in the step."""
    return terms.arrival_timing(x.reached, x.arrival_error, cfg.timing_tolerance)


@reward_term("prior", 0.0, inputs=('actions',))
def _prior(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
    """:func:`terms.noise_prior` of the step's action."""
    return terms.noise_prior(x.actions)


@reward_term("skill", 0.0, inputs=('skill',))
def _skill(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
    """:func:`terms.skill_fidelity` of the step against its text's skill rule (the evaluation's contact height)."""
    return terms.skill_fidelity(*x.pelvis_before_after(), x.new_feet_heights(), x.skill, x.step_seconds(),
                                scale=cfg.skill_multipliers() if cfg.skill_scale else None)


@reward_term("joint_dist", 1.0, inputs=('joint_error',))
def _joint_dist(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
    """:func:`terms.joint_progress` of the goal joint toward its target (ReachJoint)."""
    return terms.joint_progress(x.joint_error[:, 0], x.joint_error[:, 1])


@reward_term("joint_arrival", 5.0, inputs=('joint_error',))
def _joint_arrival(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
    """:func:`terms.joint_arrival` at the goal time (ReachJoint)."""
    return terms.joint_arrival(x.joint_error[:, 2])


@reward_term("pelvis_height", 1.0, inputs=('pelvis_target',))
def _pelvis_height(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
    """-(mean |pelvis z - target| over the new frames) where the task sets a target (Sit), 0 where it does not."""
    target = x.pelvis_target
    error = (x.joints_world[:, x.history_length:, PELVIS, 2] - target[:, None]).abs().mean(dim=1)
    return torch.where(torch.isfinite(target), -error, torch.zeros_like(error))


@reward_term("collision", 0.0, inputs=('scene',))
def _collision(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
    """:func:`terms.collision` over the new frames."""
    return terms.collision(x.joints_world[:, x.history_length :], x.scene, x.new_frames_sdf())


@reward_term("terrain_contact", 0.0, inputs=('scene',))
def _terrain_contact(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
    """:func:`terms.terrain_contact` over the new frames, scaled per text, from the step's shared terrain query.

    The same values as the kernel (``-contact_cost``); with a scene ``foot_floor`` measures the same gap.
    """
    return terms.foot_floor(x.new_feet_heights(), 0.0, cfg.contact_threshold, x.floor_scale)


@reward_term("clearance", 0.0, inputs=('scene',))
def _clearance(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
    """:func:`terms.clearance` over the new frames."""
    return terms.clearance(x.joints_world[:, x.history_length :], x.scene, sdf=x.new_frames_sdf())


TERM_NAMES: tuple[str, ...] = tuple(REWARD_TERMS)
"""The shipped terms' names, in reporting order: DART's, the Joystick and TimedPath tasks', the common, the scenes'."""

DEFAULT_WEIGHTS: dict[str, float] = {name: term.weight for name, term in REWARD_TERMS.items()}
"""DART's README weights (``fixtext_repeat_floor100_hop10_skate100``), the task terms' (1 each), 0 for the common."""


class RewardComposer:
    """Weighted sum of a task's terms (DART's seven by default).

    Args:
        config: weights and thresholds (default: DART's).
        weights: extra per-term weight overrides applied on top of ``config.weights``.
        terms: the names the task computes and reports, a subset of :data:`TERM_NAMES`
            (default :data:`DART_TERMS`).

    Raises:
        ConfigError: an unknown term name (with a "did you mean"), a non-finite weight, a
            negative threshold, or an override in ``weights`` of a term the task does not compute.
    """

    def __init__(self, config: RewardConfig | None = None, weights: Mapping[str, float] | None = None,
                 terms: Sequence[str] = DART_TERMS):
        config = config or RewardConfig()
        defaults = {name: term.weight for name, term in REWARD_TERMS.items()}
        merged = {**defaults, **config.weights, **dict(weights or {})}
        config = dataclasses.replace(config, weights=merged, floor_scale_words=tuple(config.floor_scale_words))
        config.validate()
        for name in terms:
            require(name in REWARD_TERMS, "terms", f"unknown reward term '{name}'{closest(name, tuple(REWARD_TERMS))}")
        for name in weights or {}:  # explicit overrides of a term the task never computes are mistakes
            require(name in terms, "reward_weights",
                    f"the task has no reward term '{name}'{closest(name, tuple(terms))}; its terms: {', '.join(terms)}")
        self.config = config
        self.terms = tuple(REWARD_TERMS[name]._replace(weight=float(config.weights[name])) for name in terms)

    @property
    def weights(self) -> dict[str, float]:
        """Term name -> weight in use."""
        return {t.name: t.weight for t in self.terms}

    def floor_scales(self, texts: Sequence[str]) -> torch.Tensor:
        """(K,) ``foot_floor`` multiplier per text: ``floor_scale`` per matching word (DART's hop/run)."""
        cfg = self.config
        return torch.tensor(
            [cfg.floor_scale ** sum(w in t.lower() for w in cfg.floor_scale_words) for t in texts], dtype=torch.float32
        )

    @staticmethod
    def skill_codes(texts: Sequence[str]) -> torch.Tensor:
        """(K,) long :func:`~latentrl.rewards.skills.skill_code` per text (what the ``skill`` term judges)."""
        return torch.tensor([skill_code(t) for t in texts], dtype=torch.long)

    def __call__(self, inputs: RewardInputs) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """Returns ``(total (N,), {name: (N,) unweighted term})``, float32."""
        for t in self.terms:
            for name in t.inputs:
                inputs.need(name, t.name)
        values = {t.name: t.compute(inputs, self.config).float() for t in self.terms}
        total = torch.zeros_like(next(iter(values.values())))
        for t in self.terms:
            if t.weight != 0.0:
                total = total + t.weight * values[t.name]
        return total, values
