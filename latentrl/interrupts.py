"""Ctrl-C (SIGINT) and preemption (SIGTERM) stop a long command the same way: save, say so, exit.

SLURM, Kubernetes and ``kill`` stop a job with SIGTERM, and a job started in the background by a
non-interactive shell ignores SIGINT; without this, such a job dies without saving. The CLI entry
calls :func:`install` once; SIGTERM then runs whatever SIGINT's handler is at that moment (the
trainers' "save after this step" handler, or Python's KeyboardInterrupt), and the exit status says
which signal stopped the command (130 or 143).
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
from collections.abc import Iterator
from dataclasses import dataclass

_terminated = False
"""True once this process received SIGTERM."""


def exit_code() -> int:
    """The status of a command stopped by a signal: 143 (128 + SIGTERM) after SIGTERM, else 130 (Ctrl-C)."""
    return 128 + signal.SIGTERM if _terminated else 128 + signal.SIGINT


def signal_name(signum: int) -> str:
    """How a message names the signal: "SIGTERM" or "Ctrl-C"."""
    return "SIGTERM" if signum == signal.SIGTERM else "Ctrl-C"


def install() -> None:
    """Make SIGTERM act as Ctrl-C for the rest of the process; only the main thread can install it.

    A second SIGTERM is ignored, so a scheduler's repeated signal does not cut a save short. A torchrun rank
    (``RANK``, ``WORLD_SIZE``, ``MASTER_ADDR``, ``MASTER_PORT`` set) is left as it is: torchrun stops the other
    ranks with SIGTERM when one fails, and they must stop at once rather than wait on a collective to save.
    """
    if threading.current_thread() is not threading.main_thread():
        return
    if all(os.environ.get(name) for name in ("RANK", "WORLD_SIZE", "MASTER_ADDR", "MASTER_PORT")):
        return

    def on_term(signum, frame):
        global _terminated
        if _terminated:
            return
        _terminated = True
        handler = signal.getsignal(signal.SIGINT)
        if callable(handler):
            handler(signal.SIGTERM, frame)
        else:  # SIGINT ignored (a background job) or left to the OS: stop as Ctrl-C would
            raise KeyboardInterrupt

    signal.signal(signal.SIGTERM, on_term)


@dataclass
class StopRequest:
    """Set by the first Ctrl-C/SIGTERM inside :func:`deferred`; the loop saves at its next clean point."""

    requested: bool = False
    signum: int = signal.SIGINT


@contextlib.contextmanager
def deferred(what: str) -> Iterator[StopRequest]:
    """While inside, the first Ctrl-C or SIGTERM only sets ``requested`` (the loop saves and stops).

    ``what`` ends the notice printed then ("saving <what>"). A second Ctrl-C stops at once. Outside the
    main thread no handler can be installed and nothing changes.
    """
    request = StopRequest()
    if threading.current_thread() is not threading.main_thread():
        yield request
        return

    def handler(signum, frame):
        if request.requested:
            raise KeyboardInterrupt
        request.requested, request.signum = True, signum
        print(f"\n{signal_name(signum)}: saving {what} (Ctrl-C again to stop without saving)",
              file=sys.stderr, flush=True)

    previous = signal.signal(signal.SIGINT, handler)
    try:
        yield request
    finally:
        signal.signal(signal.SIGINT, previous)
