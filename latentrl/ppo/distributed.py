"""Data-parallel PPO on ``torch.distributed``: rank helpers and the collectives the runner needs.

Launched by ``torchrun`` (or ``latentrl train --nproc N``), every process is one rank with its own
envs. :func:`current` reads torchrun's ``RANK``/``WORLD_SIZE``/``LOCAL_RANK`` and returns a
:class:`Collective`; without them it returns :data:`SINGLE`, whose methods do nothing, so the
trainers run one code path. What is synchronized (rsl_rl's scheme):

- the policy's weights and buffers are broadcast from rank 0 at the start (and after a resume);
- gradients are averaged over ranks before every optimizer step (:meth:`Collective.average_gradients`),
  so Adam takes the same step everywhere and the weights stay identical;
- the observation normalizer folds in the moments of *all* ranks' rollouts (:meth:`Collective.fold_moments`);
- the approx-KL early stop decides on the mean over ranks (every rank stops at the same minibatch);
- episode statistics and reward terms are gathered for logging (:meth:`Collective.gather`);
- rank 0 alone logs, evaluates and checkpoints; the stop flag of its evaluation is broadcast.

A rank that fails makes ``torchrun`` stop the others; the process-group timeout
(``LATENTRL_DIST_TIMEOUT`` seconds, default 1800, since the other ranks wait while rank 0 evaluates)
bounds every collective in case a rank hangs.
"""

from __future__ import annotations

import contextlib
import datetime
import os
import re
import signal
import subprocess
import sys
import threading
from collections.abc import Iterable, Iterator
from typing import Any

import torch
from torch import nn

from latentrl.errors import ConfigError, LatentRLError


class RankLostError(LatentRLError):
    """A collective failed because another rank died or hung: a fault of the run, not bad input (exit 1)."""

    exit_code = 1


def _first_line(exc: BaseException) -> str:
    """The gist of a backend error: its first line without the ``[file.cc:123]`` prefix, at most 160 characters."""
    text = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    text = re.sub(r"^\[[^\]]*\.(cc|cpp|h):\d+\]\s*", "", text)
    return text if len(text) <= 160 else text[:157] + "..."

TIMEOUT_VAR = "LATENTRL_DIST_TIMEOUT"
DEFAULT_TIMEOUT_S = 1800.0


MAX_TIMEOUT_S = 7 * 24 * 3600.0
LAUNCH_VARS = ("RANK", "WORLD_SIZE", "MASTER_ADDR", "MASTER_PORT")
"""What torchrun sets for every rank; ``init_process_group`` needs all four."""


def launched() -> bool:
    """Whether this process was started by torchrun: ``RANK``, ``WORLD_SIZE``, ``MASTER_ADDR``, ``MASTER_PORT`` set.

    Why all four: a stray ``RANK``/``WORLD_SIZE`` (left by a cluster job or a notebook) is not a launch,
    and without ``MASTER_ADDR`` the rendezvous fails (see :func:`check_environment`).
    """
    return all(os.environ.get(name) for name in LAUNCH_VARS)


def _env_int(name: str, low: int, default: int) -> int:
    """Environment variable ``name`` as an integer >= ``low`` (``default`` when unset), or one line naming it."""
    raw = os.environ.get(name)
    if not raw:
        return default
    try:
        value = int(raw.strip())
    except ValueError:
        value = low - 1
    if value < low:
        raise ConfigError(f"environment variable {name}={raw!r}: expected an integer >= {low} (torchrun sets it); "
                          f"unset it, or start the ranks with torchrun or latentrl train --nproc N")
    return value


def check_environment() -> str | None:
    """Check torchrun's variables before anything starts; a note when stray ones are ignored, else None.

    A complete launch (:func:`launched`) must have integer ``RANK`` < ``WORLD_SIZE`` and ``LOCAL_RANK``
    and a valid :func:`timeout_s`. A partial one is a leftover: with ``WORLD_SIZE`` above 1 it is
    refused in one line (the other ranks would wait for a rendezvous that never comes), otherwise it is
    ignored and the note says so (the run is one process).
    """
    present = [name for name in ("RANK", "WORLD_SIZE", "LOCAL_RANK", "MASTER_ADDR", "MASTER_PORT")
               if os.environ.get(name)]
    if not present:
        return None
    world = _env_int("WORLD_SIZE", 1, 1)
    rank = _env_int("RANK", 0, 0)
    _env_int("LOCAL_RANK", 0, 0)
    shown = " ".join(f"{name}={os.environ[name]}" for name in present)
    if launched():
        if rank >= world:
            raise ConfigError(f"environment: RANK={rank} must be below WORLD_SIZE={world} ({shown})")
        timeout_s()
        return None
    missing = [name for name in LAUNCH_VARS if not os.environ.get(name)]
    if world > 1:
        raise ConfigError(f"environment: {shown} is set but {' and '.join(missing)} not: not a complete torchrun "
                          f"launch; unset {' '.join(n for n in present if n in ('RANK', 'WORLD_SIZE', 'LOCAL_RANK'))}"
                          f" to train in one process, or start the ranks with torchrun or latentrl train --nproc N")
    if any(name in present for name in ("RANK", "WORLD_SIZE", "LOCAL_RANK")):
        return f"ignoring {shown} ({' and '.join(missing)} not set: not a torchrun launch); training in one process"
    return None


def timeout_s() -> float:
    """Seconds each collective may wait: ``LATENTRL_DIST_TIMEOUT`` (default 1800), a number in (0, 7 days]."""
    raw = os.environ.get(TIMEOUT_VAR)
    if raw is None:
        return DEFAULT_TIMEOUT_S
    try:
        value = float(raw)
    except ValueError:
        value = float("nan")
    if not 0 < value <= MAX_TIMEOUT_S:  # NaN fails both
        raise ConfigError(f"environment variable {TIMEOUT_VAR}={raw!r}: expected the seconds each collective may "
                          f"wait, a number in (0, {MAX_TIMEOUT_S:.0f}] (default {DEFAULT_TIMEOUT_S:.0f}); fix or "
                          "unset it")
    return value


def local_rank() -> int:
    """This process's GPU index on its node (torchrun's ``LOCAL_RANK``; 0 outside torchrun)."""
    return _env_int("LOCAL_RANK", 0, 0)


def rank_device(device: str) -> str:
    """The device of this rank: ``cuda`` (any index) becomes ``cuda:LOCAL_RANK`` under torchrun; CPU stays."""
    if launched() and torch.device(device).type == "cuda":
        if local_rank() >= torch.cuda.device_count():
            raise ConfigError(f"rank with LOCAL_RANK {local_rank()} needs GPU {local_rank()}, but this node has "
                              f"{torch.cuda.device_count()}; start at most one rank per GPU (--nproc-per-node)")
        return f"cuda:{local_rank()}"
    return device


def backend_for(device: str) -> str:
    """The process-group backend: nccl for CUDA ranks, gloo for CPU ranks."""
    return "nccl" if torch.device(device).type == "cuda" else "gloo"


class Collective:
    """One rank of a process group (or, as :data:`SINGLE`, the only process: every method is the identity)."""

    def __init__(self, rank: int = 0, world_size: int = 1):
        self.rank, self.world_size = rank, world_size

    @contextlib.contextmanager
    def guard(self, op: str) -> Iterator[None]:
        """Turn a collective that fails because another rank is gone into one :class:`RankLostError` line."""
        try:
            yield
        except RuntimeError as exc:  # gloo/nccl: a peer closed its connection, or the timeout passed
            if re.search(r"timed out|timeout", str(exc), re.I):
                raise RankLostError(f"rank {self.rank}: {op} timed out after {timeout_s():g} s ({TIMEOUT_VAR}) "
                                    "waiting for the other ranks; another rank hung or stopped, so this one stops "
                                    "too") from None
            raise RankLostError(f"rank {self.rank}: {op} with the other ranks failed ({_first_line(exc)}); another "
                                f"rank stopped or hung, so this one stops too") from None

    @property
    def enabled(self) -> bool:
        """More than one rank: only then do the collectives communicate."""
        return self.world_size > 1

    @property
    def is_main(self) -> bool:
        """Rank 0: the one that logs, evaluates and writes checkpoints."""
        return self.rank == 0

    # ------------------------------------------------------------------ start
    @torch.no_grad()
    def broadcast_module(self, module: nn.Module) -> None:
        """Copy rank 0's parameters and buffers to every rank."""
        if not self.enabled:
            return
        for tensor in list(module.parameters()) + list(module.buffers()):
            with self.guard("broadcast"):
                torch.distributed.broadcast(tensor.data, src=0)

    def broadcast_object(self, value: Any) -> Any:
        """Rank 0's ``value`` on every rank (a run directory, a stop flag)."""
        if not self.enabled:
            return value
        box = [value]
        with self.guard("broadcast_object_list"):
            torch.distributed.broadcast_object_list(box, src=0)
        return box[0]

    def any(self, flag: bool) -> bool:
        """Whether ``flag`` is true on at least one rank (one small all-reduce): a decision every rank takes alike."""
        if not self.enabled:
            return flag
        nccl = torch.distributed.get_backend() == "nccl"
        device = torch.device("cuda", torch.cuda.current_device()) if nccl else None
        value = torch.tensor([int(flag)], dtype=torch.int32, device=device)
        with self.guard("all_reduce"):
            torch.distributed.all_reduce(value, op=torch.distributed.ReduceOp.MAX)
        return bool(value.item())

    # ------------------------------------------------------------------ update
    def average_gradients(self, params: Iterable[nn.Parameter]) -> None:
        """Replace every gradient by its mean over ranks (one flat all-reduce)."""
        if not self.enabled:
            return
        grads = [p.grad for p in params if p.grad is not None]
        if not grads:
            return
        flat = torch.cat([g.reshape(-1) for g in grads])
        with self.guard("all_reduce"):
            torch.distributed.all_reduce(flat)
        flat /= self.world_size
        offset = 0
        for g in grads:
            g.copy_(flat[offset:offset + g.numel()].view_as(g))
            offset += g.numel()

    def mean(self, value: torch.Tensor) -> torch.Tensor:
        """Mean of a tensor over ranks (a new tensor)."""
        if not self.enabled:
            return value
        value = value.detach().clone()
        with self.guard("all_reduce"):
            torch.distributed.all_reduce(value)
        return value / self.world_size

    @torch.no_grad()
    def fold_moments(self, normalizer: nn.Module | None, obs: torch.Tensor) -> None:
        """Fold every rank's observations ``obs`` (..., D) into ``normalizer`` (a ``RunningNormalizer``).

        Each rank's (count, mean, M2) are combined exactly (Chan et al.): two all-reduces, then the
        same ``update_from_moments`` on every rank, so the statistics stay identical.
        """
        if normalizer is None:
            return
        if not self.enabled:
            normalizer.update(obs)
            return
        batch = obs.reshape(-1, obs.shape[-1]).to(normalizer.mean.dtype)
        n_local = float(batch.shape[0])
        mean_local = batch.mean(0)
        head = torch.cat((torch.tensor([n_local], dtype=batch.dtype, device=batch.device), mean_local * n_local))
        with self.guard("all_reduce"):
            torch.distributed.all_reduce(head)
        n = head[0]
        mean = head[1:] / n
        m2 = (batch - mean).square().sum(0)  # this rank's squared deviations from the global mean
        with self.guard("all_reduce"):
            torch.distributed.all_reduce(m2)
        normalizer.update_from_moments(mean, m2 / n, int(n.item()))

    # ------------------------------------------------------------------ logging
    def gather(self, value: Any) -> list[Any]:
        """Every rank's picklable ``value``, in rank order (``[value]`` in one process)."""
        if not self.enabled:
            return [value]
        out: list[Any] = [None] * self.world_size
        with self.guard("all_gather_object"):
            torch.distributed.all_gather_object(out, value)
        return out

    @torch.no_grad()
    def check_identical(self, module: nn.Module) -> str | None:
        """None if ``module``'s parameters agree on every rank, else which rank and tensor differ."""
        if not self.enabled:
            return None
        names, tensors = zip(*module.named_parameters())
        sums = torch.stack([t.detach().double().sum() for t in tensors]).cpu()
        everyone = self.gather(sums)
        for r, other in enumerate(everyone):
            if not torch.equal(other, everyone[0]):
                i = int((other != everyone[0]).nonzero()[0, 0])
                return f"policy weight '{names[i]}' differs between rank 0 and rank {r}"
        return None

    def barrier(self) -> None:
        """Wait until every rank gets here (nothing to wait for in one process)."""
        if self.enabled:
            with self.guard("barrier"):
                torch.distributed.barrier()


SINGLE = Collective()
"""The single-process collective (no process group)."""

_current: Collective = SINGLE


def init(device: str) -> Collective:
    """Join torchrun's process group (nccl on CUDA, gloo on CPU) once; :data:`SINGLE` when not launched."""
    global _current
    if not launched() or _current is not SINGLE:
        return _current
    if torch.device(device).type == "cuda":
        torch.cuda.set_device(local_rank())
    timeout = datetime.timedelta(seconds=timeout_s())
    torch.distributed.init_process_group(backend_for(device), timeout=timeout)
    _current = Collective(torch.distributed.get_rank(), torch.distributed.get_world_size())
    return _current


def current() -> Collective:
    """The collective :func:`init` set up, or :data:`SINGLE`."""
    return _current


def shutdown() -> None:
    """Leave the process group (end of a run).

    The ranks meet at a barrier first, so no rank tears its connections down while another still uses them (a
    rank that left early made its peer abort on exit with "terminate called without an active exception").
    """
    global _current
    if _current is not SINGLE and torch.distributed.is_initialized():
        try:
            torch.distributed.barrier()
        except RuntimeError:  # a peer is gone: nothing left to wait for
            pass
        torch.distributed.destroy_process_group()
    _current = SINGLE


def end_process(code: int) -> None:
    """End a torchrun-launched rank's process now with ``code``, its output flushed (and after :func:`shutdown`).

    A failed rank (``code`` != 0) skips the shutdown: it must not wait at a barrier for peers that may be gone.

    Why: at interpreter exit, C++ objects the process group leaves behind (gloo's threads) are destroyed in no
    fixed order, and now and then one aborts the process ("terminate called without an active exception"),
    which torchrun reports as a failed rank after a run that finished. Everything a run writes is on disk by
    now (checkpoints and logs are closed), so the rank skips the teardown (``os._exit``).
    """
    import logging

    if code == 0:
        shutdown()
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(code)


# --------------------------------------------------------------------------- torchrun's report
_ELASTIC_LOG = re.compile(r"^[IWE]\d{4} [\d:.]+ +\d+ .*torch/distributed/")
_TIMED_OUT = re.compile(r"^(?:\[rank\d+\]: ?)?latentrl: error: rank (\d+): \S+ timed out after ([\d.e+]+) s")
"""A rank's :class:`RankLostError` line for a collective that waited ``LATENTRL_DIST_TIMEOUT`` in vain."""


class TorchrunOutput:
    """Filters torchrun's stderr for ``latentrl train --nproc``: the ranks' lines pass, torchrun's own go.

    Why: when a rank dies, torchrun logs its agent's steps and raises ``ChildFailedError`` with a
    traceback and a report block. :meth:`cause` reads the report's root cause (which rank, its exit
    code or signal) so the launcher can say it in one line instead.
    """

    def __init__(self) -> None:
        self.held: list[str] = []
        self.report: list[str] | None = None
        self.report_done = False
        self.timed_out: dict[int, str] = {}
        """rank -> seconds, for the ranks whose collective timed out (their own line said so)."""
        self.timed_out_lines: list[str] = []
        """Those lines, held back: :meth:`cause` restates them with the rank that hung."""

    def feed(self, line: str) -> list[str]:
        """The lines to show now, given the next line of torchrun's stderr."""
        if waited := _TIMED_OUT.match(line):
            self.timed_out[int(waited.group(1))] = waited.group(2)
            self.timed_out_lines.append(line)
            return []
        if _ELASTIC_LOG.match(line):
            return []
        if self.report is not None and not self.report_done:
            self.report.append(line)
            if line.startswith("====") and any(x.startswith("Root Cause") for x in self.report):
                self.report_done = True
            return []
        if line.startswith("Traceback (most recent call last):"):
            shown, self.held = self.held, [line]
            return shown
        if self.held:
            if line[:1].isspace():
                self.held.append(line)
                return []
            if "ChildFailedError" in line:  # torchrun's own traceback: keep only its report
                self.held, self.report, self.report_done = [], [line], False
                return []
            if line.startswith("torch.distributed.elastic."):  # torchrun's own (SignalException on Ctrl-C)
                self.held = []
                return []
            shown, self.held = self.held + [line], []
            return shown
        return [line]

    def flush(self) -> list[str]:
        """Lines still held back (a traceback that did not end; timed-out lines when torchrun made no report)."""
        shown, self.held = self.held, []
        if not self.report:
            shown, self.timed_out_lines = self.timed_out_lines + shown, []
        return shown

    def cause(self) -> str | None:
        """``rank 1 was killed by SIGKILL`` / ``rank 0 exited with code 2``: the report's root cause, if any."""
        if not self.report:
            return None
        text = "".join(self.report)
        root = text.split("Root Cause", 1)[-1]
        rank = re.search(r"rank\s*:\s*(\d+)", root)
        code = re.search(r"exitcode\s*:\s*(-?\d+)", root)
        if not rank or not code:
            return None
        value = int(code.group(1))
        if int(rank.group(1)) in self.timed_out:  # not its fault: the ranks torchrun had to kill hung
            failures = text.split("Root Cause", 1)[0]
            hung = [r for r, c in re.findall(r"rank\s*:\s*(\d+).*?exitcode\s*:\s*(-?\d+)", failures, re.S)
                    if int(c) == -signal.SIGKILL]
            who = (f"{'rank' if len(hung) == 1 else 'ranks'} {', '.join(hung)} hung (did not stop when asked; "
                   "killed by SIGKILL)" if hung else "another rank hung or stopped")
            return (f"rank {rank.group(1)} timed out after {self.timed_out[int(rank.group(1))]} s ({TIMEOUT_VAR}) "
                    f"waiting for the other ranks: {who}")
        if value < 0:
            try:
                name = signal.Signals(-value).name
            except ValueError:
                name = f"signal {-value}"
            return f"rank {rank.group(1)} was killed by {name}"
        return f"rank {rank.group(1)} exited with code {value}"


def run_torchrun(cmd: list[str]) -> tuple[int, TorchrunOutput]:
    """Run torchrun's ``cmd`` for ``latentrl train --nproc``: its exit code and its filtered stderr.

    torchrun runs in its own session, so the signals that stop a run reach this launcher alone, and the
    launcher passes the first of them on as one SIGINT: Ctrl-C from a terminal, SIGTERM to its PID (a
    scheduler's preemption, after :func:`latentrl.interrupts.install`) and SIGHUP (the terminal closed).
    torchrun then sends each rank SIGINT; the ranks agree on the iteration to stop at (the runner's
    ``Collective.any``), rank 0 saves it, and this raises ``KeyboardInterrupt`` once torchrun has ended.
    A second signal stops waiting (torchrun gets SIGTERM). Works even when the shell started the launcher
    with SIGINT ignored, as the ranks do.
    """
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.default_int_handler)
        if hasattr(signal, "SIGHUP"):
            signal.signal(signal.SIGHUP, signal.default_int_handler)
    proc = subprocess.Popen(cmd, stderr=subprocess.PIPE, text=True, errors="replace", bufsize=1,
                            start_new_session=True)
    output = TorchrunOutput()  # the ranks' lines pass; torchrun's report becomes the caller's one line
    interrupted = False
    while True:
        try:
            for line in proc.stderr:
                sys.stderr.writelines(output.feed(line))
                sys.stderr.flush()
            break
        except KeyboardInterrupt:
            if interrupted:  # a second signal: stop waiting for the ranks
                with contextlib.suppress(ProcessLookupError):
                    os.killpg(proc.pid, signal.SIGTERM)
                raise
            interrupted = True  # every rank saves the same iteration and stops; keep showing what they say
            with contextlib.suppress(ProcessLookupError):  # torchrun may have ended already
                os.killpg(proc.pid, signal.SIGINT)
    sys.stderr.writelines(output.flush())
    code = proc.wait()
    if interrupted:
        raise KeyboardInterrupt
    return code, output
