"""One writer per run directory: an exclusive OS file lock on ``<run_dir>/.lock``.

``latentrl train`` and ``motion train`` hold the lock from before their first write until they
exit, so two processes never interleave checkpoints in one folder. The kernel drops the lock when
its holder dies (``SIGKILL`` included), so a stale ``.lock`` file never blocks a later resume. The
file keeps the holder's PID, which the refusal names. ``latentrl eval`` and ``latentrl optimize`` hold
the same lock on their ``--out`` folder (:func:`latentrl.preflight.locked_output`), so two of them never
mix their results in one folder. The file is opened without following a
symbolic link (:func:`latentrl.safe_io.open_no_follow`): a linked ``.lock`` is refused, never
emptied. Where ``fcntl`` does not exist (Windows) no lock is taken.
"""

from __future__ import annotations

import os
from pathlib import Path
from types import TracebackType

from latentrl.errors import ConfigError
from latentrl.safe_io import open_no_follow

LOCK_FILE = ".lock"


RUN_HINT = "wait for it to finish or stop it, then --resume"


class RunLock:
    """``with RunLock(run_dir): ...`` holds an exclusive, non-blocking lock; a second holder gets ``ConfigError``.

    ``what`` names the folder in the refusal ("run directory", "--out folder"); ``hint`` says what to do.
    """

    def __init__(self, run_dir: str | Path, what: str = "run directory", hint: str = RUN_HINT):
        self.run_dir = Path(run_dir)
        self.path = self.run_dir / LOCK_FILE
        self.what, self.hint = what, hint
        self._fd: int | None = None

    def acquire(self) -> RunLock:
        """Take the lock (a no-op while this object holds it); ``ConfigError`` naming the holder if another does."""
        if self._fd is not None:
            return self
        try:
            import fcntl
        except ImportError:  # no OS lock here; nothing to hold
            return self
        self.run_dir.mkdir(parents=True, exist_ok=True)
        fd = open_no_follow(self.path, os.O_RDWR | os.O_CREAT, "lock file")
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            holder = os.read(fd, 64).decode("ascii", "replace").strip() or "unknown"
            os.close(fd)
            raise ConfigError(f"{self.what} {self.run_dir} is in use by another latentrl process (PID {holder}); "
                              f"{self.hint}") from None
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode("ascii"))
        self._fd = fd
        return self

    def release(self) -> None:
        """Give the lock back (closing the file drops it); nothing happens when it is not held."""
        if self._fd is not None:
            os.close(self._fd)  # closing drops the flock; the file stays (unlinking would race a waiting opener)
            self._fd = None

    def __enter__(self) -> RunLock:
        return self.acquire()

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        self.release()
