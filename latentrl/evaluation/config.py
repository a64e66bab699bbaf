"""``EvalConfig``: the ``eval:`` section of a training config (periodic evaluation during training)."""

from __future__ import annotations

from dataclasses import dataclass, field

from latentrl.config import require


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
