"""``EnvConfig``: the ``env:`` section of a training config, and :func:`build`, the env it describes.

Settings every task shares sit at the top of the section; each task has its own sub-section
(``env.reach``, ``env.path``, ``env.joystick``, ``env.timed``) holding its constructor's arguments,
and a :class:`~latentrl.envs.tasks.TaskSpec` in :data:`~latentrl.envs.tasks.TASKS` (a task registered from outside
the package without a section here takes its arguments from ``env.options``)::

    env:
      task: path
      num_envs: 64
      texts: [walk]
      rewards: {weights: {skate: 100}, contact_threshold: 0.03}
      path: {observe_next: true, random_waypoints: 5}

Configs written before the sections existed named the task arguments at the top
(``env.observe_next``); :data:`ALIASES` maps those keys onto their sections.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

from latentrl.config import apply_aliases, require
from latentrl.constants import ACTION_BOUND, GUIDANCE_SCALE
from latentrl.envs.path import next_at_last_problem
from latentrl.envs.reach_joint import ReachJointConfig
from latentrl.envs.scene import HEIGHT_GRID_SPACING_M, height_grid_problem, resolve_scene
from latentrl.envs.settings import StepSettings
from latentrl.envs.tasks import TASKS, task_spec
from latentrl.errors import ConfigError, LatentRLError, closest
from latentrl.motion.rollout import LOCK_MIN_WEIGHT
from latentrl.motion.text import prompt_problem
from latentrl.resources import packaged, task_file
from latentrl.rewards import REWARD_TERMS, RewardConfig
from latentrl.scenes.courses import CoursePool

MAX_NUM_ENVS = 1 << 20
"""Parallel envs, at most (each holds a motion-model history on the device)."""


@dataclass
class ReachConfig:
    """``env.reach``: arguments of :class:`~latentrl.envs.ReachLocationEnv` (DART's reach task)."""

    goal_angle_deg: float = 60.0
    """Goals within +/- this angle of the body's forward axis."""
    goal_distance: list[float] = field(default_factory=lambda: [0.5, 5.0])
    """Goal distance range (m)."""

    def validate(self) -> None:
        """``goal_distance`` is a [min, max] pair."""
        require(len(self.goal_distance) == 2, "goal_distance", f"must be [min, max], got {self.goal_distance}")

    def kwargs(self) -> dict[str, Any]:
        """The constructor arguments of :class:`~latentrl.envs.ReachLocationEnv`."""
        return {"goal_angle_deg": self.goal_angle_deg, "goal_distance": tuple(self.goal_distance)}


@dataclass
class PathConfig:
    """``env.path``: arguments of :class:`~latentrl.envs.FollowPathEnv`."""

    paths: str | None = None
    """A DART path file (or suite name); None draws random smooth paths each episode."""
    observe_next: bool = False
    """Also observe the waypoint after the current one."""
    next_at_last: str = "repeat"
    """What ``observe_next`` shows at the last waypoint: "repeat" (the last waypoint again) or "extend" (a point
    one last-segment length beyond it, so the last goal looks like any straight stretch)."""
    random_waypoints: int = 5
    """Waypoints per random path."""
    text_per_waypoint: bool = False
    """Random paths draw a new text per waypoint (mixed-skill paths)."""
    random_segment: list[float] = field(default_factory=lambda: [1.0, 3.0])
    """Random segment lengths, uniform in [min, max] metres (mixed skills want room for each skill to settle)."""
    random_turn_deg: float = 45.0
    """Each random segment turns by up to +/- this many degrees."""

    def validate(self) -> None:
        """Segment range, turn, waypoint count and ``next_at_last`` in range."""
        require(len(self.random_segment) == 2 and 0 < self.random_segment[0] <= self.random_segment[1],
                "random_segment", f"must be [min, max] metres with 0 < min <= max, got {self.random_segment}")
        require(0 <= self.random_turn_deg <= 180, "random_turn_deg",
                f"must be degrees in [0, 180], got {self.random_turn_deg}")
        require(self.random_waypoints >= 1, "random_waypoints", f"must be >= 1, got {self.random_waypoints}")
        problem = next_at_last_problem(self.next_at_last)
        require(problem is None, "next_at_last", str(problem))

    def kwargs(self) -> dict[str, Any]:
        """The constructor arguments of :class:`~latentrl.envs.FollowPathEnv` (file names resolved)."""
        paths = str(resolve_task_file(self.paths)) if self.paths else None
        return {"paths": paths, "observe_next": self.observe_next, "next_at_last": self.next_at_last,
                "random_waypoints": self.random_waypoints,
                "text_per_waypoint": self.text_per_waypoint, "random_segment": tuple(self.random_segment),
                "random_turn_deg": self.random_turn_deg}


@dataclass
class JoystickConfig:
    """``env.joystick``: arguments of :class:`~latentrl.envs.JoystickEnv` (commanded heading and speed)."""

    speed_range: list[float] = field(default_factory=lambda: [0.7, 1.4])
    """Commanded speeds are drawn uniformly in [min, max] m/s; keep them plausible for the texts
    (the default model walks at about 0.85-1.2 m/s and runs at 3.2-4.2 m/s)."""
    heading_change_deg: float = 90.0
    """Each new command turns the heading by up to +/- this many degrees (the first, from the body's facing)."""
    heading_change_seconds: list[float] = field(default_factory=lambda: [2.0, 6.0])
    """Seconds between command changes, uniform in [min, max]."""
    commands: str | None = None
    """A command-timeline file (or suite name in tasks/joystick) to train on instead of random commands."""

    def validate(self) -> None:
        """Speed range, heading change and command durations in range."""
        require(len(self.speed_range) == 2 and 0 <= self.speed_range[0] <= self.speed_range[1], "speed_range",
                f"must be [min, max] m/s with 0 <= min <= max, got {self.speed_range}")
        require(0 <= self.heading_change_deg <= 180, "heading_change_deg",
                f"must be degrees in [0, 180], got {self.heading_change_deg}")
        require(len(self.heading_change_seconds) == 2 and 0 < self.heading_change_seconds[0]
                <= self.heading_change_seconds[1], "heading_change_seconds",
                f"must be [min, max] seconds with 0 < min <= max, got {self.heading_change_seconds}")

    def kwargs(self) -> dict[str, Any]:
        """The constructor arguments of :class:`~latentrl.envs.JoystickEnv` (file names resolved)."""
        commands = str(resolve_task_file(self.commands, "joystick")) if self.commands else None
        return {"speed_range": tuple(self.speed_range), "heading_change_deg": self.heading_change_deg,
                "heading_change_seconds": tuple(self.heading_change_seconds), "commands": commands}


@dataclass
class TimedConfig:
    """``env.timed``: arguments of :class:`~latentrl.envs.TimedPathEnv` (waypoints with arrival times)."""

    paths: str | None = None
    """A timed path file (or suite name in tasks/timed); None draws random timed paths each episode."""
    speed_range: list[float] = field(default_factory=lambda: [0.7, 1.4])
    """Random paths time each segment at a speed uniform in [min, max] m/s; max also caps the pace target."""
    observe_next: bool = False
    """Also observe the waypoint after the current one."""
    next_at_last: str = "repeat"
    """What ``observe_next`` shows at the last waypoint: "repeat" (the last waypoint again) or "extend" (a point
    one last-segment length beyond it, so the last goal looks like any straight stretch)."""
    random_waypoints: int = 5
    """Waypoints per random path."""
    text_per_waypoint: bool = False
    """Random paths draw a new text per waypoint."""
    time_left_clip: float = 10.0
    """The time-left observation is clipped to +/- this many seconds."""

    def validate(self) -> None:
        """Speed range, clip, waypoint count and ``next_at_last`` in range."""
        require(len(self.speed_range) == 2 and 0 < self.speed_range[0] <= self.speed_range[1], "speed_range",
                f"must be [min, max] m/s with 0 < min <= max, got {self.speed_range}")
        require(self.time_left_clip > 0, "time_left_clip", f"must be > 0 seconds, got {self.time_left_clip}")
        require(self.random_waypoints >= 1, "random_waypoints", f"must be >= 1, got {self.random_waypoints}")
        problem = next_at_last_problem(self.next_at_last)
        require(problem is None, "next_at_last", str(problem))

    def kwargs(self) -> dict[str, Any]:
        """The constructor arguments of :class:`~latentrl.envs.TimedPathEnv` (file names resolved)."""
        paths = str(resolve_task_file(self.paths, "timed")) if self.paths else None
        return {"paths": paths, "speed_range": tuple(self.speed_range), "observe_next": self.observe_next,
                "next_at_last": self.next_at_last, "random_waypoints": self.random_waypoints,
                "text_per_waypoint": self.text_per_waypoint,
                "time_left_clip": self.time_left_clip}


ALIASES: dict[str, str] = {
    "goal_angle_deg": "reach.goal_angle_deg",
    "goal_distance": "reach.goal_distance",
    "paths": "path.paths",
    "observe_next": "path.observe_next",
    "random_waypoints": "path.random_waypoints",
    "text_per_waypoint": "path.text_per_waypoint",
}
"""Keys of the flat ``env:`` section of earlier versions -> where they live now."""


@dataclass
class EnvConfig:
    """Which environment to train in (see docs/envs.md for every argument)."""

    task: str = "reach"
    """'reach' (latentrl/ReachLocation-v0, DART's task), 'path' (latentrl/FollowPath-v0), 'joystick'
    (latentrl/Joystick-v0), 'timed' (latentrl/TimedPath-v0), or a task registered with
    :func:`~latentrl.envs.tasks.register_task`."""
    num_envs: int = 256
    """Environments stepped together (DART: 256)."""
    motion: str = "default"
    """Motion model: 'default', a latentrl model file, or a DART denoiser checkpoint."""
    seed_history: str | None = None
    """Episode seed histories (.npz, docs/motion.md); default: the model's own (DART download: its mean pose)."""
    texts: list[str] = field(default_factory=lambda: ["walk"])
    """Prompts; each episode draws one (DART: walk, run, hop on left leg; one policy per text)."""
    text_weights: list[float] | None = None
    """Sampling weight per text (default: uniform)."""
    max_episode_steps: int | None = None
    """Primitives per episode before truncation (default: 32 for reach, 256 for path and timed, 75 for joystick)."""
    guidance_scale: float = GUIDANCE_SCALE
    """Classifier-free guidance of the motion model (DART: 5)."""
    action_bound: float = ACTION_BOUND
    """Actions are clamped to +/- this inside the env."""
    random_initial_steps: bool = False
    """Randomize the first episode counters so truncations do not synchronize."""
    reward_weights: dict[str, float] = field(default_factory=dict)
    """Overrides of DART's reward weights, e.g. {skate: 100, foot_floor: 100, jerk: 0}."""
    rewards: RewardConfig = field(default_factory=RewardConfig)
    """Reward weights and thresholds (``reward_weights`` overrides its weights)."""
    nonfinite_actions: str = "error"
    """'error' stops on NaN/inf actions; 'zero' replaces them and reports it."""
    compile: bool = False
    """Run each step's tensor maths (sampler, decode, placement, rewards) as one torch.compile graph."""
    amp: str | None = None
    """Sample the motion model under autocast: 'bf16' (CPUs with AVX-512 BF16, GPUs) or 'fp16' (CUDA); None = float32.
    Faster at large batches, outputs differ by ~1 % (docs/envs.md); evaluation samples as the policy trained."""
    foot_lock: bool = False
    """Keep planted feet from sliding: the body is shifted back under a foot on the floor, frame by frame
    (docs/motion.md, "Foot lock"). Off by default: most shipped policies were trained without it (docs/motion.md lists
    those that use it)."""
    foot_lock_min_weight: float = LOCK_MIN_WEIGHT
    """With ``foot_lock``: the summed contact weight (DART's skate ramp, 1 on the floor, 0 from 3 cm up) from which
    a foot is pinned fully; below it the correction scales with the weight. 0.05 pins any foot inside the 3 cm band
    (docs/motion.md)."""
    reach: ReachConfig = field(default_factory=ReachConfig)
    """Arguments of the reach task."""
    path: PathConfig = field(default_factory=PathConfig)
    """Arguments of the path task."""
    joystick: JoystickConfig = field(default_factory=JoystickConfig)
    """Arguments of the joystick task."""
    timed: TimedConfig = field(default_factory=TimedConfig)
    """Arguments of the timed-path task."""
    reach_joint: ReachJointConfig = field(default_factory=ReachJointConfig)
    """Arguments of the joint-goal task (docs/joint_goals.md)."""
    options: dict[str, Any] = field(default_factory=dict)
    """Arguments of a registered task that has no section of its own above (its spec's ``config`` fields)."""
    scene: Any = None
    """Objects in the world (docs/scenes.md): a ``latentrl.scene/1`` file (a path, or a name in tasks/scenes), or
    ``{random_obstacles: {count: [3, 8], ...}}`` drawn per episode, or a course pool, ``{random_mazes: {count: 256,
    ...}}`` or ``{random_stairs: {...}}`` (the path task: each episode walks a course of the pool along its route);
    None: the flat floor alone."""
    terminate_on_collision: bool = False
    """With a scene: end an episode when a joint comes inside its skin radius of an object."""
    observe_scene: bool = True
    """With a scene: observe it (``scene_rays``, and ``height_grid`` if set). False: the policy walks blind among the
    objects, which reach it only through the rewards, the end at a collision and a ``route`` guide's goal (a policy
    that follows routes without seeing what they go around; docs/scenes.md, "Routes")."""
    route: float | None = None
    """With a scene (reach, path, timed and joystick tasks; a joystick's goal is a point 3-6 m along its command):
    plan each goal's shortest route keeping this many metres (pelvis, xy)
    from every object and observe the farthest route point in clear sight as the goal where an object is in the
    way (:mod:`latentrl.envs.guide`; docs/scenes.md, "Routes"); None: the task's goal."""
    height_grid: int = 0
    """With a scene (``scene``, or a task's own such as sit's seat): also observe the terrain on a k x k grid around
    the pelvis (``scene_height_grid``, odd k in [3, 15]); 0: no grid."""
    height_grid_spacing: float = HEIGHT_GRID_SPACING_M
    """Metres between neighbouring samples of the height grid."""

    def validate(self) -> None:
        """Every field in range: a registered task (and its ``options``), sizes, step settings, texts, weights."""
        require(self.task in TASKS, "task", f"expected one of {tuple(TASKS)}, got '{self.task}'")
        require(not (self.options and self._has_section()), "options",
                f"task '{self.task}' takes its arguments from env.{self.task}, not env.options "
                f"(got {sorted(self.options)})")
        if not self._has_section():
            section = self.section
            if callable(getattr(section, "validate", None)):
                try:
                    section.validate()
                except ConfigError as exc:
                    raise ConfigError(f"options.{exc}") from None
        require(self.num_envs >= 1, "num_envs", f"must be >= 1, got {self.num_envs}")
        require(self.num_envs <= MAX_NUM_ENVS, "num_envs", f"must be <= {MAX_NUM_ENVS}, got {self.num_envs}")
        self.step_settings().validate()
        require(len(self.texts) >= 1, "texts", "give at least one prompt")
        for problem in map(prompt_problem, self.texts):
            require(problem is None, "texts", str(problem))
        require(self.text_weights is None or len(self.text_weights) == len(self.texts), "text_weights",
                f"needs one weight per text ({len(self.texts)}), got {self.text_weights}")
        require(self.max_episode_steps is None or self.max_episode_steps >= 1, "max_episode_steps",
                f"must be >= 1, got {self.max_episode_steps}")
        for name in self.reward_weights:
            require(name in REWARD_TERMS, "reward_weights", f"unknown reward term '{name}'"
                    f"{closest(name, tuple(REWARD_TERMS))}; known: {', '.join(REWARD_TERMS)}")
        require(self.scene is not None or not self.terminate_on_collision, "terminate_on_collision",
                "needs a scene (env.scene)")
        require(self.route is None or self.scene is not None, "route", "needs a scene (env.scene)")
        require(isinstance(self.observe_scene, bool), "observe_scene",
                f"expected true or false, got {self.observe_scene!r:.30}")
        require(self.observe_scene or self.scene is not None, "observe_scene", "false needs a scene (env.scene)")
        require(self.observe_scene or not self.height_grid, "height_grid",
                "is observed with the scene; env.observe_scene is false")
        require(self.route is None or (not isinstance(self.route, bool) and isinstance(self.route, (int, float))
                                       and 0 < self.route <= 2), "route",
                f"expected the route's clearance in metres, in (0, 2], or null, got {self.route!r:.30}")
        problem = height_grid_problem(self.height_grid, self.height_grid_spacing)
        if problem is not None:
            raise ConfigError(problem)
        if self.scene is not None:
            try:
                spec = self.scene_spec()
            except LatentRLError as exc:
                raise ConfigError(f"scene: {exc}" if not str(exc).startswith("scene") else str(exc)) from None
            if isinstance(spec, CoursePool):
                require(getattr(TASKS[self.task].env_class(), "walks_courses", False), "scene",
                        f"{spec.kind}: the env walks each course's route, which only the path task does (got task "
                        f"'{self.task}')")
                require(not getattr(self.section, "paths", None), "path.paths",
                        f"{spec.kind} brings its own paths (each course's route); leave path.paths unset")

    def scene_spec(self) -> Any:
        """The env's scene (:func:`latentrl.envs.scene.scene_spec`), a file name resolved; None without one."""
        return resolve_scene(self.scene)

    def step_settings(self) -> StepSettings:
        """How the env steps the motion (guidance, action bound, foot lock, autocast): the fields above."""
        return StepSettings.of(self)

    def _has_section(self) -> bool:
        return self.task in {f.name for f in fields(self)} and dataclasses.is_dataclass(getattr(self, self.task))

    @property
    def section(self) -> Any:
        """The task's arguments: its section (``env.<task>``), or its spec's ``config`` built from ``env.options``."""
        if self._has_section():
            return getattr(self, self.task)
        try:
            return task_spec(self.task).config_class()(**self.options)
        except TypeError as exc:
            raise ConfigError(f"options: {exc} (the arguments of task '{self.task}')") from None

    @property
    def observe_next(self) -> bool:
        """Whether the env observes the waypoint after the current one (tasks whose section has ``observe_next``)."""
        return bool(getattr(self.section, "observe_next", False))

    @property
    def next_at_last(self) -> str:
        """What ``next_goal_*`` shows at the last waypoint (tasks whose section has it; "repeat" for the others)."""
        return str(getattr(self.section, "next_at_last", "repeat"))


def resolve_task_file(path: str, kind: str = "paths") -> Path:
    """A task file named relative to the working directory, to the package, or by suite name in ``tasks/<kind>``."""
    found = task_file(path, kind)
    if found is None:
        raise ConfigError(f"path file not found: {path} (looked in {Path.cwd()} and {packaged()})")
    return found


def build(cfg: EnvConfig, device: str, motion=None, **extra):
    """The torch VectorEnv an ``EnvConfig`` describes (``motion`` may be a loaded model)."""
    common = dict(motion=motion if motion is not None else cfg.motion, texts=list(cfg.texts),
                  text_weights=cfg.text_weights, device=device, random_initial_steps=cfg.random_initial_steps,
                  reward_weights=dict(cfg.reward_weights) or None, reward_config=cfg.rewards,
                  nonfinite_actions=cfg.nonfinite_actions, compile=cfg.compile, **cfg.step_settings().step_kwargs())
    if cfg.max_episode_steps is not None:
        common["max_episode_steps"] = cfg.max_episode_steps
    if cfg.scene is not None:  # flat-floor envs get exactly the arguments they always had
        common.update(scene=cfg.scene_spec(), terminate_on_collision=cfg.terminate_on_collision)
        if not cfg.observe_scene:
            common.update(observe_scene=False)
        if cfg.route is not None:
            common.update(route=cfg.route)
    if cfg.height_grid:  # the env refuses it without a scene (env.scene, or a task's own such as sit's seat)
        common.update(height_grid=cfg.height_grid, height_grid_spacing=cfg.height_grid_spacing)
    common.update(extra)
    return task_spec(cfg.task).env_class()(cfg.num_envs, **cfg.section.kwargs(), **common)


def observes_scene(env: Mapping[str, Any] | None) -> bool:
    """Whether a policy trained with this stored ``env`` section observes its scene (``scene_rays``).

    It does when it was trained with a scene and without ``observe_scene: false``.
    """
    env = env or {}
    return env.get("scene") is not None and env.get("observe_scene", True) is not False


def stored_env_config(config: Mapping[str, Any] | None) -> EnvConfig | None:
    """The ``EnvConfig`` a run saved (in its checkpoints' ``config``), or None when it saved no ``env`` section."""
    env = (config or {}).get("env") if isinstance(config, Mapping) else None
    if not isinstance(env, Mapping):
        return None
    from latentrl.config import from_dict

    return from_dict(EnvConfig, apply_aliases(dict(env), ALIASES), "policy checkpoint: env")
