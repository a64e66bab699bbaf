"""The runner around a PPO implementation: loop bookkeeping, logging, evaluation, checkpoints, resume, guards.

:class:`Runner` owns what the native and the SB3 trainer share: the run's config and identity,
seeding, the iteration/step/time counters, checkpoints (save, prune, resume with its checks),
the TensorBoard :class:`~latentrl.monitor.Monitor` and progress bar around :meth:`Runner.learn`,
the periodic evaluation, and the non-finite guards. A backend (:mod:`latentrl.ppo.trainer`,
:mod:`latentrl.ppo.sb3`) builds its policy and optimizer, runs its iterations in :meth:`Runner.learn`
and calls :meth:`Runner.finish_iteration` after each.

Non-finite values stop the run: the backend checks the rollout and, after each update, the losses
and weights, and :func:`stop_if_nonfinite` raises a :class:`~latentrl.errors.NonFiniteError` naming
the iteration, the quantity and the last good checkpoint, which is left as it was (nothing is
saved after the bad iteration).
"""

from __future__ import annotations

import contextlib
import random
import signal
import sys
import threading
import time
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch

from latentrl import interrupts
from latentrl.errors import ConfigError, NonFiniteError
from latentrl.monitor import EvalReport, Monitor, RolloutStats
from latentrl.ppo import checkpoint as ckpt
from latentrl.ppo import distributed
from latentrl.ppo.config import BatchPlan, PolicyConfig, PPOConfig
from latentrl.ppo.policy import ActorCritic
from latentrl.ppo.progress import RunProgress
from latentrl.ppo.storage import RolloutBuffer
from latentrl.ppo.warm_start import warm_start
from latentrl.resources import policy_file

Evaluator = Callable[[ActorCritic], EvalReport]
"""Evaluation hook: gets the policy (eval mode), returns metrics and figures; must not train it."""


class IterationTime(NamedTuple):
    """Where one iteration's wall time went: collecting the rollout or updating the policy."""
    collection_s: float
    """Wall seconds collecting the rollout (GAE included)."""
    update_s: float
    """Wall seconds in the PPO update."""


class TrainResult(NamedTuple):
    """What a finished training run returns: where it wrote, how far it got and its last statistics."""
    run_dir: Path
    final_checkpoint: Path
    iterations: int
    env_steps: int
    elapsed_s: float
    rollout: RolloutStats
    """Episode statistics over the last ``stats_window`` episodes at the end."""
    train: dict[str, float]
    """Update statistics of the last iteration ({} if no iteration ran)."""
    eval: EvalReport | None
    """The last evaluation, if any ran."""
    times: list[IterationTime]
    """Per-iteration timings of the iterations this call ran (benchmarks)."""
    stopped_early: bool
    """An evaluation asked to stop (``EvalReport.stop``) before ``num_iterations``."""


def seed_everything(seed: int, deterministic: bool = True) -> None:
    """Seed python, numpy and torch (all devices); ask cuDNN for deterministic kernels."""
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)
    torch.backends.cudnn.deterministic = deterministic
    if deterministic:
        torch.backends.cudnn.benchmark = False


def run_evaluation(evaluate: Evaluator, policy: ActorCritic) -> EvalReport:
    """Call the hook in eval mode without perturbing the training random streams (restored afterwards)."""
    state = ckpt.capture_rng()
    was_training = policy.training
    policy.eval()
    try:
        with torch.no_grad():
            report = evaluate(policy)
    finally:
        ckpt.restore_rng(state)
        policy.train(was_training)
    return report if isinstance(report, EvalReport) else EvalReport(dict(report))


# --------------------------------------------------------------------------- non-finite guards
LOSS_NAMES = {"policy_gradient_loss": "policy loss", "value_loss": "value loss", "entropy_loss": "entropy loss",
              "loss": "total loss", "approx_kl": "approx KL", "grad_norm": "gradient norm"}
"""Update statistics that must be finite, and how errors name them."""
ROLLOUT_HINT = "the env must return finite observations and rewards"
UPDATE_HINT = "a new run with a lower ppo.learning_rate or max_grad_norm may avoid it"


def nonfinite_rollout(buffer: RolloutBuffer) -> str | None:
    """The first non-finite quantity of a filled buffer, e.g. ``'reward of env 3 at rollout step 5 is nan'``.

    The fast path sums each tensor (a sum is finite only if every element is) and syncs once; the
    slow path, which finds the env and step, runs only when something is wrong. None if all is finite.
    Final observations count only where an episode ended (the rows GAE reads).
    """
    checks = (("observation", buffer.obs), ("reward", buffer.rewards), ("value estimate", buffer.values),
              ("advantage", buffer.advantages))
    read_final = torch.where(buffer.dones[..., None], buffer.final_obs, 0.0)
    if bool(torch.isfinite(torch.stack([x.sum() for _, x in checks] + [read_final.sum()])).all()):
        return None
    T, N = buffer.num_steps, buffer.num_envs
    ended = buffer.dones.nonzero()  # (M, 2) [t, n] of the rows whose final observation is read
    final = buffer.final_obs[buffer.dones]  # (M, D)
    found = [(name, (~torch.isfinite(x.reshape(T, N, -1)).all(-1)).nonzero(), x) for name, x in checks]
    found.append(("final observation", ended[(~torch.isfinite(final).all(-1)).nonzero()[:, 0]], buffer.final_obs))
    for name, where, x in found:
        if len(where):
            t, n = (int(i) for i in where[0])
            row = x[t, n].reshape(-1)
            value = row[~torch.isfinite(row)][0].item()
            if name == "observation":  # row t holds the observation step t - 1 returned (row 0: the rollout's start)
                when = f"returned by rollout step {t - 1}" if t else "at the start of the rollout"
                return f"observation of env {n} {when} is {value}"
            return f"{name} of env {n} at rollout step {t} is {value}"
    return None  # a sum overflowed, but every value is finite


def nonfinite_update(stats: Mapping[str, float], policy: torch.nn.Module) -> str | None:
    """The first non-finite update statistic or weight after a PPO update, or None."""
    for key, name in LOSS_NAMES.items():
        value = stats.get(key)
        if value is not None and not np.isfinite(value):
            others = ", ".join(f"{LOSS_NAMES[k]} {stats[k]:.4g}" for k in LOSS_NAMES if k in stats and k != key)
            return f"{name} is {value} ({others})"
    params = dict(policy.named_parameters())
    if not bool(torch.stack([torch.isfinite(p).all() for p in params.values()]).all()):
        bad = next(n for n, p in params.items() if not bool(torch.isfinite(p).all()))
        return f"policy weight '{bad}' became non-finite"
    return None


def stop_if_nonfinite(trainer: Any, bar: RunProgress, problem: str | None, hint: str = UPDATE_HINT) -> None:
    """Raise :class:`NonFiniteError` for ``problem`` in the trainer's current iteration (also logged to train.log)."""
    if problem is None:
        return
    last = trainer.last_checkpoint or "none yet"
    message = (f"iteration {trainer.iteration + 1}: {problem}; training stopped without saving this iteration "
               f"(last good checkpoint: {last}); {hint}")
    bar.write(f"stopped: {message}")
    raise NonFiniteError(message)


# --------------------------------------------------------------------------- ranks
WORLD_SIZE_KEY = "world_size"
"""Checkpoint field: the number of ranks that wrote it (absent in older checkpoints: 1)."""


def distributed_plan(ppo: PPOConfig, num_envs: int, world_size: int) -> BatchPlan:
    """``ppo.plan(num_envs)`` of one rank, with ``num_iterations`` counting steps of all ``world_size`` ranks."""
    plan = ppo.plan(num_envs)
    if world_size == 1:
        return plan
    return plan._replace(num_iterations=-(-ppo.total_steps // (plan.batch_size * world_size)))


class _Silent:
    """Monitor and progress bar of ranks other than 0: every call does nothing."""

    def __getattr__(self, name: str) -> Callable[..., None]:
        return lambda *args, **kwargs: None


# --------------------------------------------------------------------------- runner
class Runner:
    """One training run in ``run_dir``; subclasses supply the PPO implementation.

    Args:
        env: the training env (a torch ``VectorEnv``, or an SB3 ``VecEnv`` for the SB3 backend).
        run_dir: where events, checkpoints and ``train.log`` go.
        ppo: PPO settings.
        policy_cfg: network settings.
        config: the full resolved run config stored in checkpoints (default: the two sections).
        motion: ``{"path", "sha256"}`` of the env's motion model, stored and checked on resume.
        evaluate: optional evaluation hook called every ``ppo.eval_every`` iterations.
        layout: observation layout override (default: ``env.metadata["observation_layout"]``).
        progress: show the tqdm bar.

    Subclasses set :attr:`name`, build ``self.policy`` and ``self.optimizer`` in :meth:`build`, and
    implement :meth:`learn`; they may add checkpoint fields (:meth:`checkpoint_extra`,
    :meth:`load_extra`), files beside a checkpoint (:meth:`after_save`) and rollout statistics.
    """

    name = "runner"
    checkpoint_suffixes: tuple[str, ...] = ()
    """Suffixes of files the backend writes beside each checkpoint (pruned with it)."""

    def __init__(self, env: Any, run_dir: str | Path, ppo: PPOConfig, policy_cfg: PolicyConfig, *,
                 config: Any = None, motion: Mapping[str, Any] | None = None, evaluate: Evaluator | None = None,
                 layout: Mapping[str, Any] | None = None, progress: bool = True):
        ppo.validate()
        policy_cfg.validate()
        self.env, self.run_dir, self.cfg = env, Path(run_dir), ppo
        self.config = config if config is not None else {"ppo": ppo, "policy": policy_cfg}
        self.motion, self.evaluate, self.progress = motion, evaluate, progress
        self.dist = distributed.current()
        self.plan = distributed_plan(ppo, env.num_envs, self.dist.world_size)
        self.rank_seed = ppo.seed + self.dist.rank
        """The seed of this rank: ``ppo.seed + rank`` (torchrun); ``ppo.seed`` in one process."""
        seed_everything(self.rank_seed, ppo.torch_deterministic)
        self.iteration, self.env_steps, self.elapsed_s = 0, 0, 0.0
        self._pending_rng: dict | None = None
        self.last_train: dict[str, float] = {}
        self.last_eval: EvalReport | None = None
        self.times: list[IterationTime] = []
        self.stop_requested = False
        self.interrupted = False
        """Stop after this iteration, saved: decided at the iteration's end, by every rank alike (see ``signalled``)."""
        self.signalled = False
        """This process got Ctrl-C or SIGTERM; under torchrun the ranks agree on it at the next iteration end."""
        self.last_checkpoint: Path | None = None
        self.extended_from: int | None = None
        """The run's former ``ppo.total_steps`` when this resume extends it (``--total-steps``), else None."""
        """The newest checkpoint this run wrote or resumed from (named by non-finite errors)."""
        self.policy: ActorCritic
        self.optimizer: torch.optim.Optimizer
        self.build(policy_cfg, layout)
        self.warm_started: list[str] | None = None
        """The observation fields that started fresh when ``ppo.init_from`` warm-started this run, else None."""
        self.dist.broadcast_module(self.policy)

    def warm_start(self) -> None:
        """Load ``ppo.init_from``'s weights into the fresh policy (nothing without it); every rank reads the file.

        Called for a run that starts at step 0, never for a resumed one: a resume continues its own weights, so
        the source may since have moved or the run have been resumed onto another motion model. A missing file
        is a one-line config error.
        """
        spec = self.cfg.init_from
        if not spec:
            return
        path = policy_file(spec)
        if not Path(path).is_file():
            raise ConfigError(f"ppo.init_from: no policy '{spec}' (expected a shipped policy name such as "
                              "reach_walk_default or a checkpoint .pt)")
        self.warm_started = warm_start(self.policy, path, self.motion)

    # ------------------------------------------------------------------ backend
    def build(self, policy_cfg: PolicyConfig, layout: Mapping[str, Any] | None) -> None:
        """Create the policy, optimizer and backend state for this env (each trainer implements it)."""
        raise NotImplementedError

    def learn(self) -> None:
        """Run iterations until ``plan.num_iterations`` (or a stop); call :meth:`finish_iteration` after each."""
        raise NotImplementedError

    def rollout_stats(self) -> RolloutStats:
        """Episode statistics of the recent rollouts, for the log and the result."""
        raise NotImplementedError

    def checkpoint_extra(self) -> dict:
        """Backend state stored in each checkpoint beside the common fields (none by default)."""
        return {}

    def load_extra(self, extra: Mapping[str, Any]) -> None:
        """Restore what :meth:`checkpoint_extra` stored, when resuming (nothing by default)."""
        pass

    def after_save(self, path: Path) -> None:
        """Called after a checkpoint was written to ``path`` (nothing by default)."""
        pass

    # ------------------------------------------------------------------ checkpoints
    def checkpoint(self) -> dict:
        """The checkpoint state of this moment: weights, optimizer, configs, motion, env settings and world size."""
        state = ckpt.make_checkpoint(trainer=self.name, iteration=self.iteration, env_steps=self.env_steps,
                                     elapsed_s=self.elapsed_s, policy=self.policy, optimizer=self.optimizer,
                                     config=self.config, motion=self.motion, env=self.env,
                                     extra=self.checkpoint_extra())
        state[WORLD_SIZE_KEY] = self.dist.world_size
        return state

    def save(self, path: str | Path) -> Path:
        """Write a checkpoint (atomically); under torchrun only rank 0 writes, the others just note the path."""
        path = Path(path)
        if self.dist.is_main:
            path = ckpt.save_checkpoint(self.checkpoint(), path)
            self.after_save(path)
        self.last_checkpoint = path
        return path

    def resume(self, allow_motion_mismatch: bool = False) -> Path | None:
        """Continue from the newest readable checkpoint in ``run_dir``; None (fresh start) if there is none."""
        found = ckpt.load_latest(self.run_dir, map_location=self.policy_device)
        if found is None:
            warnings.warn(f"{self.run_dir}: no checkpoint to resume from; starting at step 0", stacklevel=2)
            return None
        path, state = found
        self.extended_from = ckpt.check_resumable(state, path, trainer=self.name, config=self.config,
                                                  motion=self.motion, allow_motion_mismatch=allow_motion_mismatch)
        ckpt.check_shapes(state, path, self.policy.obs_dim, self.policy.action_dim)
        self.policy.load_state_dict(state["policy"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.iteration, self.env_steps, self.elapsed_s = state["iteration"], state["env_steps"], state["elapsed_s"]
        saved_world = int(state.get(WORLD_SIZE_KEY, 1))
        if saved_world != self.dist.world_size:  # the schedule follows env steps, not iterations
            self.iteration = self.env_steps // (self.plan.batch_size * self.dist.world_size)
            warnings.warn(f"{path}: written by {saved_world} rank(s), resumed on {self.dist.world_size}: weights, "
                          f"optimizer, normalizer and {self.env_steps} env steps carry over; iteration counted "
                          f"as {self.iteration}; random streams start afresh", stacklevel=2)
        self.load_extra(state["extra"])
        # rank 0 continues the saved random streams; other ranks (and other world sizes) start from their seed
        self._pending_rng = state["rng"] if self.dist.is_main and saved_world == self.dist.world_size else None
        self.dist.broadcast_module(self.policy)
        self.last_checkpoint = path
        return path

    @property
    def policy_device(self) -> torch.device:
        """The device the policy's parameters live on."""
        return next(self.policy.parameters()).device

    def restore_pending_rng(self) -> bool:
        """After the env was reset: put back the random streams (and env state) a resumed run saved; True if any."""
        if self._pending_rng is None:
            return False
        ckpt.restore_rng(self._pending_rng, self.env)
        self._pending_rng = None
        return True

    # ------------------------------------------------------------------ loop
    def train(self) -> TrainResult:
        """Run :meth:`learn` between the monitor's and the progress bar's set-up and close; write ``final.pt``."""
        if self.dist.is_main:
            self.monitor = Monitor(self.run_dir, resume_step=self.env_steps if self.iteration else None)
            self.bar = RunProgress(self.run_dir, self.plan.num_iterations * self.global_batch_size, self.env_steps,
                                   self.progress)
        else:  # rank 0 alone writes TensorBoard and train.log
            self.monitor, self.bar = _Silent(), _Silent()
        if self.iteration == 0:
            self.monitor.log_hparams(ckpt.plain_config(self.config))
        self.bar.write(f"{self.name} trainer: start at iteration {self.iteration}, {self.env_steps} env steps, "
                       f"{self.plan.num_iterations} iterations of {self.global_batch_size} steps"
                       + (f" ({self.dist.world_size} ranks)" if self.dist.enabled else ""))
        start_iteration = self.iteration
        self._start, self._steps_at_start, self._elapsed_at_start = time.perf_counter(), self.env_steps, self.elapsed_s
        try:
            with _sigint_deferred(self):
                self.learn()
        finally:
            self.monitor.close()
            self.bar.close()
        final = self.run_dir / ckpt.FINAL
        self.check_ranks_agree()
        if self.iteration > start_iteration or not final.is_file():
            self.save(final)
        self.dist.barrier()  # final.pt exists for every rank that returns
        return TrainResult(self.run_dir, final, self.iteration, self.env_steps, self.elapsed_s, self.rollout_stats(),
                           self.last_train, self.last_eval, self.times, self.stop_requested)

    @property
    def global_batch_size(self) -> int:
        """Env steps of one iteration summed over ranks (``plan.batch_size`` per rank x world size)."""
        return self.plan.batch_size * self.dist.world_size

    def check_ranks_agree(self) -> None:
        """Under torchrun: stop if the ranks' weights drifted apart (a bug, never expected); collective."""
        problem = self.dist.check_identical(self.policy)
        if problem is not None:
            raise RuntimeError(f"iteration {self.iteration}: {problem}; distributed training is out of sync")

    def restart_clock(self) -> None:
        """Start the throughput and elapsed-time clocks now (after set-up work such as the first reset)."""
        self._start, self._steps_at_start, self._elapsed_at_start = time.perf_counter(), self.env_steps, self.elapsed_s

    def count_iteration(self, env_steps: int, collection_s: float, update_s: float) -> float:
        """Advance the counters after an update; returns env steps/s since the (re)start."""
        self.iteration, self.env_steps = self.iteration + 1, env_steps
        self.times.append(IterationTime(collection_s, update_s))
        now = time.perf_counter()
        self.elapsed_s = self._elapsed_at_start + (now - self._start)
        return (self.env_steps - self._steps_at_start) / max(now - self._start, 1e-9)

    @property
    def logging_now(self) -> bool:
        """Whether the iteration just counted is logged (every ``log_every``, and the last)."""
        return self.iteration % self.cfg.log_every == 0 or self.iteration == self.plan.num_iterations

    def finish_iteration(self, fps: float, rollout: RolloutStats) -> None:
        """After the backend logged iteration k: evaluate and checkpoint when due, flush, move the bar."""
        cfg, k, step = self.cfg, self.iteration, self.env_steps
        last = k == self.plan.num_iterations
        if cfg.eval_every and (k % cfg.eval_every == 0 or last):
            if self.evaluate is not None and self.dist.is_main:  # rank 0 evaluates; its stop holds for every rank
                self.last_eval = run_evaluation(self.evaluate, self.policy)
                self.stop_requested = bool(self.last_eval.stop)
                self.monitor.log_eval(step, self.last_eval)
                self.bar.write(f"eval iter {k} steps {step}: "
                               + " ".join(f"{n} {v:.4g}" for n, v in self.last_eval.metrics.items()))
            self.stop_requested = self.dist.broadcast_object(self.stop_requested)
        due = cfg.checkpoint_every and k % cfg.checkpoint_every == 0
        # ranks see a signal in different iterations: all stop at the first iteration end where one has it
        self.interrupted = self.interrupted or self.dist.any(self.signalled)
        if (due or self.interrupted) and not (last or self.stop_requested):
            self.check_ranks_agree()
            self.save(ckpt.iteration_path(self.run_dir, k))
            if self.dist.is_main:
                ckpt.prune_checkpoints(self.run_dir, cfg.keep_checkpoints, suffixes=self.checkpoint_suffixes)
        if self.interrupted:  # Ctrl-C: this iteration is saved (final.pt when it was the last); stop here
            end = last or self.stop_requested
            saved = self.run_dir / ckpt.FINAL if end else ckpt.iteration_path(self.run_dir, k)
            if end:
                self.save(saved)
            note = (f"interrupted: saved iteration {k} ({step} env steps) to {saved}; "
                    f"continue with --resume {self.run_dir}")
            if self.dist.is_main:
                self.bar.write(note)
            print(note, file=sys.stderr, flush=True)
            raise KeyboardInterrupt
        self.monitor.flush()
        self.bar.update(step, fps, rollout)


@contextlib.contextmanager
def _sigint_deferred(runner: Runner):
    """While training, the first Ctrl-C asks the runner to save after this iteration and stop.

    SIGTERM reaches this handler too (:func:`latentrl.interrupts.install`). A second Ctrl-C stops at once.
    Only the main thread can install the handler; elsewhere nothing changes.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        if runner.signalled:
            raise KeyboardInterrupt
        runner.signalled = True
        print(f"\n{interrupts.signal_name(signum)}: saving a checkpoint after this iteration "
              "(Ctrl-C again to stop without saving)", file=sys.stderr, flush=True)

    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
