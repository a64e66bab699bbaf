"""``latentrl optimize``: solve a constraint suite by latent noise optimization (a thin shell over latentrl.optim)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch
from tqdm import tqdm

from latentrl.constants import GUIDANCE_SCALE
from latentrl.errors import ConfigError
from latentrl.motion.checkpoint import load_motion_model
from latentrl.optim import OptimizeSettings, load_suite, optimize
from latentrl.optim.report import write_outputs
from latentrl.optim.solver import INITS, add_unconstrained_jerk
from latentrl.optim.warm import policy_warm_start
from latentrl.preflight import check_device, check_writable, locked_output
from latentrl.resources import task_file
from latentrl.timing import hardware


@dataclass
class OptimizeRequest:
    """``latentrl optimize``: a suite, a motion model and the optimizer's settings."""

    suite: str
    out: str | None = None
    motion: str = "default"
    steps: int = 100
    lr: float = 0.05
    batch: int = 16
    samples: int = 1
    init: str = "randn"
    init_scale: float = 0.1
    guidance: float = GUIDANCE_SCALE
    device: str = "cpu"
    seed: int = 0
    stop_cm: float | None = None
    floor: float = 1.0
    skate: float = 1.0
    jerk: float = 0.0
    prior: float = 0.1
    problems: list[str] | None = None
    progress: bool = True


def optimize_command(req: OptimizeRequest) -> int:
    """Load, solve, write ``report.json``/``report.md``, ``optimize.png`` and ``motions/<problem>.npz``."""
    check_device(req.device, "--device")
    path = task_file(req.suite, "constraints") or Path(req.suite)
    problems = load_suite(path)
    if req.problems:
        known = {p.name for p in problems}
        missing = [n for n in req.problems if n not in known]
        if missing:
            raise ConfigError(f"--problem {missing[0]!r}: not in {path} (it has {', '.join(sorted(known))[:200]})")
        problems = [p for p in problems if p.name in req.problems]
    settings = OptimizeSettings(steps=req.steps, lr=req.lr, init=req.init, init_scale=req.init_scale,
                                samples=req.samples, batch=req.batch, guidance=req.guidance, seed=req.seed,
                                weights={"floor": req.floor, "skate": req.skate, "jerk": req.jerk,
                                         "prior": req.prior}, stop_cm=req.stop_cm)
    settings.check()
    warm = None
    if req.init not in INITS:
        warm = policy_warm_start(req.init)
    out_dir = Path(req.out) if req.out else Path.cwd() / f"optimize-{path.stem}"
    check_writable(out_dir, "--out")
    model = load_motion_model(req.motion, device=req.device)
    torch.manual_seed(req.seed)
    bar = None
    if req.progress:
        bar = tqdm(total=settings.steps * len(problems), unit="step", desc="optimize", dynamic_ncols=True)
    with locked_output(out_dir):  # one optimize per folder; a failure removes the folder this command created
        results = optimize(model, problems, settings, warm_start=warm,
                           on_step=None if bar is None else (lambda _step, count: bar.update(count)))
        if bar is not None:
            bar.close()
        add_unconstrained_jerk(model, results, settings.guidance, seed=req.seed)
        header = {"suite": str(path), "motion_model": req.motion, "device": req.device, "hardware": hardware()}
        report = write_outputs(results, out_dir, settings, header)
    print((out_dir / "report.md").read_text(encoding="utf-8"))
    print(f"wrote {report} and {len(results)} motions in {out_dir / 'motions'}")
    return 0
