"""How evaluations run: the ``eval:`` config section and the path runner's settings.

``EvalConfig`` is the ``eval:`` section of a training config (periodic evaluation during training);
:class:`EvalSettings` is what the path runner needs (``report.json`` records it).

The training hook builds the settings from the ``eval:`` and ``env:`` sections; ``latentrl eval``
from its flags and from the env config stored in the policy's checkpoint.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from latentrl.config import require, require_seed
from latentrl.constants import SUCCESS_RADIUS_M
from latentrl.envs.settings import StepSettings
from latentrl.memory import physical_memory
from latentrl.motion.rollout import lock_min_weight_problem
from latentrl.motion.skeleton import FPS


@dataclass
class EvalConfig:
    """Periodic evaluation during training (every ``ppo.eval_every`` iterations) on a small path set."""

    paths: list[str] = field(default_factory=lambda: ["tasks/paths/dart_demo_walk.json"])
    """Path files (DART's JSON format)."""
    episodes: int = 8
    """Episodes per path."""
    max_steps: int = 96
    """Step budget per episode (primitives); timeouts count as failures."""
    deterministic: bool = False
    """Use the policy mean instead of sampling (DART samples)."""
    text: str | None = None
    """Replace every waypoint's text (e.g. evaluate a 'run' policy on walk paths)."""
    success_target: float | None = None
    """Stop training once eval success reaches this (used by `bench train`)."""
    foot_lock_min_weight: float | None = None
    """With the env's foot lock: evaluations (these and ``latentrl eval`` of the checkpoints, which store it) pin
    a foot fully from this contact weight; None: the env's ``foot_lock_min_weight``. A card's figures taken with
    another value than training's are reproduced by the policy alone."""
    refine: int | None = None
    """ReachJoint policies: the optimizer steps ``latentrl eval`` of the checkpoints refines with by default (its
    ``--refine``; the card's figures); None: off. The trainer's periodic evaluation does not refine."""
    refine_horizon: int | None = None
    """With ``refine``: its ``--refine-horizon`` (None: 3)."""
    refine_skate: float | None = None
    """With ``refine``: its ``--refine-skate`` weight (None: 0)."""
    refine_start: str | None = None
    """With ``refine``: its ``--refine-start``, ``policy``, ``zeros`` or ``auto`` (None: policy). A policy whose
    goals are joints it was not trained on refines from zero noise better (docs/joint_goals.md); ``auto`` starts
    from the policy's action for the joints it was trained on and from zero noise for the others."""
    refine_pace: float | None = None
    """With ``refine``: its ``--refine-pace`` weight (None: 0.5)."""
    refine_land: int | None = None
    """With ``refine``: its ``--refine-land`` frames, a footstep's foot held down on its stone after its time
    (None: 0, 2 frames held in x and y)."""
    avoid: int | None = None
    """Evaluations among objects: the optimizer steps of the scene filter ``latentrl eval`` of the checkpoints
    applies by default (its ``--avoid``; the card's figures); None: off. The trainer's periodic evaluation does not
    filter."""
    avoid_horizon: int | None = None
    """With ``avoid``: its ``--avoid-horizon`` (None: 2)."""
    avoid_margin: float | None = None
    """With ``avoid``: its ``--avoid-margin``, metres (None: 0.1)."""
    avoid_samples: int | None = None
    """With ``avoid``: its ``--avoid-samples``, draws of the policy tried before the optimizer (None: 0)."""
    sit_plan: int | None = None
    """Sit policies: the optimizer steps of the planned sit ``latentrl eval`` of the checkpoints applies by default
    (its ``--sit-plan``; the card's figures); None: off. The trainer's periodic evaluation does not plan."""
    sit_plan_samples: int | None = None
    """With ``sit_plan``: its ``--sit-plan-samples``, plans drawn before the optimizer (None: 32)."""
    sit_plan_getup: int | None = None
    """With ``sit_plan``: its ``--sit-plan-getup``, primitives per plan of the stand-up and the walk away (None: 3;
    0: the policy's)."""
    sit_plan_approach: float | None = None
    """With ``sit_plan``: its ``--sit-plan-approach``, metres from the sit-down spot within which the approach's end
    is planned too (None or 0: the policy's approach)."""
    route: float | None = None
    """Reach and path policies among objects: the route guide's clearance, metres, that ``latentrl eval`` applies by
    default (its ``--route``; the card's figures); None: off. The trainer's periodic evaluation does not guide."""
    video_every: int = 1
    """Every this many evaluations (the first of each training process included), the first episode of the first
    suite entry goes to TensorBoard as ``eval/episode``: an animated GIF at 10 frames/s with the scene and goals;
    0: never."""
    video_size: int = 160
    """Width and height of that video in pixels (a multiple of 16, 64 to 640)."""

    def validate(self) -> None:
        """Episodes and step budget are >= 1; the foot lock's weight in range; the video's cadence and size."""
        require(self.episodes >= 1, "episodes", f"must be >= 1, got {self.episodes}")
        require(self.max_steps >= 1, "max_steps", f"must be >= 1, got {self.max_steps}")
        require(self.video_every >= 0, "video_every", f"must be >= 0 (0: no video), got {self.video_every}")
        require(self.video_size % 16 == 0 and 64 <= self.video_size <= MAX_VIDEO_SIZE, "video_size",
                f"must be a multiple of 16 from 64 to {MAX_VIDEO_SIZE}, got {self.video_size}")
        if self.foot_lock_min_weight is not None:
            problem = lock_min_weight_problem(self.foot_lock_min_weight)
            require(problem is None, "foot_lock_min_weight", str(problem))
        require(self.refine is None or 0 <= self.refine <= 1000, "refine",
                f"must be 0-1000 optimizer steps (or null: off), got {self.refine}")
        require(self.refine_horizon is None or 1 <= self.refine_horizon <= 16, "refine_horizon",
                f"must be 1-16 primitives (or null: 3), got {self.refine_horizon}")
        require(self.refine_skate is None or 0 <= self.refine_skate <= 1000, "refine_skate",
                f"must be a weight in [0, 1000] (or null: 0), got {self.refine_skate}")
        require(self.refine_pace is None or 0 <= self.refine_pace <= 1000, "refine_pace",
                f"must be a weight in [0, 1000] (or null: 0.5), got {self.refine_pace}")
        require(self.refine_land is None or 0 <= self.refine_land <= 16, "refine_land",
                f"must be 0-16 frames (or null: 0), got {self.refine_land}")
        require(self.refine_start in (None, "policy", "zeros", "auto"), "refine_start",
                f"must be policy, zeros or auto (or null: policy), got {self.refine_start!r:.40}")
        require(self.avoid is None or 0 <= self.avoid <= 1000, "avoid",
                f"must be 0-1000 optimizer steps (or null: off), got {self.avoid}")
        require(self.avoid_horizon is None or 1 <= self.avoid_horizon <= 16, "avoid_horizon",
                f"must be 1-16 primitives (or null: 2), got {self.avoid_horizon}")
        require(self.avoid_margin is None or 0 <= self.avoid_margin <= 1, "avoid_margin",
                f"must be metres in [0, 1] (or null: 0.1), got {self.avoid_margin}")
        require(self.avoid_samples is None or 0 <= self.avoid_samples <= 256, "avoid_samples",
                f"must be 0-256 draws (or null: 0), got {self.avoid_samples}")
        require(self.sit_plan is None or 0 <= self.sit_plan <= 1000, "sit_plan",
                f"must be 0-1000 optimizer steps (or null: off), got {self.sit_plan}")
        require(self.sit_plan_samples is None or 0 <= self.sit_plan_samples <= 1024, "sit_plan_samples",
                f"must be 0-1024 drawn plans (or null: 32), got {self.sit_plan_samples}")
        require(self.sit_plan_getup is None or 0 <= self.sit_plan_getup <= 32, "sit_plan_getup",
                f"must be 0-32 primitives (or null: 3), got {self.sit_plan_getup}")
        require(self.sit_plan_approach is None or 0 <= self.sit_plan_approach <= 5, "sit_plan_approach",
                f"must be metres in [0, 5] (or null: off), got {self.sit_plan_approach}")
        require(self.route is None or 0 <= self.route <= 2, "route",
                f"must be metres in [0, 2] (or null: off), got {self.route}")


MAX_VIDEO_SIZE = 640
"""Largest ``eval.video_size``: a bigger GIF every evaluation would swell the events file."""
MAX_EPISODES = 1 << 16
"""Episodes per path, at most (they run in parallel, one env each)."""
MAX_EVAL_STEPS = 100_000
"""Step budget per episode, at most."""


@dataclass
class EvalSettings(StepSettings):
    """How an evaluation runs; stored in ``report.json`` under ``settings``.

    The fields of :class:`~latentrl.envs.settings.StepSettings` (guidance, action bound, foot lock, autocast)
    come first: they are the policy's training values (:meth:`take_training_env`), so the eval env steps the
    motion as training did.
    """

    episodes: int = 32
    """Episodes per path, run in parallel as one batch (DART: 32 envs)."""
    max_steps: int = 256
    """Step budget per episode in primitives of 8 frames (DART's ``num_steps`` 256 = 68.3 s, enough for
    its longest walking path, 36 m, at half of DART's walking speed). Episodes still running are failures."""
    deterministic: bool = False
    """Use the policy's mean action instead of sampling (DART samples)."""
    seed: int = 0
    """Base seed; each path gets its own seed derived from it, the file stem and the path index."""
    device: str = "cpu"
    success_threshold: float = SUCCESS_RADIUS_M
    """Waypoint radius, metres (xy, pelvis); DART 0.3."""
    next_at_last: str = "repeat"
    """What a path or timed policy's ``next_goal_*`` observes at the last waypoint (``env.path.next_at_last``,
    ``env.timed.next_at_last``); its training value."""
    scene: Any = None
    """The eval env's scene (docs/scenes.md): the policy's training scene (``env.scene``) or ``eval --scene``;
    None: the flat floor."""
    observe_scene: bool = True
    """Whether the policy observes the scene (False: a policy trained without one, evaluated among objects, or
    trained blind among them: ``env.observe_scene: false``)."""
    height_grid: int = 0
    """The policy's local height grid (``env.height_grid``; 0: none), observed with the scene."""
    height_grid_spacing: float = 0.25
    """Its sample spacing, metres (``env.height_grid_spacing``)."""
    route: float | None = None
    """Among objects: the route guide's clearance, metres (``env.route``, ``eval --route``; None: off)."""

    def take_training_env(self, env_cfg: Any) -> None:
        """Step the motion as the policy's training env did (its :class:`StepSettings`; None: the defaults).

        A path or timed policy also observes its last waypoint as in training (``next_at_last``).
        """
        for name, value in StepSettings.of(env_cfg).step_kwargs().items():
            setattr(self, name, value)
        self.next_at_last = str(getattr(env_cfg, "next_at_last", "repeat"))
        self.scene = getattr(env_cfg, "scene", None)
        self.observe_scene = bool(getattr(env_cfg, "observe_scene", True))
        self.height_grid = int(getattr(env_cfg, "height_grid", 0) or 0)
        self.height_grid_spacing = float(getattr(env_cfg, "height_grid_spacing", 0.25))
        self.route = getattr(env_cfg, "route", None)

    def scene_kwargs(self, scene: Any) -> dict[str, Any]:
        """The eval env's scene arguments for ``scene`` (resolved; None: the flat floor, no arguments).

        The policy observes the scene (rays, and its height grid) only when it was trained with one
        (:attr:`observe_scene` and a training scene in :attr:`scene`); a flat-floor policy walks it blind.
        """
        if scene is None:
            return {}
        observe = bool(self.observe_scene and self.scene is not None)
        out: dict[str, Any] = {"scene": scene, "observe_scene": observe}
        if observe and self.height_grid:
            out.update(height_grid=self.height_grid, height_grid_spacing=self.height_grid_spacing)
        if self.route:
            out["route"] = self.route
        return out

    def take_eval_config(self, eval_cfg: Any) -> None:
        """The ``eval:`` section's deployment choices that differ from training (``foot_lock_min_weight``)."""
        weight = getattr(eval_cfg, "foot_lock_min_weight", None)
        if weight is not None:
            self.foot_lock_min_weight = float(weight)

    def motion_kwargs(self) -> dict[str, Any]:
        """The env arguments that decide how the motion is stepped (what :meth:`take_training_env` sets)."""
        return self.step_kwargs()

    def validate(self) -> None:
        """Episodes, budget, seed and memory in range, and the step settings (:meth:`StepSettings.validate`)."""
        require(self.episodes >= 1, "episodes", f"must be >= 1, got {self.episodes}")
        require(self.max_steps >= 1, "max_steps", f"must be >= 1, got {self.max_steps}")
        require(self.episodes <= MAX_EPISODES, "episodes",
                f"must be <= {MAX_EPISODES} (they run as one batch of envs), got {self.episodes}")
        require(self.max_steps <= MAX_EVAL_STEPS, "max_steps", f"must be <= {MAX_EVAL_STEPS}, got {self.max_steps}")
        require_seed(self.seed)
        need = self.memory_bytes()
        total = physical_memory()
        require(total is None or need <= total // 2, "episodes",
                f"{self.episodes} episodes x {self.max_steps} steps need about {need / 2**30:.1f} GiB (their envs "
                f"and motion); this machine has {(total or 0) / 2**30:.1f} GiB; lower --episodes or --max-steps")
        require(self.success_threshold > 0, "success_threshold", f"must be > 0, got {self.success_threshold}")
        super().validate()

    def memory_bytes(self) -> int:
        """Rough memory of the episodes: each one's env and the frames it records.

        An env is :data:`latentrl.memory.ENV_BYTES`; a frame's joints and features are float32.
        """
        from latentrl.evaluation.results import frames_after
        from latentrl.memory import ENV_BYTES

        return self.episodes * (frames_after(self.max_steps) * (22 * 3 + 276) * 4 + ENV_BYTES)

    @property
    def budget_s(self) -> float:
        """The reach time a failed episode gets: the frames of a full budget (seed frames included) / 30."""
        from latentrl.evaluation.results import frames_after

        return frames_after(self.max_steps) / FPS
