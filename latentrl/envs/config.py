"""``EnvConfig``: the ``env:`` section of a training config, and :func:`build`, the env it describes."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from latentrl.config import require
from latentrl.errors import ConfigError, closest
from latentrl.motion.text import prompt_problem
from latentrl.resources import packaged, task_file
from latentrl.rewards import TERM_NAMES

TASKS = ("reach", "path")


@dataclass
class EnvConfig:
    """Which environment to train in (see docs/envs.md for every argument)."""

    task: str = "reach"
    """'reach' (latentrl/ReachLocation-v0, DART's task) or 'path' (latentrl/FollowPath-v0)."""
    num_envs: int = 256
    """Environments stepped together (DART: 256)."""
    motion: str = "default"
    """Motion model: 'default', a latentrl model file, or a DART denoiser checkpoint."""
    texts: list[str] = field(default_factory=lambda: ["walk"])
    """Prompts; each episode draws one (DART: walk, run, hop on left leg; one policy per text)."""
    text_weights: list[float] | None = None
    """Sampling weight per text (default: uniform)."""
    max_episode_steps: int | None = None
    """Primitives per episode before truncation (default: 32 for reach, 256 for path)."""
    guidance_scale: float = 5.0
    """Classifier-free guidance of the motion model (DART: 5)."""
    action_bound: float = 4.0
    """Actions are clamped to +/- this inside the env."""
    random_initial_steps: bool = False
    """Randomize the first episode counters so truncations do not synchronize."""
    reward_weights: dict[str, float] = field(default_factory=dict)
    """Overrides of DART's reward weights, e.g. {skate: 100, foot_floor: 100, jerk: 0}."""
    goal_angle_deg: float = 60.0
    """reach: goals within +/- this angle of the body's forward axis."""
    goal_distance: list[float] = field(default_factory=lambda: [0.5, 5.0])
    """reach: goal distance range (m)."""
    paths: str | None = None
    """path: a DART path file; None draws random smooth paths each episode."""
    observe_next: bool = False
    """path: also observe the waypoint after the current one."""
    random_waypoints: int = 5
    """path: waypoints per random path."""
    text_per_waypoint: bool = False
    """path: random paths draw a new text per waypoint (mixed-skill paths)."""
    nonfinite_actions: str = "error"
    """'error' stops on NaN/inf actions; 'zero' replaces them and reports it."""

    def validate(self) -> None:
        require(self.task in TASKS, "task", f"expected one of {TASKS}, got '{self.task}'")
        require(self.num_envs >= 1, "num_envs", f"must be >= 1, got {self.num_envs}")
        require(len(self.texts) >= 1, "texts", "give at least one prompt")
        for problem in map(prompt_problem, self.texts):
            require(problem is None, "texts", str(problem))
        require(self.text_weights is None or len(self.text_weights) == len(self.texts), "text_weights",
                f"needs one weight per text ({len(self.texts)}), got {self.text_weights}")
        require(self.max_episode_steps is None or self.max_episode_steps >= 1, "max_episode_steps",
                f"must be >= 1, got {self.max_episode_steps}")
        require(len(self.goal_distance) == 2, "goal_distance", f"must be [min, max], got {self.goal_distance}")
        for name in self.reward_weights:
            require(name in TERM_NAMES, "reward_weights",
                    f"unknown reward term '{name}'{closest(name, TERM_NAMES)}; known: {', '.join(TERM_NAMES)}")


def resolve_task_file(path: str) -> Path:
    """A path file named relative to the working directory, to the package, or by suite name."""
    found = task_file(path)
    if found is None:
        raise ConfigError(f"path file not found: {path} (looked in {Path.cwd()} and {packaged()})")
    return found


def build(cfg: EnvConfig, device: str, motion=None, **extra):
    """The torch VectorEnv an ``EnvConfig`` describes (``motion`` may be a loaded model)."""
    from latentrl.envs.path import FollowPathEnv
    from latentrl.envs.reach import ReachLocationEnv

    common = dict(motion=motion if motion is not None else cfg.motion, texts=list(cfg.texts),
                  text_weights=cfg.text_weights, device=device, guidance_scale=cfg.guidance_scale,
                  action_bound=cfg.action_bound, random_initial_steps=cfg.random_initial_steps,
                  reward_weights=dict(cfg.reward_weights) or None, nonfinite_actions=cfg.nonfinite_actions)
    if cfg.max_episode_steps is not None:
        common["max_episode_steps"] = cfg.max_episode_steps
    common.update(extra)
    if cfg.task == "reach":
        return ReachLocationEnv(cfg.num_envs, goal_angle_deg=cfg.goal_angle_deg,
                                goal_distance=tuple(cfg.goal_distance), **common)
    paths = str(resolve_task_file(cfg.paths)) if cfg.paths else None
    return FollowPathEnv(cfg.num_envs, paths=paths, observe_next=cfg.observe_next,
                         random_waypoints=cfg.random_waypoints, text_per_waypoint=cfg.text_per_waypoint, **common)
