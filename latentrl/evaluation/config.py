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
from latentrl.constants import ACTION_BOUND, GUIDANCE_SCALE, SUCCESS_RADIUS_M
from latentrl.motion.rollout import LOCK_MIN_WEIGHT
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

    def validate(self) -> None:
        require(self.episodes >= 1, "episodes", f"must be >= 1, got {self.episodes}")
        require(self.max_steps >= 1, "max_steps", f"must be >= 1, got {self.max_steps}")


MAX_EPISODES = 1 << 16
"""Episodes per path, at most (they run in parallel, one env each)."""
MAX_EVAL_STEPS = 100_000
"""Step budget per episode, at most."""


def physical_memory() -> int | None:
    """Bytes of RAM of this machine, or None where the OS does not say."""
    import os

    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


@dataclass
class EvalSettings:
    """How an evaluation runs; stored in ``report.json`` under ``settings``."""

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
    guidance_scale: float = GUIDANCE_SCALE
    """Classifier-free guidance of the motion model (DART's ``guidance_param``); the policy's training value."""
    success_threshold: float = SUCCESS_RADIUS_M
    """Waypoint radius, metres (xy, pelvis); DART 0.3."""
    action_bound: float = ACTION_BOUND
    """Actions are clamped to +/- this inside the env; the policy's training value."""
    foot_lock: bool = False
    """Keep planted feet from sliding (docs/motion.md, "Foot lock"); the policy's training value."""
    foot_lock_min_weight: float = LOCK_MIN_WEIGHT
    """The contact weight from which the lock pins a foot fully; the policy's training value."""
    amp: str | None = None
    """Autocast dtype the motion model samples in ('bf16', 'fp16' or None = float32); the policy's training value."""
    next_at_last: str = "repeat"
    """What a path or timed policy's ``next_goal_*`` observes at the last waypoint (``env.path.next_at_last``,
    ``env.timed.next_at_last``); its training value."""

    def take_training_env(self, env_cfg: Any) -> None:
        """Step the motion as the policy's training env did: its guidance, action bound, foot lock and autocast.

        A path or timed policy also observes its last waypoint as in training (``next_at_last``).
        """
        self.guidance_scale = float(getattr(env_cfg, "guidance_scale", GUIDANCE_SCALE))
        self.action_bound = float(getattr(env_cfg, "action_bound", ACTION_BOUND))
        self.foot_lock = bool(getattr(env_cfg, "foot_lock", False))
        self.foot_lock_min_weight = float(getattr(env_cfg, "foot_lock_min_weight", LOCK_MIN_WEIGHT))
        self.next_at_last = str(getattr(env_cfg, "next_at_last", "repeat"))
        self.amp = getattr(env_cfg, "amp", None)

    def motion_kwargs(self) -> dict[str, Any]:
        """The env arguments that decide how the motion is stepped (what :meth:`take_training_env` sets)."""
        return {"guidance_scale": self.guidance_scale, "action_bound": self.action_bound, "foot_lock": self.foot_lock,
                "foot_lock_min_weight": self.foot_lock_min_weight, "amp": self.amp}

    def validate(self) -> None:
        require(self.episodes >= 1, "episodes", f"must be >= 1, got {self.episodes}")
        require(self.max_steps >= 1, "max_steps", f"must be >= 1, got {self.max_steps}")
        require(self.episodes <= MAX_EPISODES, "episodes",
                f"must be <= {MAX_EPISODES} (they run as one batch of envs), got {self.episodes}")
        require(self.max_steps <= MAX_EVAL_STEPS, "max_steps", f"must be <= {MAX_EVAL_STEPS}, got {self.max_steps}")
        require_seed(self.seed)
        need = self.memory_bytes()
        total = physical_memory()
        require(total is None or need <= total // 2, "episodes",
                f"{self.episodes} episodes x {self.max_steps} steps keep about {need / 2**30:.1f} GiB of motion; "
                f"this machine has {(total or 0) / 2**30:.1f} GiB; lower --episodes or --max-steps")
        require(self.success_threshold > 0, "success_threshold", f"must be > 0, got {self.success_threshold}")

    def memory_bytes(self) -> int:
        """Rough memory the per-episode records need: joints and features of every frame (float32)."""
        from latentrl.evaluation.results import frames_after

        return self.episodes * frames_after(self.max_steps) * (22 * 3 + 276) * 4

    @property
    def budget_s(self) -> float:
        """The reach time a failed episode gets: the frames of a full budget (seed frames included) / 30."""
        from latentrl.evaluation.results import frames_after

        return frames_after(self.max_steps) / FPS
