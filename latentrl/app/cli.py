"""``latentrl`` command line: the argument definitions of every subcommand, nothing else.

Each subcommand turns its arguments into the request dataclass of its command
(:mod:`latentrl.app.train`, :mod:`~latentrl.app.evaluate`, :mod:`~latentrl.app.motion`,
:mod:`~latentrl.app.bench`) and calls it; the command's module loads only then (keeps ``--help`` fast).
Errors a user can cause (:class:`latentrl.errors.LatentRLError`, bad arguments) become one line on
stderr and exit code 2; non-finite training values exit 3 (:class:`~latentrl.errors.NonFiniteError`),
I/O failures while a command runs (disk full) exit 1, Ctrl-C 130; ``--debug`` shows the traceback.
"""

from __future__ import annotations

import argparse
import dataclasses
import signal
import sys
import threading
from collections.abc import Sequence
from pathlib import Path

from latentrl import interrupts
from latentrl.constants import GUIDANCE_SCALE
from latentrl.errors import LatentRLError


class _HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Help that shows every option's default (unless its text already names one) and keeps examples' lines."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = action.help or ""
        default = action.default
        if "(default" in text or any(default is v for v in (None, False, True, argparse.SUPPRESS)) \
                or not action.option_strings:
            return action.help
        shown = " ".join(map(str, default)) if isinstance(default, (list, tuple)) else default
        return f"{text} (default: {str(shown).replace('%', '%%')})".strip()


class _Parser(argparse.ArgumentParser):
    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", _HelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str):  # one line, exit 2 (argparse's own convention)
        self.exit(2, f"{self.prog}: error: {message}\n")


EXAMPLES = {
    "motion": "latentrl motion sample --text walk --seconds 5 --render walk.mp4",
    "motion info": "latentrl motion info --motion default",
    "motion sample": "latentrl motion sample --text walk:3 --text 'turn left:1.5' --foot-lock --render walk.mp4",
    "motion train": "latentrl motion train configs/motion/tiny.yaml --run-dir runs/motion-tiny",
    "motion export-bvh": "latentrl motion export-bvh motion.npz --out motion.bvh",
    "data": "latentrl data convert-amass ~/amass/ACCAD --labels babel.json --smplx-model ~/smplx --out data/accad",
    "data convert-amass": "latentrl data convert-amass ~/amass/ACCAD --labels babel.json --smplx-model ~/smplx "
                          "--out data/accad",
    "quickstart": "latentrl quickstart --run-dir runs/quick",
    "train": "latentrl train configs/quick.yaml --set ppo.total_steps=65536 --run-dir runs/my-reach",
    "eval": "latentrl eval reach_walk_default --episodes 4 --out eval-walk",
    "compare": "latentrl compare eval-a eval-b --out compare.md",
    "optimize": "latentrl optimize inbetween_walk --steps 100 --out optimize-inbetween",
    "bench": "latentrl bench rollout --batches 1 16 --json rollout.json",
    "bench rollout": "latentrl bench rollout --batches 1 16 --json rollout.json",
    "bench env": "latentrl bench env --num-envs 1 64 --models default --json env.json",
    "bench train": "latentrl bench train --skip-success --iterations 3",
    "bench motion": "latentrl bench motion --seconds 20 --batch 4 --foot-lock",
    "bench optimize": "latentrl bench optimize --skip-suites --cost-steps 3",
    "view": "latentrl view runs/quick/eval --record eval.mp4",
    "play": "latentrl play reach_walk_default --port 8080 --record play.mp4",
    "export": "latentrl export onnx reach_walk_default --out reach.onnx",
    "export onnx": "latentrl export onnx reach_walk_default --out reach.onnx --text walk",
    "list": "latentrl list policies",
    "physics": "latentrl physics track walk.npz --out tracked-walk",
    "physics track": "latentrl physics track walk.npz --out tracked-walk --assist-hz 2",
    "physics loop": "latentrl physics loop --text walk --seconds 10 --out loop-walk",
    "physics train-tracker": "latentrl physics train-tracker physics/tracker --run-dir runs/tracker",
    "scene": "latentrl scene from-mesh room.glb --up y --out room.json",
    "scene from-mesh": "latentrl scene from-mesh table.stl --voxel 0.05 --offset 0 2 0 --out table.json",
}
"""One example line per command, shown at the end of its ``--help`` (keyed by the words after ``latentrl``)."""


def subcommands(parser: argparse.ArgumentParser, words: tuple[str, ...] = ()):
    """Yield ``(words, parser)`` of every (nested) subcommand below ``parser``, depth first."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help for a in action._choices_actions}
            for name, sub in action.choices.items():
                if sub.description is None:
                    sub.description = helps.get(name)
                yield (*words, name), sub
                yield from subcommands(sub, (*words, name))


def _add_examples(parser: argparse.ArgumentParser) -> None:
    """Set every subcommand's epilog to its line of :data:`EXAMPLES` (a missing one fails the CLI tests)."""
    for words, sub in subcommands(parser):
        example = EXAMPLES.get(" ".join(words))
        if example:
            sub.epilog = f"example:\n  {example}"


def _device(text: str) -> str:
    """Argument type of ``--device``: a torch device this machine has (checked before any work starts)."""
    from latentrl.preflight import check_device

    try:
        check_device(text, "--device")
    except LatentRLError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--device: ")) from None
    return text


def _render(text: str) -> str | int:
    """Argument type of ``eval --render``: none, gif or mp4; an integer is the former form (the first N as GIF)."""
    try:
        return int(text)
    except ValueError:
        return text.lower()


def _trainer(name: str) -> str:
    """Argument type of ``--trainer``: a name in the trainer registry (``ppo.run.TRAINERS``)."""
    from latentrl.ppo.run import TRAINERS

    if name not in TRAINERS:
        raise argparse.ArgumentTypeError(f"invalid choice: '{name}' (choose from {', '.join(map(repr, TRAINERS))})")
    return name


def _seed(text: str) -> int:
    """Argument type of ``--seed``: an integer in [0, 2**32 - 1]."""
    from latentrl.config import seed_problem

    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer seed, got '{text}'") from None
    if seed_problem(value) is not None:
        raise argparse.ArgumentTypeError(str(seed_problem(value)))
    return value


_seed.__name__ = "int"


def _positive(kind: type):
    """Argument type: an int or float > 0 (and finite)."""

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            expected = "an integer" if kind is int else "a number"
            raise argparse.ArgumentTypeError(f"expected {expected}, got '{text}'") from None
        if not value > 0 or value == float("inf"):
            raise argparse.ArgumentTypeError(f"must be > 0, got {text}")
        return value

    parse.__name__ = kind.__name__  # argparse names the type in "invalid <type> value" messages
    return parse


_pos_int, _pos_float = _positive(int), _positive(float)


def _at_most(kind: type, upper: float):
    """Argument type: an int or float in (0, upper] (finite): a bench or export size that cannot exhaust the machine."""
    positive = _positive(kind)

    def parse(text: str):
        value = positive(text)
        if value > upper:
            raise argparse.ArgumentTypeError(f"must be at most {upper:,}, got {text}")
        return value

    parse.__name__ = kind.__name__
    return parse


def _guidance(text: str) -> float:
    """Argument type: a classifier-free guidance scale, finite and within +/- MAX_GUIDANCE (NaN makes NaN motion)."""
    from latentrl.constants import MAX_GUIDANCE

    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number, got '{text}'") from None
    if not abs(value) <= MAX_GUIDANCE:  # also refuses nan
        raise argparse.ArgumentTypeError(f"must be a finite number in [-{MAX_GUIDANCE:g}, {MAX_GUIDANCE:g}], "
                                         f"got {text}")
    return value


_guidance.__name__ = "float"


def _nproc(text: str) -> int:
    """Argument type: ranks on this machine, 1 to its CPU count (each rank is a process with its own torch)."""
    import os

    value = _pos_int(text)
    cores = os.cpu_count() or 1
    if value > cores:
        raise argparse.ArgumentTypeError(f"must be at most this machine's {cores} CPU cores, got {text}")
    return value


_nproc.__name__ = "int"
MAX_BENCH_BATCH = 1 << 20
"""Largest batch or env count a benchmark times (memory is also estimated before it runs)."""
MAX_BENCH_STEPS = 100_000
"""Most timed steps, repeats, rounds or iterations a benchmark flag may ask for."""
MAX_THREAD_FLAG = 1024
"""Most torch threads a ``--threads`` flag may ask for (``latentrl.config.MAX_THREADS``)."""
_batch_size, _step_count = _at_most(int, MAX_BENCH_BATCH), _at_most(int, MAX_BENCH_STEPS)
_threads = _at_most(int, MAX_THREAD_FLAG)


def _fraction(text: str) -> float:
    """Argument type: a float in (0, 1]."""
    value = _pos_float(text)
    if value > 1:
        raise argparse.ArgumentTypeError(f"must lie in (0, 1], got {text}")
    return value


def _motion_commands(sub) -> None:
    motion = sub.add_parser("motion", help="inspect, sample and train motion models")
    msub = motion.add_subparsers(dest="motion_command", metavar="SUBCOMMAND", parser_class=_Parser)
    msub.required = True

    info = msub.add_parser("info", help="describe a motion model (architecture, latent size, texts)")
    info.add_argument("--motion", default="default", help="'default', a latentrl model file, or a DART checkpoint")
    info.add_argument("--seed-history", help="(K, 2, 276) seed histories (.npz/.pt) for DART layouts")
    info.set_defaults(func=_motion_info)

    sample = msub.add_parser("sample", help="roll a motion model out over a text timeline; write .npz (and .gif/.mp4)")
    sample.add_argument("--motion", default="default", help="'default', a latentrl model file, or a DART checkpoint")
    sample.add_argument("--seed-history", help="(K, 2, 276) seed histories (.npz/.pt) for DART layouts")
    sample.add_argument("--text", action="append", metavar="PROMPT[:SECONDS]",
                        help="prompt; repeat to chain prompts: 'walk:3' lasts 3 s, DART's 'walk*20,turn left*6' counts "
                             "primitives of 8 frames, a prompt without either shares what --seconds leaves "
                             "(default: walk)")
    sample.add_argument("--seconds", type=float, default=None,
                        help="length of the motion (default: 10, or the sum of the --text durations)")
    sample.add_argument("--seed", type=_seed, default=0, help="random seed (noise and seed-history choice)")
    sample.add_argument("--guidance", type=float, default=GUIDANCE_SCALE, help="classifier-free guidance scale")
    sample.add_argument("--batch", type=int, default=1, help="number of motions (files get _<i> suffixes)")
    sample.add_argument("--device", default="cpu", type=_device, help="torch device")
    sample.add_argument("--out", default="motion.npz", help="output .npz (shared motion format)")
    sample.add_argument("--foot-lock", action="store_true",
                        help="keep planted feet from sliding (the envs' foot lock; docs/motion.md)")
    sample.add_argument("--no-floor-snap", action="store_true",
                        help="the model alone: no snap of each primitive's lowest foot onto the floor")
    sample.add_argument("--render", metavar="FILE", help="also draw the first motion as a .gif or .mp4 (MP4 needs "
                                                         "latentrl[video])")
    sample.set_defaults(func=_motion_sample)

    train = msub.add_parser("train", help="train a motion model (VAE, then denoiser) from a YAML config")
    train.add_argument("config", nargs="?", help="YAML config (e.g. configs/motion/default.yaml)")
    train.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a config field (dotted)")
    train.add_argument("--run-dir", help="run directory (default: runs/motion-<time>)")
    train.add_argument("--resume", metavar="RUN_DIR", help="continue the run in RUN_DIR from its last checkpoint")
    train.add_argument("--out", help="where to write the model (default: <run_dir>/motion_model.pt)")
    train.add_argument("--vae-from", metavar="MODEL.pt",
                       help="take this trained model's VAE and train only the denoiser (same model.vae and data)")
    train.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    train.set_defaults(func=_motion_train)

    bvh = msub.add_parser("export-bvh", help="write a motion .npz as BVH (SMPL-22 skeleton, Y-up, centimetres)")
    bvh.add_argument("motion", metavar="MOTION.npz", help="motion file in the shared format (e.g. from eval or sample)")
    bvh.add_argument("--out", metavar="FILE.bvh", help="output file (default: the motion file with .bvh)")
    bvh.set_defaults(func=_motion_export_bvh)


def _data_commands(sub) -> None:
    data = sub.add_parser("data", help="motion-text datasets: convert AMASS-style sequences")
    dsub = data.add_subparsers(dest="data_command", metavar="SUBCOMMAND", parser_class=_Parser)
    dsub.required = True
    conv = dsub.add_parser("convert-amass",
                           help="AMASS SMPL(-X/-H) .npz + labels -> motion-text .npz files (see docs/datasets.md)")
    from latentrl.datasets.amass import add_convert_arguments

    add_convert_arguments(conv)
    conv.set_defaults(func=_convert_amass)


def _train_commands(sub) -> None:
    quick = sub.add_parser("quickstart", help="train configs/quick.yaml on the default motion model, then evaluate it")
    quick.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a field of configs/quick.yaml")
    quick.add_argument("--run-dir", help="run directory (default: runs/quickstart-<time>)")
    quick.add_argument("--episodes", type=int, default=8, help="evaluation episodes per path")
    quick.add_argument("--max-steps", type=int, default=128, help="evaluation step budget per episode")
    quick.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    quick.set_defaults(func=_quickstart)

    train = sub.add_parser("train", help="train a controller with PPO from a YAML config")
    train.add_argument("config", nargs="?", help="YAML config (e.g. configs/quick.yaml)")
    train.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a config field (dotted)")
    train.add_argument("--trainer", default="native", type=_trainer, help="PPO implementation: native or sb3 "
                       "(or a trainer registered with latentrl.ppo.run.register_trainer)")
    train.add_argument("--device", type=_device, help="torch device (sets ppo.device), e.g. cpu or cuda")
    train.add_argument("--seed", type=_seed, help="random seed (sets ppo.seed)")
    train.add_argument("--total-steps", type=int, help="env steps to train (sets ppo.total_steps)")
    train.add_argument("--run-dir", help="run directory (default: runs/<config>-<time>)")
    train.add_argument("--resume", metavar="RUN_DIR", help="continue the run in RUN_DIR from its newest checkpoint")
    train.add_argument("--allow-motion-mismatch", action="store_true",
                       help="resume onto a different motion model than the run was trained on (experts)")
    train.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    train.add_argument("--nproc", type=_nproc,
                       help="ranks on this machine (launches torchrun; env.num_envs is per rank; docs/training.md)")
    train.set_defaults(func=_train)


def _bench_commands(sub) -> None:
    bench = sub.add_parser("bench", help="measure speed and quality; figures go to --json")
    bsub = bench.add_subparsers(dest="bench_command", metavar="BENCHMARK", parser_class=_Parser)
    bsub.required = True
    roll = bsub.add_parser("rollout", help="primitives/s of the motion model, side by side with DART's sampler")
    roll.add_argument("--batches", type=_batch_size, nargs="+", default=[1, 16, 256], help="batch sizes")
    roll.add_argument("--models", nargs="+", default=["official", "default"],
                      help="'official' (DART size, random weights), 'default', or model paths")
    roll.add_argument("--device", nargs="+", type=_device, default=None,
                      help="devices (default: cpu, plus cuda when present)")
    roll.add_argument("--repeats", type=_step_count, default=5, help="timed runs per figure (median reported)")
    roll.add_argument("--rounds", type=_step_count, default=None,
                      help="with --dart-src: time ours, then DART's, this many times over (default 5); ratios are "
                           "the median over rounds with their min-max and IQR")
    roll.add_argument("--threads", type=_threads, default=None, help="torch CPU threads (default: torch's)")
    roll.add_argument("--amp", nargs="+", choices=["bf16", "fp16"],
                      help="also time autocast in these dtypes (CPU: bf16; CUDA: bf16/fp16); with --compile also "
                           "compiled; rows print their difference from the plain fp32 sampler")
    roll.add_argument("--compile", action="store_true",
                      help="also time the sampler under torch.compile(fullgraph=True) with frozen weights")
    roll.add_argument("--cuda-graph", action="store_true",
                      help="on CUDA also time the compiled sampler captured and replayed as a CUDA graph "
                           "(torch.compile mode='reduce-overhead'); with --amp also in those dtypes")
    roll.add_argument("--packed", action="store_true",
                      help="also time the sampler with its linear weights prepacked for oneDNN "
                           "(MotionModel.pack_for_cpu; CPU only; with --compile also compiled)")
    roll.add_argument("--dart-src", default=None,
                      help="extracted zkf1997/DART tree; runs ../shared/tools/dart_peer_bench.py side by side")
    roll.add_argument("--dart-python", default=None, help="python of the environment able to import DART")
    roll.add_argument("--dart-bench", default=None, help="path to dart_peer_bench.py (default: ../shared/tools)")
    roll.add_argument("--json", help="write all figures to this JSON file")
    roll.set_defaults(func=_bench_rollout)

    env = bsub.add_parser("env", help="env steps/s of the batched env vs. a per-env SyncVectorEnv loop")
    env.add_argument("--models", nargs="+", default=["default", "official"],
                     help="'default', 'official' (DART size, random weights), 'tiny', or model paths")
    env.add_argument("--num-envs", type=_batch_size, nargs="+", default=[1, 64, 256, 1024], help="env counts")
    env.add_argument("--device", nargs="+", type=_device, default=None,
                     help="devices (default: cpu, plus cuda when present)")
    env.add_argument("--steps", type=_step_count, default=5, help="timed steps per figure")
    env.add_argument("--max-seconds", type=_at_most(float, 86_400), default=120.0,
                     help="skip combinations estimated to take longer")
    env.add_argument("--no-baseline", dest="baseline", action="store_false", help="skip the per-env loop")
    env.add_argument("--compile", action="store_true",
                     help="also time the env with compile=True (on CUDA captured as a CUDA graph; its first two "
                          "steps compile and record, not timed)")
    env.add_argument("--amp", choices=["bf16", "fp16"], default=None,
                     help="also time the env with amp=bf16/fp16 (the motion model under autocast; docs/envs.md); "
                          "with --compile also both together")
    env.add_argument("--threads", type=_threads, default=None, help="torch CPU threads")
    env.add_argument("--scene", action="store_true",
                     help="also time the env with 8 random obstacles per env (docs/scenes.md) and print its step-time "
                          "ratio to the flat env")
    env.add_argument("--json", help="write all figures to this JSON file")
    env.set_defaults(func=_bench_env)

    tr = bsub.add_parser("train", help="time to eval success on the quick config; native vs SB3 iteration time")
    tr.add_argument("--config", help="training config (default: configs/quick.yaml)")
    tr.add_argument("--set", action="append", metavar="KEY=VALUE", help="override a config field (dotted)")
    tr.add_argument("--target", type=_fraction, default=0.9, help="eval success rate to reach")
    tr.add_argument("--eval-every", type=_step_count, default=10, help="iterations between evaluations")
    tr.add_argument("--max-steps", type=_at_most(int, 10**12), default=None, help="env-step cap for the success run")
    tr.add_argument("--iterations", type=_step_count, default=5, help="iterations per trainer in the side-by-side run")
    tr.add_argument("--skip-success", action="store_true", help="only the native vs SB3 comparison")
    tr.add_argument("--no-side-by-side", dest="side_by_side", action="store_false",
                    help="only the success run (no native vs SB3 comparison)")
    tr.add_argument("--threads", type=_threads, default=None, help="torch CPU threads")
    tr.add_argument("--run-dir", help="where the benchmark's runs go (default: a temporary folder)")
    tr.add_argument("--no-progress", action="store_true")
    tr.add_argument("--json", help="write all figures to this JSON file")
    tr.add_argument("--nproc", type=_nproc, nargs="+",
                    help="instead: env steps/s with this many ranks each (latentrl train --nproc N), e.g. 1 2")
    tr.set_defaults(func=_bench_train)

    motion = bsub.add_parser("motion", help="stability and text control of a motion model vs. its training data")
    motion.add_argument("--motion", default="default", help="'default' or a model file")
    motion.add_argument("--seconds", type=_at_most(float, 3600), default=60.0, help="rollout length per prompt")
    motion.add_argument("--batch", type=_at_most(int, 1024), default=8, help="rollouts per prompt")
    motion.add_argument("--guidance", type=_guidance, default=GUIDANCE_SCALE, help="classifier-free guidance scale")
    motion.add_argument("--seed", type=_seed, default=0, help="random seed")
    motion.add_argument("--json", help="write all figures to this JSON file")
    motion.add_argument("--no-floor-snap", action="store_true",
                        help="measure the model alone, without the rollout's floor snap")
    motion.add_argument("--snap-ramp", action="store_true",
                        help="spread each primitive's floor-snap shift over its frames (docs/motion.md)")
    motion.add_argument("--foot-lock", action="store_true",
                        help="roll out with the foot lock (planted feet do not slide; docs/motion.md)")
    motion.add_argument("--no-skills", action="store_true",
                        help="skip the scene-skill checks (crouch, sit, stairs, reach, wave)")
    motion.set_defaults(func=_bench_motion)
    _bench_optimize_command(bsub)


def _bench_optimize_command(bsub) -> None:
    opt = bsub.add_parser("optimize", help="noise optimization on the shipped constraint suites: error, skate, jerk, "
                                           "time to 1 cm, cost per 100 steps vs DART")
    opt.add_argument("--suites", nargs="+", default=["inbetween", "inbetween_mid", "joint_targets"],
                     help="shipped constraint suites")
    opt.add_argument("--steps", type=_step_count, default=100, help="Adam steps")
    opt.add_argument("--batch", type=_at_most(int, 4096), default=16, help="problems solved together")
    opt.add_argument("--lr", type=_pos_float, default=0.05, help="Adam learning rate")
    opt.add_argument("--warm", metavar="POLICY", help="also run every suite warm-started from this policy's noises")
    opt.add_argument("--cost-steps", type=_step_count, default=5, help="timed steps of the cost rows")
    opt.add_argument("--models", nargs="+", default=["default", "official"], help="models of the cost rows")
    opt.add_argument("--batches", type=_at_most(int, 4096), nargs="+", default=None,
                     help="problems solved together in the rate rows: problems per minute at 100 steps on the "
                          "default model (default: 1 8 64)")
    opt.add_argument("--device", action="append", type=_device, help="repeat for several (default: cpu and cuda)")
    opt.add_argument("--threads", type=_threads)
    opt.add_argument("--skip-suites", action="store_true", help="only the cost rows")
    opt.add_argument("--json", help="write all figures to this JSON file")
    opt.add_argument("--plot", metavar="PNG", help="mean goal error against wall time, per suite and start")
    opt.set_defaults(func=_bench_optimize)


def _bench_optimize(args: argparse.Namespace) -> int:
    from latentrl.app.bench.optimize import OptimizeBenchRequest, bench_optimize

    return bench_optimize(request(OptimizeBenchRequest, args))


def _eval_commands(sub) -> None:
    ev = sub.add_parser("eval", help="evaluate a policy over waypoint paths (DART's protocol); report, plots, motions")
    ev.add_argument("policy", metavar="POLICY",
                    help="PPO checkpoint (.pt) from latentrl train, or a shipped policy by name (reach_walk_default)")
    ev.add_argument("--paths", nargs="+", metavar="FILE",
                    help="DART-format path files or suite names in tasks/paths (default: those of dart_walk_long "
                         "dart_run_long dart_hop_long using only the policy's prompts); for joystick and timed "
                         "policies, command-timeline or timed path files, or suite names in tasks/joystick or "
                         "tasks/timed")
    ev.add_argument("--episodes", type=int, default=32, help="episodes per path, run as one batch (DART: 32)")
    ev.add_argument("--max-steps", type=int, default=256,
                    help="step budget per episode, in primitives of 8 frames (DART: 256 = 68.3 s); "
                         "episodes that do not finish count as failures")
    ev.add_argument("--deterministic", action="store_true", help="take the policy's mean action (default: sample)")
    ev.add_argument("--motion", default=None,
                    help="the motion model the policy was trained on: 'default', a model file or a DART checkpoint "
                         "(default: the one named in the policy's stored config)")
    ev.add_argument("--allow-motion-mismatch", action="store_true",
                    help="evaluate on a motion model other than the policy's (experts)")
    ev.add_argument("--foot-lock-min-weight", type=float, default=None, metavar="W",
                    help="with the policy's foot lock on: pin a foot fully from this contact weight (default: the "
                         "policy's training value; 0.05 pins any foot inside DART's 3 cm band, docs/motion.md)")
    ev.add_argument("--device", type=_device, help="torch device (default: cuda when available, else cpu)")
    ev.add_argument("--seed", type=_seed, default=0, help="base random seed (seed histories and action noise)")
    ev.add_argument("--out", help="output folder (default: eval-<policy name> beside the policy)")
    ev.add_argument("--render", type=_render, default="none", metavar="{none,gif,mp4}",
                    help="draw episodes as GIF or MP4 (MP4 needs latentrl[video]) plus BVH, into <out>/renders "
                         "(default none)")
    ev.add_argument("--render-episodes", type=int, default=1, metavar="N",
                    help="with --render: draw the first N episodes of every path (default 1)")
    ev.add_argument("--no-render", dest="render", action="store_const", const="none", help="draw nothing (default)")
    ev.add_argument("--no-motions", dest="motions", action="store_false", help="skip the per-episode .npz files")
    ev.add_argument("--no-progress", action="store_true", help="hide the progress bar (paths x episodes)")
    ev.add_argument("--scene", metavar="SCENE",
                    help="evaluate among objects: a latentrl.scene/1 file or a name in tasks/scenes, or "
                         "random_obstacles (3-8 per episode; not for joystick policies); reach, path, timed, "
                         "joystick and ReachJoint policies; the report adds collision rate and penetration "
                         "(docs/scenes.md). Default: the policy's training scene")
    ev.add_argument("--physics", action="store_true",
                    help="reach/path policies: execute every primitive on a MuJoCo humanoid and plan from the "
                         "simulated frames, beside the kinematic run of the same seeds (latentrl[physics]; "
                         "docs/physics.md)")
    ev.add_argument("--refine", type=int, default=None, metavar="STEPS",
                    help="ReachJoint policies: before every step, STEPS optimizer steps on the policy's noise land "
                         "the goals due in the next --refine-horizon primitives (default: the policy's stored "
                         "eval.refine, else 0: off; docs/joint_goals.md)")
    ev.add_argument("--refine-horizon", type=int, default=None, metavar="H",
                    help="with --refine: primitives predicted (8 frames each), the first executed (default: the "
                         "policy's stored eval.refine_horizon, else 3)")
    ev.add_argument("--refine-skate", type=float, default=None, metavar="W",
                    help="with --refine: weight of the predicted frames' foot skate (m/s) in the refiner's loss: "
                         "planted feet for goal error (default: the policy's stored eval.refine_skate, else 0)")
    ev.add_argument("--refine-pace", type=float, default=None, metavar="W",
                    help="with --refine: weight of the pace target of a goal beyond the horizon, the point that "
                         "arrives on time at the horizon's end (default: the policy's stored eval.refine_pace, "
                         "else 0.5)")
    ev.add_argument("--refine-land", type=int, default=None, metavar="FRAMES",
                    help="with --refine: hold each footstep's foot down on its stone (x, y and the floor) for FRAMES "
                         "frames after its time, in place of 2 frames held in x and y: a foot that cannot be down "
                         "in time lands on its stone, not past it (default: the policy's stored eval.refine_land, "
                         "else 0; 6 with --refine 64 lands 574 of stepping_stones' 576 footsteps in 32 episodes)")
    ev.add_argument("--refine-start", choices=["policy", "zeros", "auto"], default=None,
                    help="with --refine: start each step's refinement from the policy's action, from zero noise "
                         "(for joints the policy was not trained on), or auto: the policy's for its trained joints, "
                         "zeros for the others; default: the policy's stored eval.refine_start, else policy")
    ev.add_argument("--avoid", type=int, default=None, metavar="STEPS",
                    help="evaluations among objects: before every step, predict --avoid-horizon primitives of the "
                         "policy's noise and, where a joint comes within its skin plus --avoid-margin of an object, "
                         "move the noise by STEPS optimizer steps, as little as it takes (default: the policy's "
                         "stored eval.avoid, else 0: off; docs/scenes.md)")
    ev.add_argument("--avoid-horizon", type=int, default=None, metavar="H",
                    help="with --avoid: primitives predicted (8 frames each), the first executed (default: the "
                         "policy's stored eval.avoid_horizon, else 2)")
    ev.add_argument("--avoid-margin", type=float, default=None, metavar="M",
                    help="with --avoid: metres beyond each joint's skin radius kept from every object (feet and "
                         "ankles: the skin alone; default: the policy's stored eval.avoid_margin, else 0.1)")
    ev.add_argument("--avoid-samples", type=int, default=None, metavar="K",
                    help="with --avoid: first try K more draws of the stochastic policy in one batched prediction and "
                         "take the safe one ending nearest the policy's own plan; the optimizer only where none is "
                         "safe (default: the policy's stored eval.avoid_samples, else 0; not with --refine)")
    ev.add_argument("--sit-plan", type=int, default=None, metavar="STEPS",
                    help="sit policies: when the approach ends, plan the settle steps and the sit instead of the "
                         "policy's actions: draw --sit-plan-samples plans, keep the one ending with the pelvis nearest "
                         "its seated point over the seat, and refine it by STEPS optimizer steps (default: the "
                         "policy's stored eval.sit_plan, else 0: off; docs/scenes.md)")
    ev.add_argument("--sit-plan-samples", type=int, default=None, metavar="K",
                    help="with --sit-plan: N(0, I) plans drawn and scored first (0: start from zero noise; default: "
                         "the policy's stored eval.sit_plan_samples, else 32)")
    ev.add_argument("--sit-plan-getup", type=int, default=None, metavar="PRIMITIVES",
                    help="with --sit-plan: plan the stand-up and the walk away too, PRIMITIVES at a time (the pelvis "
                         "back at standing height, then 0.7 m from the seat centre; 0: the policy stands up and "
                         "walks away; default: the policy's stored eval.sit_plan_getup, else 3)")
    ev.add_argument("--sit-plan-approach", type=float, default=None, metavar="M",
                    help="with --sit-plan: plan the approach's end too, once the pelvis is within M metres of the "
                         "sit-down spot (5 primitives of the walk text at a time, ending at the spot turned to the "
                         "sitter's facing; 0: the policy approaches; default: the policy's stored "
                         "eval.sit_plan_approach, else 0)")
    ev.add_argument("--route", type=float, default=None, metavar="M",
                    help="reach, path, timed and joystick policies among objects: plan the shortest route to each goal "
                         "(a joystick's: 3-6 m along its command) keeping M "
                         "metres from every object, and show the policy the farthest route point in clear sight as "
                         "its goal (success stays the task's goal; default: the policy's stored eval.route, else "
                         "0: off; docs/scenes.md)")
    ev.set_defaults(func=_evaluate)

    cmp = sub.add_parser("compare", help="several evaluation reports side by side (markdown table)")
    cmp.add_argument("reports", nargs="+", metavar="REPORT", help="report.json files or eval output folders")
    cmp.add_argument("--out", metavar="FILE.md", help="also write the table to this file")
    cmp.set_defaults(func=_compare)


def _port(text: str) -> int:
    """Argument type of ``--port``: 0..65535 (0 = any free port)."""
    if not text.isdigit() or int(text) > 65535:
        raise argparse.ArgumentTypeError(f"expected a port in 0..65535, got '{text}'")
    return int(text)


def _viewer_commands(sub) -> None:
    def server_flags(p) -> None:
        p.add_argument("--host", default="127.0.0.1", help="address to listen on (default: this machine only)")
        p.add_argument("--port", type=_port, default=8080, help="port to listen on (default 8080; 0 = any free port)")
        p.add_argument("--skeleton", action="store_true",
                       help="also draw the skeleton (lines and joints) inside the capsule body; a checkbox switches it")

    view = sub.add_parser("view", help="browser viewer for a motion .npz, an evaluation folder or a training run")
    view.add_argument("path", metavar="PATH", help="motion .npz, eval folder (report.json), run folder or .npz folder")
    server_flags(view)
    view.add_argument("--record", metavar="FILE", help="also draw every frame played into this .gif or .mp4 when the "
                                                       "viewer stops (MP4 needs latentrl[video])")
    view.set_defaults(func=lambda a: _viewer("view_command", a.path, host=a.host, port=a.port, record=a.record,
                                             skeleton=a.skeleton))

    play = sub.add_parser("play", help="steer a policy live in the browser: clicks set a reach/path policy's goal "
                                       "and waypoints or a ReachJoint policy's timed joint goals, arrows or WASD a "
                                       "joystick policy's heading and speed")
    play.add_argument("policy", metavar="POLICY", help="PPO checkpoint (.pt) of a reach, path, joystick or ReachJoint "
                                                       "policy, or a shipped policy by name (reach_walk_default)")
    play.add_argument("--motion", default=None,
                      help="the motion model the policy was trained on (default: the one its stored config names)")
    play.add_argument("--allow-motion-mismatch", action="store_true", help="run on another motion model (experts)")
    play.add_argument("--device", type=_device, help="torch device (default: cuda when available, else cpu)")
    play.add_argument("--text", help="prompt to start with (default: the policy's training text)")
    play.add_argument("--deterministic", action="store_true", help="start with the policy's mean action")
    play.add_argument("--seed", type=_seed, default=0, help="seed of the start pose and the action noise")
    play.add_argument("--scene", metavar="SCENE", help="play among objects: a latentrl.scene/1 file or a name in "
                                                        "tasks/scenes (default: the policy's training scene, else the "
                                                        "bare floor); ctrl-click drops boxes into it")
    play.add_argument("--route", type=float, default=None, metavar="M",
                      help="reach, path and joystick policies: head along the shortest route keeping M metres from "
                           "every object, so dropped boxes are walked around (default: the policy's env.route, else "
                           "0: straight for the goal; docs/scenes.md)")
    server_flags(play)
    play.add_argument("--record", metavar="FILE", help="also draw every frame shown into this .gif or .mp4 when the "
                                                       "viewer stops (MP4 needs latentrl[video])")
    play.set_defaults(func=lambda a: _viewer(
        "play_command", a.policy, host=a.host, port=a.port, motion=a.motion, device=a.device, text=a.text,
        deterministic=a.deterministic, seed=a.seed, allow_motion_mismatch=a.allow_motion_mismatch, record=a.record,
        scene=a.scene, skeleton=a.skeleton, route=a.route))


def _viewer(name: str, *args, **kwargs) -> int:
    from latentrl import viewer  # optional extra: imported only when a viewer command runs

    return int(getattr(viewer, name)(*args, **kwargs) or 0)


def _export_commands(sub) -> None:
    export = sub.add_parser("export", help="controllers for game engines (ONNX)")
    esub = export.add_subparsers(dest="export_command", metavar="FORMAT", parser_class=_Parser)
    esub.required = True
    onnx = esub.add_parser("onnx", help="the whole controller step (policy mean, guided sampler, decoder, world "
                                        "update) as one ONNX graph (needs latentrl[onnx])")
    onnx.add_argument("policy", metavar="POLICY", help="PPO checkpoint (.pt) of a reach, path, joystick or "
                                                       "timed policy, or a shipped policy by name (reach_walk_default)")
    onnx.add_argument("--out", required=True, metavar="FILE", help="output .onnx file")
    onnx.add_argument("--batch", type=_batch_size, default=1,
                      help="characters per call, fixed in the graph (default 1)")
    onnx.add_argument("--text", help="bake this prompt in (default: the graph takes a text_embedding input)")
    onnx.add_argument("--opset", type=int, default=17, help="ONNX opset version, >= 17 (default 17)")
    onnx.add_argument("--motion", default=None,
                      help="the motion model the policy was trained on (default: the one its stored config names)")
    onnx.add_argument("--allow-motion-mismatch", action="store_true",
                      help="export with a motion model other than the policy's (experts)")
    onnx.set_defaults(func=_export_onnx)


def _export_onnx(a: argparse.Namespace) -> int:
    from latentrl.export.onnx import export_command

    return int(export_command(a.policy, a.out, batch=a.batch, text=a.text, opset=a.opset, motion=a.motion,
                              allow_motion_mismatch=a.allow_motion_mismatch) or 0)


def _list_commands(sub) -> None:
    ls = sub.add_parser("list", help="what ships: tasks and their Gymnasium ids, policies, configs, suites, prompts")
    ls.add_argument("section", nargs="?", metavar="SECTION",
                    help="tasks, policies, configs, suites or prompts (default: all of them)")
    ls.add_argument("--motion", default="default", help="whose prompts to list: 'default', a model file or a DART "
                                                         "checkpoint (default: default)")
    ls.set_defaults(func=_list)


def _list(args: argparse.Namespace) -> int:
    from latentrl.app.listing import ListRequest, list_command

    return list_command(request(ListRequest, args))


def _physics_commands(sub) -> None:
    phys = sub.add_parser("physics", help="execute motions on a MuJoCo humanoid (pip install 'latentrl[physics]')")
    psub = phys.add_subparsers(dest="physics_command", metavar="SUBCOMMAND", parser_class=_Parser)
    psub.required = True
    tr = psub.add_parser("track", help="PD-track a motion .npz with a reported root assist; write motion.npz and "
                                       "report.json (docs/physics.md)")
    tr.add_argument("motion", metavar="MOTION.npz", help="motion .npz (from motion sample or eval)")
    tr.add_argument("--out", required=True, help="output folder for motion.npz and report.json")
    tr.add_argument("--height", type=float, help="humanoid height in m (default: fitted to the motion's bones)")
    tr.add_argument("--assist-hz", type=float, default=2.0, help="root assist frequency, 0 = off (default: 2)")
    tr.add_argument("--tracker", metavar="CHECKPOINT",
                    help="a physics train-tracker checkpoint: track with the learned tracker (its assist is "
                         "--assist-hz over the checkpoint's assist_hz, at most full strength)")
    tr.set_defaults(func=_physics_track)
    tt = psub.add_parser("train-tracker", help="train the learned tracker with PPO on MuJoCo (docs/physics.md)")
    tt.add_argument("config", nargs="?", metavar="CONFIG", help="tracker config: a YAML path or a packaged name "
                                                                "(physics/tracker)")
    tt.add_argument("--run-dir", help="run directory (default: runs/tracker-<time>)")
    tt.add_argument("--resume", metavar="RUN_DIR", help="continue the run in RUN_DIR from its newest checkpoint")
    tt.add_argument("--total-steps", type=int, help="override ppo.total_steps (also extends a resumed run)")
    tt.set_defaults(func=_physics_train_tracker)
    lp = psub.add_parser("loop", help="closed loop: the motion model plans each primitive from the last two simulated "
                                      "frames; beside the open loop of the same noise (docs/physics.md)")
    lp.add_argument("--out", required=True, help="output folder for closed.npz, open_kinematic.npz and report.json")
    lp.add_argument("--text", action="append", help="prompt; repeat to chain prompts (as motion sample)")
    lp.add_argument("--seconds", type=float, help="length of the motion (default: 10)")
    lp.add_argument("--seed", type=int, default=0, help="random seed of the noise and the seed history")
    lp.add_argument("--motion", default="default", help="'default' or a latentrl model file")
    lp.add_argument("--height", type=float, default=1.72, help="humanoid height in m")
    lp.add_argument("--assist-hz", type=float, default=2.0, help="root assist frequency, 0 = off")
    lp.set_defaults(func=_physics_loop)


def _physics_loop(args: argparse.Namespace) -> int:
    from latentrl.app.physics import LoopRequest, loop_command

    return loop_command(request(LoopRequest, args))


def _physics_train_tracker(args: argparse.Namespace) -> int:
    from latentrl.app.physics_tracker import TrainTrackerRequest, train_tracker_command

    return train_tracker_command(request(TrainTrackerRequest, args))


def _physics_track(args: argparse.Namespace) -> int:
    from latentrl.app.physics import TrackRequest, track_command

    return track_command(request(TrackRequest, args))


def _scene_commands(sub) -> None:
    scene = sub.add_parser("scene", help="scene files: build one from a mesh (docs/scenes.md)")
    ssub = scene.add_subparsers(dest="scene_command", metavar="SUBCOMMAND", parser_class=_Parser)
    ssub.required = True
    fm = ssub.add_parser("from-mesh", help="voxelize a mesh (STL, OBJ, PLY, OFF, GLB) into a latentrl.scene/1 file "
                                           "of boxes (pip install 'latentrl[mesh]')")
    fm.add_argument("mesh", metavar="MESH", help="the mesh file")
    fm.add_argument("--out", required=True, help="the scene file to write (.json)")
    fm.add_argument("--voxel", type=float, default=0.1, help="voxel edge in metres, 0.01-1: the boxes reach at most "
                                                             "this far beyond the mesh (default: 0.1)")
    fm.add_argument("--scale", type=float, default=1.0, help="multiply the mesh's coordinates (0.01: centimetres)")
    fm.add_argument("--up", choices=("z", "y"), default="z", help="the mesh's up axis (y: glTF, most OBJ exports)")
    fm.add_argument("--offset", type=float, nargs=3, metavar=("X", "Y", "Z"), default=[0.0, 0.0, 0.0],
                    help="metres added after scaling: where the mesh's origin goes (the body starts at the origin "
                         "facing +y)")
    fm.add_argument("--floor-height", type=float, default=0.0, help="the scene's floor; voxels at it are dropped")
    fm.add_argument("--max-boxes", type=int, default=64, help="refuse a mesh that needs more boxes (at most 64)")
    fm.set_defaults(func=_scene_from_mesh)


def _scene_from_mesh(args: argparse.Namespace) -> int:
    from latentrl.app.scene import FromMeshRequest, from_mesh_command

    return from_mesh_command(request(FromMeshRequest, args))


def _optimize_commands(sub) -> None:
    opt = sub.add_parser("optimize", help="keyframes and joint targets by latent noise optimization (docs/optimize.md)")
    opt.add_argument("suite", metavar="SUITE", help="a latentrl.constraints/1 JSON file or a shipped suite name "
                                                     "(inbetween_walk, ...)")
    opt.add_argument("--out", help="output folder (default: ./optimize-<suite>)")
    opt.add_argument("--motion", default="default", help="'default', a latentrl model file, or a DART checkpoint")
    opt.add_argument("--steps", type=_positive(int), default=100, help="Adam steps (learning rate falls linearly to 0)")
    opt.add_argument("--lr", type=_positive(float), default=0.05, help="Adam learning rate")
    opt.add_argument("--batch", type=_positive(int), default=16, help="problems solved together as one tensor")
    opt.add_argument("--samples", type=_positive(int), default=1, help="starts per problem; the best is kept")
    opt.add_argument("--init", default="randn", help="'zeros', 'randn' (N(0, 0.1^2)) or a reach/path policy .pt "
                                                     "(or shipped name) whose noises start the optimizer")
    opt.add_argument("--init-scale", type=float, default=0.1, help="standard deviation of the 'randn' start")
    opt.add_argument("--guidance", type=float, default=GUIDANCE_SCALE, help="classifier-free guidance scale")
    opt.add_argument("--stop-cm", type=_positive(float), help="end a batch once every problem is within this (cm)")
    for name, default, what in (("floor", 1.0, "floor distance (m)"), ("skate", 1.0, "foot skate (m/s)"),
                                ("jerk", 0.0, "jerk (m/s^3)"), ("prior", 0.1, "noise above the Gaussian shell")):
        opt.add_argument(f"--{name}", type=float, default=default, help=f"weight of the {what} regularizer")
    opt.add_argument("--problem", dest="problems", action="append", metavar="NAME", help="solve only this problem")
    opt.add_argument("--device", default="cpu", type=_device, help="torch device")
    opt.add_argument("--seed", type=_seed, default=0, help="random seed of the starts")
    opt.add_argument("--no-progress", action="store_true", help="hide the progress bar")
    opt.set_defaults(func=_optimize)


def _optimize(args: argparse.Namespace) -> int:
    from latentrl.app.optimize import OptimizeRequest, optimize_command

    return optimize_command(request(OptimizeRequest, args))


def build_parser() -> argparse.ArgumentParser:
    """The ``latentrl`` argument parser with every subcommand (motion, data, train, eval, optimize, bench, ...)."""
    from latentrl import __version__

    parser = _Parser(prog="latentrl", description="Train RL controllers in DART's latent motion space.")
    parser.add_argument("--version", action="version", version=f"latentrl {__version__}")
    parser.add_argument("--debug", action="store_true", help="show full tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    _motion_commands(sub)
    _data_commands(sub)
    _train_commands(sub)
    _eval_commands(sub)
    _optimize_commands(sub)
    _bench_commands(sub)
    _viewer_commands(sub)
    _export_commands(sub)
    _list_commands(sub)
    _physics_commands(sub)
    _scene_commands(sub)
    _add_examples(parser)
    return parser


def request(cls: type, args: argparse.Namespace):
    """The request dataclass ``cls`` filled from parsed arguments of the same names.

    ``--set`` fills ``overrides`` and ``--no-progress`` clears ``progress``; arguments left at None
    keep the request's default.
    """
    given = dict(vars(args))
    if "set" in given:
        given["overrides"] = list(given.pop("set") or [])
    if "no_progress" in given:
        given["progress"] = not given.pop("no_progress")
    names = {f.name for f in dataclasses.fields(cls)}
    return cls(**{k: v for k, v in given.items() if k in names and v is not None})


def _motion_info(args: argparse.Namespace) -> int:
    from latentrl.app.motion import InfoRequest, info

    return info(request(InfoRequest, args))


def _motion_sample(args: argparse.Namespace) -> int:
    from latentrl.app.motion import SampleRequest, sample

    return sample(request(SampleRequest, args))


def _motion_train(args: argparse.Namespace) -> int:
    from latentrl.app.motion import MotionTrainRequest, train

    return train(request(MotionTrainRequest, args))


def _motion_export_bvh(args: argparse.Namespace) -> int:
    from latentrl.app.motion import ExportBvhRequest, export_bvh

    return export_bvh(request(ExportBvhRequest, args))


def _quickstart(args: argparse.Namespace) -> int:
    from latentrl.app.train import QuickstartRequest, quickstart

    return quickstart(request(QuickstartRequest, args))


def _train(args: argparse.Namespace) -> int:
    from latentrl.app.train import TrainRequest, train

    return train(request(TrainRequest, args))


def _bench_preflight(args: argparse.Namespace) -> None:
    """Before any benchmark runs: its --json must be writable and the tools it names must exist."""
    import shutil

    from latentrl.errors import ConfigError
    from latentrl.preflight import check_output_file

    if getattr(args, "json", None):
        check_output_file(args.json, "--json")
    python = getattr(args, "dart_python", None)
    if python and not (Path(python).is_file() or shutil.which(python)):
        raise ConfigError(f"--dart-python {python}: no such program (give the python of an environment "
                          "that can import DART)")
    for flag in ("dart_src", "dart_bench"):
        value = getattr(args, flag, None)
        if value and not Path(value).exists():
            raise ConfigError(f"--{flag.replace('_', '-')} {value}: not found")


def _bench_rollout(args: argparse.Namespace) -> int:
    _bench_preflight(args)
    from latentrl.app.bench.rollout import RolloutBenchRequest, bench_rollout

    return bench_rollout(request(RolloutBenchRequest, args))


def _bench_env(args: argparse.Namespace) -> int:
    _bench_preflight(args)
    from latentrl.app.bench.env import EnvBenchRequest, bench_env

    return bench_env(request(EnvBenchRequest, args))


def _bench_train(args: argparse.Namespace) -> int:
    _bench_preflight(args)
    from latentrl.app.bench.train import TrainBenchRequest, bench_train

    return bench_train(request(TrainBenchRequest, args))


def _bench_motion(args: argparse.Namespace) -> int:
    _bench_preflight(args)
    from latentrl.app.bench.motion import MotionBenchRequest, bench_motion

    return bench_motion(request(MotionBenchRequest, args))


def _evaluate(args: argparse.Namespace) -> int:
    from latentrl.app.evaluate import EvalRequest, evaluate

    return evaluate(request(EvalRequest, args))


def _compare(args: argparse.Namespace) -> int:
    from latentrl.app.evaluate import CompareRequest, compare

    return compare(request(CompareRequest, args))


def _convert_amass(args: argparse.Namespace) -> int:
    from latentrl.datasets.amass import ConvertAmassRequest, run_convert

    return run_convert(request(ConvertAmassRequest, args))


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; returns its exit status (argparse's too: 0 after ``--help``, 2 for bad arguments)."""
    program = argv is None  # the process itself (console script, python -m), not a caller in Python
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:
        return exc.code if isinstance(exc.code, int) else int(exc.code is not None)
    if program:
        interrupts.install()  # SIGTERM (preemption, kill) saves and stops like Ctrl-C
    code = _dispatch(args, program)
    if program and "latentrl.ppo.distributed" in sys.modules:  # a command that never loaded it has no process group
        from latentrl.ppo import distributed

        if distributed.launched():  # a torchrun rank: leave without tearing the C++ runtime down
            distributed.end_process(code)
    return code


def _dispatch(args: argparse.Namespace, program: bool) -> int:
    """Run the parsed command; every error becomes its one line and exit status."""
    try:
        return args.func(args)
    except LatentRLError as exc:
        if args.debug:
            raise
        print(f"latentrl: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except OSError as exc:  # disk full, permission denied, ... while a command runs: not bad input, exit 1
        if args.debug:
            raise
        where = f": {exc.filename}" if exc.filename else ""
        print(f"latentrl: error: {exc.strerror or exc}{where} (--debug shows the traceback)", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        if program and threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_IGN)  # handled: another Ctrl-C must not cut the exit short
        code = interrupts.exit_code()
        print("latentrl: interrupted" + (" by SIGTERM" if code == 143 else ""), file=sys.stderr)
        return code


if __name__ == "__main__":
    sys.exit(main())
