"""The composition root of a training run.

One ``TrainConfig`` (env + ppo + policy + eval sections), the env it describes, the evaluation
hook, and the bodies of ``latentrl train`` and ``latentrl quickstart``. This is the only module
(with :mod:`latentrl.cli` and :mod:`latentrl.bench`) that wires environments to trainers; ``ppo/`` never sees ``envs/``.

A YAML config holds values only::

    env:    {task: reach, num_envs: 64, texts: [walk]}
    ppo:    {total_steps: 200000, num_steps: 32, learning_rate: 3.0e-4}
    policy: {architecture: dart, latent_dim: 256}
    eval:   {paths: [tasks/paths/dart_demo_walk.json], episodes: 8, max_steps: 96}
"""

from __future__ import annotations

import argparse
import time
from dataclasses import dataclass, field
from pathlib import Path

import torch

from latentrl.config import load_config, require
from latentrl.errors import ConfigError, closest
from latentrl.motion.text import prompt_problem
from latentrl.ppo.config import PolicyConfig, PPOConfig
from latentrl.preflight import check_device, check_writable
from latentrl.rewards import TERM_NAMES

TASKS = ("reach", "path")
PACKAGE_ROOT = Path(__file__).resolve().parents[1]


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


@dataclass
class TrainConfig:
    """Everything ``latentrl train`` needs; YAML files in configs/ hold its values."""

    env: EnvConfig = field(default_factory=EnvConfig)
    ppo: PPOConfig = field(default_factory=PPOConfig)
    policy: PolicyConfig = field(default_factory=PolicyConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    threads: int = 2
    """torch CPU threads (0: torch's default)."""

    def validate(self) -> None:
        require(self.threads >= 0, "threads", f"must be >= 0 (0: torch's default), got {self.threads}")
        try:  # the batch must split into minibatches for this many envs
            self.ppo.plan(self.env.num_envs)
        except ConfigError as exc:
            raise ConfigError(f"ppo.{exc}") from None


def resolve_task_file(path: str) -> Path:
    """A path file named relative to the working directory or to the latentrl checkout."""
    p = Path(path).expanduser()
    for cand in (p, PACKAGE_ROOT / p):
        if cand.is_file():
            return cand
    raise ConfigError(f"path file not found: {path} (looked in {Path.cwd()} and {PACKAGE_ROOT})")


def load_motion(cfg: EnvConfig, device: str):
    from latentrl.motion import load_motion_model

    return load_motion_model(cfg.motion, device=device)


def make_env(cfg: EnvConfig, device: str, motion=None, **extra):
    """The torch VectorEnv an ``EnvConfig`` describes (``motion`` may be a loaded model)."""
    from latentrl.envs import FollowPathEnv, ReachLocationEnv

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


def motion_info(model) -> dict:
    """What checkpoints record of the motion model: source path and content hash."""
    return {"path": str(model.info.get("source")), "sha256": str(model.info.get("sha256"))}


def make_eval_hook(cfg: TrainConfig, motion, device: str):
    """The trainer's periodic evaluation: our path runner on ``cfg.eval.paths``, plus a track plot."""
    if cfg.ppo.eval_every <= 0:
        return None
    from latentrl.evaluation.runner import training_eval_hook

    files = [resolve_task_file(p) for p in cfg.eval.paths]
    return training_eval_hook(files, motion, cfg.env, cfg.eval, device=device)


def train_command(args: argparse.Namespace) -> int:
    """Body of ``latentrl train``."""
    overrides = list(args.set or [])
    if args.seed is not None:
        overrides.append(f"ppo.seed={args.seed}")
    if args.device is not None:
        overrides.append(f"ppo.device={args.device}")
    if args.total_steps is not None:
        overrides.append(f"ppo.total_steps={args.total_steps}")
    if args.resume:
        run_dir = Path(args.resume)
        cfg_path = run_dir / "config.yaml"
        if not cfg_path.is_file():
            raise ConfigError(f"--resume {run_dir}: no config.yaml there; is it a training run directory?")
        cfg = load_config(TrainConfig, cfg_path, overrides)
    else:
        if not args.config:
            raise ConfigError("give a CONFIG file (e.g. configs/quick.yaml) or --resume RUN_DIR")
        cfg = load_config(TrainConfig, args.config, overrides)
        name = Path(args.config).stem
        run_dir = Path(args.run_dir) if args.run_dir else Path("runs") / f"{name}-{time.strftime('%Y%m%d-%H%M%S')}"
        check_new_run(run_dir)
    result = run_training(cfg, run_dir, trainer=args.trainer, resume=bool(args.resume),
                          allow_motion_mismatch=args.allow_motion_mismatch, progress=not args.no_progress)
    print(f"trained {result.iterations} iterations ({result.env_steps} env steps) in {result.elapsed_s:.0f} s; "
          f"final policy: {result.final_checkpoint}")
    return 0


def check_new_run(run_dir: Path) -> None:
    """A fresh run must not start in a folder that holds another run (its checkpoints would mix with ours)."""
    from latentrl.ppo.checkpoint import FINAL, iteration_checkpoints

    if (run_dir / "config.yaml").is_file() or (run_dir / FINAL).is_file() or iteration_checkpoints(run_dir):
        raise ConfigError(f"--run-dir {run_dir} already holds a training run; continue it with --resume {run_dir} "
                          "or choose another --run-dir")


def run_training(cfg: TrainConfig, run_dir: Path, trainer: str = "native", resume: bool = False,
                 allow_motion_mismatch: bool = False, progress: bool = True):
    """Build env + hooks from ``cfg`` and train in ``run_dir``.

    Every input is checked (device, batch sizes, run directory, motion model, path files) before
    anything is written; :func:`latentrl.ppo.run.train` then checks the free disk space.
    """
    from latentrl.ppo.run import train

    if trainer not in ("native", "sb3"):
        raise ConfigError(f"--trainer must be 'native' or 'sb3', got '{trainer}'")
    device = str(check_device(cfg.ppo.device, "ppo.device"))
    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    cfg.ppo.plan(cfg.env.num_envs)  # batch sizes must fit before anything heavy happens
    run_dir = Path(run_dir)
    check_writable(run_dir, "run directory")
    motion = load_motion(cfg.env, device)
    env = make_env(cfg.env, device, motion=motion)
    venv = env
    if trainer == "sb3":
        from latentrl.envs import Sb3VecEnv

        venv = Sb3VecEnv(env)
    hook = make_eval_hook(cfg, motion, device)
    return train(venv, run_dir, cfg.ppo, cfg.policy, trainer=trainer, config=cfg, resume=resume,
                 motion=motion_info(motion), evaluate=hook, allow_motion_mismatch=allow_motion_mismatch,
                 progress=progress)


QUICK_CONFIG = PACKAGE_ROOT / "configs" / "quick.yaml"
QUICK_EVAL_PATHS = ("dart_demo_walk", "random_smooth")


def quickstart_command(args: argparse.Namespace) -> int:
    """Body of ``latentrl quickstart``: train ``configs/quick.yaml`` on the default model, then evaluate."""
    from latentrl.cli import build_parser
    from latentrl.evaluation.commands import check_eval_args, evaluate

    cfg = load_config(TrainConfig, QUICK_CONFIG, list(args.set or []))
    run_dir = Path(args.run_dir) if args.run_dir else Path("runs") / f"quickstart-{time.strftime('%Y%m%d-%H%M%S')}"
    check_new_run(run_dir)
    check_eval_args(args.episodes, args.max_steps, QUICK_EVAL_PATHS)  # before training, not after
    print(f"[quickstart] training configs/quick.yaml on the '{cfg.env.motion}' motion model in {run_dir}")
    result = run_training(cfg, run_dir, progress=not args.no_progress)
    print(f"[quickstart] trained {result.iterations} iterations ({result.env_steps} env steps) in "
          f"{result.elapsed_s:.0f} s; TensorBoard: tensorboard --logdir {run_dir}")
    eval_args = ["eval", str(result.final_checkpoint), "--paths", *QUICK_EVAL_PATHS, "--episodes",
                 str(args.episodes), "--max-steps", str(args.max_steps), "--motion", cfg.env.motion,
                 "--device", cfg.ppo.device, "--out", str(run_dir / "eval"), "--render", "1"]
    print(f"[quickstart] evaluating on {', '.join(QUICK_EVAL_PATHS)}: latentrl {' '.join(eval_args)}")
    code = evaluate(build_parser().parse_args(eval_args))
    print(f"[quickstart] done: report {run_dir / 'eval' / 'report.md'}, plot {run_dir / 'eval' / 'paths.png'}")
    return code
