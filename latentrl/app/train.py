"""The composition root of a training run: ``latentrl train`` and ``latentrl quickstart``.

One ``TrainConfig`` (env + ppo + policy + eval sections), the env it describes, the evaluation
hook, and the command bodies. This package is the only place that wires environments to
trainers; ``ppo/`` never sees ``envs/``.

A YAML config holds values only::

    env:    {task: reach, num_envs: 64, texts: [walk]}
    ppo:    {total_steps: 200000, num_steps: 32, learning_rate: 3.0e-4}
    policy: {architecture: dart, latent_dim: 256}
    eval:   {paths: [tasks/paths/dart_demo_walk.json], episodes: 8, max_steps: 96}
"""

from __future__ import annotations

import dataclasses
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import ClassVar

import torch

import latentrl.evaluation.tasks  # noqa: F401  (attaches the shipped tasks' evaluators)
from latentrl.config import MAX_THREADS, load_config, require
from latentrl.envs.config import ALIASES as ENV_ALIASES
from latentrl.envs.config import EnvConfig, build
from latentrl.envs.tasks import task_spec
from latentrl.errors import ConfigError
from latentrl.evaluation.config import EvalConfig
from latentrl.ppo.config import PolicyConfig, PPOConfig
from latentrl.preflight import check_compile, check_device, check_writable
from latentrl.resources import config_file
from latentrl.timing import busy_machine_warning


@dataclass
class TrainConfig:
    """Everything ``latentrl train`` needs; YAML files in configs/ hold its values."""

    env: EnvConfig = field(default_factory=EnvConfig)
    ppo: PPOConfig = field(default_factory=PPOConfig)
    policy: PolicyConfig = field(default_factory=PolicyConfig)
    eval: EvalConfig = field(default_factory=EvalConfig)
    threads: int = 2
    """torch CPU threads (0: torch's default)."""

    ALIASES: ClassVar[dict[str, str]] = {f"env.{old}": f"env.{new}" for old, new in ENV_ALIASES.items()}
    """Keys of earlier versions (the flat ``env:`` section) -> where they live now."""

    def validate(self) -> None:
        """Threads in range, and the PPO batch splits into minibatches for ``env.num_envs`` envs."""
        require(0 <= self.threads <= MAX_THREADS, "threads",
                f"must lie in [0, {MAX_THREADS}] (0: torch's default), got {self.threads}")
        try:  # the batch must split into minibatches for this many envs
            self.ppo.plan(self.env.num_envs)
        except ConfigError as exc:
            raise ConfigError(f"ppo.{exc}") from None


@dataclass
class TrainRequest:
    """``latentrl train``: a config file (or a run to resume) and the flags that override it."""

    config: str | None = None
    overrides: list[str] = field(default_factory=list)
    trainer: str = "native"
    device: str | None = None
    seed: int | None = None
    total_steps: int | None = None
    run_dir: str | None = None
    resume: str | None = None
    allow_motion_mismatch: bool = False
    progress: bool = True
    nproc: int | None = None
    """Ranks on this machine: ``--nproc N`` (N > 1) relaunches the command under torchrun."""

    def argv(self) -> list[str]:
        """The ``latentrl train`` arguments of this request, without ``--nproc`` (what each rank runs)."""
        args = ["train"] + ([self.config] if self.config else [])
        for item in self.overrides:
            args += ["--set", item]
        options = (("--trainer", self.trainer), ("--device", self.device), ("--seed", self.seed),
                   ("--total-steps", self.total_steps), ("--run-dir", self.run_dir), ("--resume", self.resume))
        args += [str(x) for flag, value in options if value is not None for x in (flag, value)]
        args += ["--allow-motion-mismatch"] * self.allow_motion_mismatch + ["--no-progress"] * (not self.progress)
        return args


@dataclass
class QuickstartRequest:
    """``latentrl quickstart``: train ``configs/quick.yaml``, then evaluate the policy."""

    overrides: list[str] = field(default_factory=list)
    run_dir: str | None = None
    episodes: int = 8
    max_steps: int = 128
    progress: bool = True


QUICK_CONFIG = "quick"
QUICK_EVAL_PATHS = ("dart_demo_walk", "sharp_turns", "random_smooth")
"""Suites the quickstart may evaluate; it keeps those whose every prompt the policy was trained on."""


def trained_suites(suites: tuple[str, ...], texts: list[str] | tuple[str, ...]) -> list[str]:
    """The suites whose waypoints use only prompts in ``texts`` (a walk policy is not judged on hops)."""
    from latentrl.app.evaluate import resolve_path_files
    from latentrl.envs import load_paths

    known = set(texts)
    return [name for name, file in zip(suites, resolve_path_files(list(suites)))
            if all(set(p.texts) <= known for p in load_paths(file))]


def load_motion(cfg: EnvConfig, device: str):
    """The motion model of the config (``env.motion``, ``env.seed_history``) on ``device``."""
    from latentrl.motion import load_motion_model

    return load_motion_model(cfg.motion, device=device, seed_history=cfg.seed_history)


def motion_info(model) -> dict:
    """What checkpoints record of the motion model: source path and content hash."""
    return {"path": str(model.info.get("source")), "sha256": str(model.info.get("sha256"))}


def make_eval_hook(cfg: TrainConfig, motion, device: str):
    """The trainer's periodic evaluation: the evaluator of the task (``cfg.eval.paths`` or its first suite)."""
    if cfg.ppo.eval_every <= 0:
        return None
    spec = task_spec(cfg.env.task)
    if spec.evaluator is None:
        raise ConfigError(f"ppo.eval_every: task '{spec.name}' has no evaluator; set ppo.eval_every=0")
    files = spec.evaluator.training_files(cfg.eval.paths, spec.suites)
    return spec.evaluator.training_hook(files, motion, cfg.env, cfg.eval, device=device)


def load_train_config(config: str | Path, overrides: list[str] | tuple[str, ...] = ()) -> TrainConfig:
    """A ``TrainConfig`` from a file (or a packaged name such as ``quick``) and ``key=value`` overrides."""
    return load_config(TrainConfig, config_file(config), list(overrides))


def launch(req: TrainRequest) -> int:
    """``latentrl train --nproc N``: run this request on N ranks of this machine with torchrun (standalone)."""
    if req.trainer == "sb3":
        raise ConfigError(SB3_SINGLE)
    if not req.resume and not req.config:
        raise ConfigError("give a CONFIG file (e.g. configs/quick.yaml) or --resume RUN_DIR")
    from latentrl.ppo import distributed

    distributed.timeout_s()  # a malformed LATENTRL_DIST_TIMEOUT fails here, not in every rank
    if not req.resume:  # config and one run directory for all ranks, checked before any rank starts
        cfg = load_train_config(req.config, request_overrides(req))
        cfg.validate()
        if cfg.env.compile:
            check_compile(check_device(cfg.ppo.device, "ppo.device"), "env.compile")
        check_training_memory(cfg, check_device(cfg.ppo.device, "ppo.device"), ranks=req.nproc)
        req = dataclasses.replace(req, run_dir=str(default_run_dir(req)))
        check_new_run(Path(req.run_dir))
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc-per-node", str(req.nproc),
           "-m", "latentrl", *req.argv()]
    print(f"launching {req.nproc} ranks: {' '.join(cmd[1:])}", flush=True)
    code, output = distributed.run_torchrun(cmd)  # Ctrl-C, SIGTERM or SIGHUP: the ranks save one iteration
    if code:
        run_dir = Path(req.resume or req.run_dir)
        cause = output.cause() or f"a rank failed (torchrun exit {code})"
        resume = (f"; continue the run with: latentrl train --resume {run_dir} --nproc {req.nproc}"
                  if (run_dir / "config.yaml").is_file() else "")
        print(f"latentrl: error: {cause}; torchrun stopped the other ranks{resume}", file=sys.stderr, flush=True)
    return code


SB3_SINGLE = ("trainer 'sb3' runs in one process only; use --trainer native for torchrun / --nproc, "
              "or run sb3 without them")


def default_run_dir(req: TrainRequest) -> Path:
    """``--run-dir``, else ``runs/<config name>-<time>``."""
    if req.run_dir:
        return Path(req.run_dir)
    return Path("runs") / f"{Path(req.config).stem}-{time.strftime('%Y%m%d-%H%M%S')}"


def request_overrides(req: TrainRequest) -> list[str]:
    """``--set`` items plus what ``--seed``, ``--device`` and ``--total-steps`` set."""
    overrides = list(req.overrides)
    if req.seed is not None:
        overrides.append(f"ppo.seed={req.seed}")
    if req.device is not None:
        overrides.append(f"ppo.device={req.device}")
    if req.total_steps is not None:
        overrides.append(f"ppo.total_steps={req.total_steps}")
    return overrides


def train(req: TrainRequest) -> int:
    """Body of ``latentrl train`` (one rank of it under torchrun; ``--nproc N`` launches torchrun)."""
    from latentrl.ppo import distributed

    if req.nproc and req.nproc > 1 and not distributed.launched():
        return launch(req)
    if note := distributed.check_environment():  # stray RANK/WORLD_SIZE: one line, or ignored with this note
        print(f"latentrl: note: {note}", flush=True)
    if distributed.launched() and req.trainer == "sb3":
        raise ConfigError(SB3_SINGLE)
    overrides = request_overrides(req)
    if req.resume:
        run_dir = Path(req.resume)
        cfg_path = run_dir / "config.yaml"
        if not cfg_path.is_file():
            raise ConfigError(f"--resume {run_dir}: no config.yaml there; is it a training run directory?")
        cfg = load_config(TrainConfig, cfg_path, overrides)
    else:
        if not req.config:
            raise ConfigError("give a CONFIG file (e.g. configs/quick.yaml) or --resume RUN_DIR")
        cfg = load_train_config(req.config, overrides)
        collective = distributed.init(distributed.rank_device(str(check_device(cfg.ppo.device, "ppo.device"))))
        run_dir = collective.broadcast_object(default_run_dir(req))  # rank 0's clock names the run
        if collective.is_main:  # before any rank writes into it
            check_new_run(run_dir)
    result = run_training(cfg, run_dir, trainer=req.trainer, resume=bool(req.resume),
                          allow_motion_mismatch=req.allow_motion_mismatch, progress=req.progress)
    if distributed.current().is_main:
        print(f"trained {result.iterations} iterations ({result.env_steps} env steps) in {result.elapsed_s:.0f} s; "
              f"final policy: {result.final_checkpoint}")
    distributed.shutdown()
    return 0


def check_training_memory(cfg: TrainConfig, device, ranks: int = 1) -> None:
    """Refuse in one line a CPU run whose memory estimate exceeds what this machine has available.

    The estimate is :func:`latentrl.memory.training_bytes` per rank; the line names the setting that costs most.
    Runs on other devices are not checked: GPU memory is not estimated.
    """
    from latentrl import memory

    if torch.device(device).type != "cpu":
        return

    p = cfg.policy
    params = memory.policy_parameters(p.architecture, p.latent_dim, p.n_blocks, p.mlp_hidden)
    need = ranks * memory.training_bytes(cfg.env.num_envs, cfg.ppo.num_steps, params)
    if ranks > 1:
        flag, hint = "--nproc", "use fewer ranks, or lower env.num_envs (it is per rank)"
    elif params * memory.PARAMETER_BYTES > cfg.env.num_envs * cfg.ppo.num_steps * memory.TRANSITION_BYTES:
        flag = "policy.mlp_hidden" if p.architecture == "mlp" else "policy.latent_dim"
        hint = f"make the policy narrower (about {params:,} parameters)"
    else:
        flag, hint = "env.num_envs", "lower env.num_envs or ppo.num_steps"
    what = (f"training {ranks} rank{'s' * (ranks > 1)} of {cfg.env.num_envs:,} envs x {cfg.ppo.num_steps:,} steps "
            f"on the CPU")
    memory.require_memory(need, flag, what, hint)


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
    from latentrl.ppo import distributed
    from latentrl.ppo.run import TRAINERS
    from latentrl.ppo.run import train as train_ppo

    if trainer not in TRAINERS:
        raise ConfigError(f"--trainer must be {' or '.join(repr(t) for t in TRAINERS)}, got '{trainer}'")
    if trainer == "sb3" and distributed.launched():
        raise ConfigError(SB3_SINGLE)
    device = distributed.rank_device(str(check_device(cfg.ppo.device, "ppo.device")))  # cuda:LOCAL_RANK per rank
    if cfg.env.compile:  # before the first step compiles (and fails deep inside torch)
        check_compile(device, "env.compile")
    collective = distributed.init(device)
    if cfg.threads:
        torch.set_num_threads(cfg.threads)
    cfg.ppo.plan(cfg.env.num_envs)  # batch sizes must fit before anything heavy happens
    check_training_memory(cfg, device)
    run_dir = Path(run_dir)
    check_writable(run_dir, "run directory")
    motion = load_motion(cfg.env, device)
    env = build(cfg.env, device, motion=motion)
    venv = env
    if trainer == "sb3":
        from latentrl.envs import Sb3VecEnv

        venv = Sb3VecEnv(env)
    hook = make_eval_hook(cfg, motion, device) if collective.is_main else None  # rank 0 evaluates
    ppo = dataclasses.replace(cfg.ppo, device=device)  # the checkpoints keep the config's device
    if torch.device(device).type == "cpu" and (busy := busy_machine_warning(torch.get_num_threads())):
        print(f"latentrl: note: {busy}", flush=True)  # stdout: stderr is kept for errors, one line each
    return train_ppo(venv, run_dir, ppo, cfg.policy, trainer=trainer, config=cfg, resume=resume,
                     motion=motion_info(motion), evaluate=hook, allow_motion_mismatch=allow_motion_mismatch,
                     progress=progress)


def quickstart(req: QuickstartRequest) -> int:
    """Body of ``latentrl quickstart``: train ``configs/quick.yaml`` on the default model, then evaluate."""
    from latentrl.app.evaluate import EvalRequest, check_eval_request, evaluate
    from latentrl.ppo import distributed

    started = time.perf_counter()
    if note := distributed.check_environment():
        print(f"latentrl: note: {note}", flush=True)
    cfg = load_train_config(QUICK_CONFIG, req.overrides)
    if quick_amp(cfg, req.overrides, native_cpu_bf16()):
        cfg.env.amp = "bf16"
        print("[quickstart] this CPU computes bf16 natively (AVX-512 BF16): the motion model samples under bf16 "
              "(env.amp=bf16; --set env.amp=null keeps float32)", flush=True)
    run_dir = Path(req.run_dir) if req.run_dir else Path("runs") / f"quickstart-{time.strftime('%Y%m%d-%H%M%S')}"
    check_new_run(run_dir)
    suites = trained_suites(QUICK_EVAL_PATHS, cfg.env.texts) or list(QUICK_EVAL_PATHS[:1])
    eval_req = EvalRequest(policy="", paths=suites, episodes=req.episodes, max_steps=req.max_steps,
                           motion=cfg.env.motion, device=cfg.ppo.device, out=str(run_dir / "eval"), render="gif",
                           progress=req.progress)
    check_eval_request(eval_req)  # before training, not after
    print(f"[quickstart] training configs/quick.yaml on the '{cfg.env.motion}' motion model in {run_dir}")
    result = run_training(cfg, run_dir, progress=req.progress)
    trained = time.perf_counter()
    print(f"[quickstart] trained {result.iterations} iterations ({result.env_steps} env steps) in "
          f"{result.elapsed_s:.0f} s; TensorBoard: tensorboard --logdir {run_dir}")
    eval_req.policy = str(result.final_checkpoint)
    print(f"[quickstart] evaluating on {', '.join(suites)} (the suites using only the trained prompts "
          f"{', '.join(cfg.env.texts)}): latentrl {' '.join(eval_req.argv())}")
    code = evaluate(eval_req)
    split = WallTimeSplit(setup_s=trained - started - result.elapsed_s, training_s=result.elapsed_s,
                          evaluation_s=time.perf_counter() - trained)
    print(f"[quickstart] done: report {run_dir / 'eval' / 'report.md'}, plot {run_dir / 'eval' / 'paths.png'}")
    print(f"[quickstart] {split.line()}")
    return code


def native_cpu_bf16() -> bool:
    """Whether this CPU has AVX-512 BF16 instructions (torch's own probe; False where torch lacks it)."""
    probe = getattr(torch.cpu, "_is_avx512_bf16_supported", None)
    return bool(probe and probe())


def quick_amp(cfg: TrainConfig, overrides: list[str], native_bf16: bool) -> bool:
    """Whether the quickstart samples under bf16: on a CPU that computes bf16 natively, unless ``--set env.amp`` chose.

    Why not in ``quick.yaml``: bf16 made the 64-env step 1.9x faster on an AVX-512 BF16 CPU but 6.3x slower
    where it is emulated (docs/benchmarks.md, "Quickstart").
    """
    chosen = any(item.split("=", 1)[0].strip() == "env.amp" for item in overrides)
    return native_bf16 and not chosen and cfg.env.amp is None and str(cfg.ppo.device).startswith("cpu")


@dataclass(frozen=True)
class WallTimeSplit:
    """Where a quickstart's wall time went, so a user sees what the one-minute training figure leaves out."""

    setup_s: float
    """Checks, motion model, envs, first reset, saving: the command's time outside training and evaluation."""
    training_s: float
    """The training clock (collection, updates, training-time evaluations, the compiled env's warm-up)."""
    evaluation_s: float
    """The final evaluation with its report, plots and GIFs."""

    def line(self) -> str:
        """One line: the three parts and their sum, in seconds."""
        total = self.setup_s + self.training_s + self.evaluation_s
        return (f"wall time {total:.1f} s: set-up {self.setup_s:.1f} s, training {self.training_s:.1f} s, "
                f"evaluation {self.evaluation_s:.1f} s (Python and torch start-up before the command not counted)")
