"""Stage 2's learned tracker: its config, its reference motions and its evaluation.

Training motions come from the frozen motion model (one rollout per prompt and seed, generated in memory
when a run starts, so nothing large is stored) or from motion files. The evaluation executes whole held-out
motions with the deterministic policy and reports what stage 2's target names: success (the share of motions
without a fall), MPJPE against the motion's joints (mm) and the root assist as percent of body weight.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from latentrl.config import require
from latentrl.errors import ConfigError
from latentrl.physics.tracker import FALL_DISTANCE_M
from latentrl.ppo.config import PolicyConfig, PPOConfig


@dataclass
class TrackingConfig:
    """The ``tracking:`` section of a tracker config (docs/physics.md, stage 2)."""

    motion_model: str = "default"
    """Motion model generating the references ('default' or a model file)."""
    texts: list[str] = field(default_factory=lambda: ["walk", "run", "hop"])
    """Prompts of the training motions (one motion per prompt and seed)."""
    seeds: list[int] = field(default_factory=lambda: [0, 1])
    """Noise seeds of the training motions."""
    eval_seeds: list[int] = field(default_factory=lambda: [100])
    """Seeds of the held-out evaluation motions (same prompts, seeds not in ``seeds``)."""
    seconds: float = 8.0
    """Length of each generated motion, seconds."""
    motion_files: list[str] = field(default_factory=list)
    """Motion .npz files to train on instead of generated motions (when not empty)."""
    eval_files: list[str] = field(default_factory=list)
    """Motion .npz files to evaluate on instead of generated held-out motions (when not empty)."""
    height: float = 1.72
    """Humanoid height, m."""
    num_envs: int = 16
    """Simulated characters stepped per env step."""
    episode_frames: int = 300
    """Frames after which an episode is truncated."""
    terminate_distance: float = 0.3
    """Mean joint distance to the reference (m) that ends an episode early."""
    action_scale: float = 0.5
    """Radians of residual PD target per unit action."""
    assist_hz: float = 2.0
    """Root assist natural frequency at full strength, Hz (0: no assist)."""
    assist_anneal_steps: int = 1_000_000
    """Env steps over which the assist falls linearly from full strength to ``assist_final`` (0: never)."""
    assist_final: float = 0.0
    """The assist's share of full strength after the anneal."""
    eval_assist: float = 0.0
    """The assist's share of full strength in evaluation (stage 2's target is measured without it)."""

    def validate(self) -> None:
        """One-line :class:`ConfigError` for the first bad field."""
        from latentrl.config import seed_problem
        from latentrl.motion.text import prompt_problem

        require(len(self.texts) > 0 or len(self.motion_files) > 0, "texts", "give at least one prompt")
        for t in self.texts:
            require(prompt_problem(t) is None, "texts", f"{prompt_problem(t)}")
        for s in [*self.seeds, *self.eval_seeds]:
            require(seed_problem(s) is None, "seeds", f"{seed_problem(s)}")
        shared = sorted(set(self.seeds) & set(self.eval_seeds))
        require(not shared, "eval_seeds", f"must differ from seeds (held-out motions), both hold {shared}")
        require(0.5 <= self.seconds <= 600, "seconds", f"must lie in [0.5, 600], got {self.seconds}")
        require(1.0 <= self.height <= 2.5, "height", f"must lie in [1.0, 2.5] m, got {self.height}")
        require(1 <= self.num_envs <= 1024, "num_envs", f"must lie in [1, 1024], got {self.num_envs}")
        require(self.episode_frames >= 2, "episode_frames", f"must be >= 2, got {self.episode_frames}")
        require(0 < self.terminate_distance <= 2.0, "terminate_distance",
                f"must lie in (0, 2] m, got {self.terminate_distance}")
        require(0 < self.action_scale <= 3.2, "action_scale", f"must lie in (0, 3.2] rad, got {self.action_scale}")
        require(0 <= self.assist_hz <= 50, "assist_hz", f"must lie in [0, 50] Hz, got {self.assist_hz}")
        require(self.assist_anneal_steps >= 0, "assist_anneal_steps", f"must be >= 0, got {self.assist_anneal_steps}")
        require(0 <= self.assist_final <= 1, "assist_final", f"must lie in [0, 1], got {self.assist_final}")
        require(0 <= self.eval_assist <= 1, "eval_assist", f"must lie in [0, 1], got {self.eval_assist}")


@dataclass
class TrackerTrainConfig:
    """A ``latentrl physics train-tracker`` config: ``tracking``, ``ppo`` and ``policy`` sections."""

    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    ppo: PPOConfig = field(default_factory=PPOConfig)
    policy: PolicyConfig = field(default_factory=PolicyConfig)


def generated_motions(cfg: TrackingConfig, seeds: list[int]) -> list[tuple[str, np.ndarray, np.ndarray, float]]:
    """(label, (T, 22, 3) joints, (T, 276) features, fps) of one motion-model rollout per prompt and seed."""
    import torch

    from latentrl.motion.checkpoint import load_motion_model

    model = load_motion_model(cfg.motion_model)
    steps = max(1, round(cfg.seconds * 30 / 8))
    out = []
    for text in cfg.texts:
        for seed in seeds:
            g = torch.Generator().manual_seed(int(seed))
            noise = torch.randn(steps, 1, *model.latent_shape, generator=g)
            roll = model.rollout([text] * steps, steps, noise=noise,
                                 state=model.initial_state(1, torch.Generator().manual_seed(int(seed))))
            out.append((f"{text} seed {seed}", roll.joints_world[0].double().numpy(),
                        roll.features_world[0].double().numpy(), 30.0))
    return out


def file_motions(paths: list[str]) -> list[tuple[str, np.ndarray, np.ndarray | None, float]]:
    """(label, joints, features or None, fps) of motion .npz files."""
    from latentrl.motion.clip import MotionClip

    out = []
    for p in paths:
        clip = MotionClip.load(p)
        if clip.frames < 2:
            raise ConfigError(f"tracking.motion_files: {p} has {clip.frames} frame(s); need at least 2")
        out.append((str(p), np.asarray(clip.joints, dtype=np.float64), clip.features, float(clip.fps)))
    return out


def build_motions(raw, humanoid):
    """:class:`~latentrl.physics.tracking_env.Motion` s of ``raw`` motions on ``humanoid``."""
    from latentrl.physics.reference import build_reference
    from latentrl.physics.tracking_env import Motion

    return [Motion.of(build_reference(j, f, fps, humanoid), humanoid) for _, j, f, fps in raw]


def training_motions(cfg: TrackingConfig, humanoid):
    """The training references: ``motion_files`` if given, else generated from ``texts`` x ``seeds``."""
    raw = file_motions(cfg.motion_files) if cfg.motion_files else generated_motions(cfg, cfg.seeds)
    return [label for label, *_ in raw], build_motions(raw, humanoid)


def evaluation_motions(cfg: TrackingConfig, humanoid):
    """The held-out references: ``eval_files`` if given, else generated from ``texts`` x ``eval_seeds``."""
    raw = file_motions(cfg.eval_files) if cfg.eval_files else generated_motions(cfg, cfg.eval_seeds)
    return [label for label, *_ in raw], build_motions(raw, humanoid)


def execute(char, motion, act: Callable[[np.ndarray], np.ndarray], assist_scale: float) -> dict:
    """Run ``motion`` from frame 0 to its end with ``act`` (observation -> action); falls as in stage 1.

    A fall (mean joint distance to the motion's joints above 0.5 m) is counted and the body put back on the
    reference there, as ``physics track`` does. Returns joints, falls and the mean assist force.
    """
    from latentrl.physics.tracking_env import joints_now

    char.reset_to(motion, 0)
    frames = motion.ref.frames
    joints = np.empty((frames, 22, 3))
    world = np.empty((frames, 22, 3, 3))
    soles = np.empty((frames, 4, 3))
    force = np.zeros(frames)
    falls: list[int] = []

    def record(t: int) -> None:
        joints[t], world[t], soles[t] = joints_now(char), char.sim.world_rotations(), char.sim.soles()

    record(0)
    for t in range(1, frames):
        force[t] = char.step(act(char.observe()), assist_scale)
        record(t)
        if not np.isfinite(joints[t]).all() or np.linalg.norm(joints[t] - motion.joints[t], axis=-1).mean() > \
                FALL_DISTANCE_M:
            falls.append(t)
            char.reset_to(motion, t)
            record(t)
    return {"joints": joints, "world": world, "soles": soles, "falls": falls, "assist_force": force,
            "assist_force_N": float(force[1:].mean()) if frames > 1 else 0.0}


def evaluate_tracker(humanoid, motions, labels, act, cfg: TrackingConfig, assist_scale: float) -> dict:
    """Success (share of motions with no fall), MPJPE mm, assist % body weight over ``motions``, and per motion."""
    from latentrl.physics.tracking_env import Character

    char = Character(humanoid, cfg.assist_hz, cfg.action_scale)
    per = []
    for label, m in zip(labels, motions, strict=True):
        r = execute(char, m, act, assist_scale)
        err = float(np.linalg.norm(r["joints"] - m.joints, axis=-1).mean() * 1000)
        per.append({"motion": label, "frames": m.ref.frames, "falls": len(r["falls"]), "mpjpe_mm": err,
                    "assist_percent_body_weight": 100.0 * r["assist_force_N"] / char.weight})
    return {"success": float(np.mean([p["falls"] == 0 for p in per])),
            "falls": int(sum(p["falls"] for p in per)),
            "mpjpe_mm": float(np.mean([p["mpjpe_mm"] for p in per])),
            "assist_percent_body_weight": float(np.mean([p["assist_percent_body_weight"] for p in per])),
            "assist_scale": float(assist_scale), "motions": per}
