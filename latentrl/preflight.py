"""Checks every command runs before it writes anything, and cleanup of what a failed command created.

A command validates its inputs (config, files, device, motion model) and its outputs (the folder is
writable, the disk has room) *before* it creates a run or output directory; if it still fails
afterwards, :class:`NewOutput` removes the directories this invocation created (never one that
existed before). Every problem is one :class:`~latentrl.errors.ConfigError` line naming the value
and the fix.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import TracebackType

from latentrl.errors import ConfigError, LatentRLError, NonFiniteError
from latentrl.runlock import RunLock

MIB = 1 << 20


# --------------------------------------------------------------------------- devices
def check_device(device: str, what: str = "--device"):
    """Parse ``device`` and make sure this machine has it; returns the ``torch.device``.

    ``what`` names the flag or config key in the message (``--device``, ``ppo.device``).
    """
    import torch

    try:
        parsed = torch.device(device)
    except (RuntimeError, TypeError, ValueError):
        raise ConfigError(f"{what}: unknown device '{device}'; use 'cpu', 'cuda' or 'cuda:<index>'") from None
    if parsed.type == "cpu":
        if parsed.index not in (None, 0):  # torch accepts 'cpu:9' here and fails later on loading tensors
            raise ConfigError(f"{what}: '{device}' does not exist; the CPU is 'cpu' (or 'cpu:0')")
        return parsed
    if parsed.type == "cuda":
        if not torch.cuda.is_available():
            raise ConfigError(f"{what}: '{device}' requested but CUDA is not available on this machine (use 'cpu')")
        count = torch.cuda.device_count()
        if parsed.index is not None and parsed.index >= count:
            raise ConfigError(f"{what}: '{device}' does not exist; this machine has {count} CUDA device(s) "
                              f"(cuda:0 .. cuda:{count - 1})")
        return parsed
    if parsed.type == "mps":
        if not torch.backends.mps.is_available():
            raise ConfigError(f"{what}: '{device}' requested but MPS is not available on this machine (use 'cpu')")
        return parsed
    raise ConfigError(f"{what}: device type '{parsed.type}' is not supported; use 'cpu' or 'cuda[:<index>]'")


# --------------------------------------------------------------------------- torch.compile
def check_compile(device, what: str = "env.compile", off: str | None = None) -> None:
    """Refuse ``torch.compile`` before any work when this machine cannot compile: one line naming ``what``.

    ``off``: how the line tells to run without compiling (default ``set WHAT=false``; a flag says "leave out ...").

    Why: torch compiles lazily, at the first step, and then fails with a dynamo traceback. It needs a
    writable cache folder (``TORCHINDUCTOR_CACHE_DIR``, default ``<tmp>/torchinductor_<user>``; and
    ``TRITON_CACHE_DIR`` when set, on CUDA), a C++ compiler on the CPU (inductor runs each of
    ``torch._inductor.config.cpp.cxx``, i.e. ``$CXX`` or ``g++``, with ``--version`` and takes the first
    that works) and a C compiler on CUDA (Triton's rule: ``$CC``, else ``gcc``, else ``clang``).
    """
    import torch

    off = off or f"set {what}=false"
    kind = torch.device(device).type
    folders = [("TORCHINDUCTOR_CACHE_DIR", _inductor_cache_dir())]
    if kind == "cuda" and os.environ.get("TRITON_CACHE_DIR"):
        folders.append(("TRITON_CACHE_DIR", os.environ["TRITON_CACHE_DIR"]))
    for variable, folder in folders:
        path = Path(folder)
        base = _nearest_existing(path)
        reason = (f"{base} is a file" if not base.is_dir() else
                  f"{path} is not a directory" if path.exists() and not path.is_dir() else _write_problem(base))
        if reason:
            source = f"{variable}={os.environ[variable]}" if os.environ.get(variable) else f"default of {variable}"
            raise ConfigError(f"{what}: torch.compile's cache folder {path} ({source}) is not writable ({reason}); "
                              f"set {variable} to a writable folder, or {off}")
    if kind == "cpu":
        tried = _cxx_candidates()
        if not any(_runs(c) for c in tried):
            raise ConfigError(f"{what}: torch.compile on the CPU needs a C++ compiler, and none runs here (tried "
                              f"{', '.join(repr(c) for c in tried)}: $CXX, else g++ on PATH); install g++ or set CXX "
                              f"to one, or {off}")
    elif kind == "cuda":
        cc = os.environ.get("CC") or shutil.which("gcc") or shutil.which("clang")
        if not cc or not _runs(cc):
            tried = f"CC={os.environ['CC']!r}" if os.environ.get("CC") else "gcc or clang on PATH"
            raise ConfigError(f"{what}: torch.compile on CUDA needs a C compiler for Triton, and none runs here "
                              f"(tried {tried}); install gcc or set CC to one, or {off}")


def _inductor_cache_dir() -> str:
    """Where inductor will keep its cache: torch's rule, restated because importing ``torch._inductor`` creates it."""
    import getpass
    import re

    folder = os.environ.get("TORCHINDUCTOR_CACHE_DIR")
    if not folder:
        try:
            user = getpass.getuser()
        except (KeyError, ModuleNotFoundError, OSError):
            user = f"uid_{os.getuid()}" if hasattr(os, "getuid") else "unknown_user"
        folder = os.path.join(tempfile.gettempdir(), "torchinductor_" + re.sub(r'[\\/:*?"<>|]', "_", user))
    return os.path.abspath(folder)


def _cxx_candidates() -> list[str]:
    """The C++ compilers inductor would try: ``config.cpp.cxx`` (``$CXX`` or ``g++`` when torch was imported)."""
    from torch._inductor import config

    found = config.cpp.cxx if isinstance(config.cpp.cxx, (list, tuple)) else (config.cpp.cxx,)
    return [str(c) for c in found if c is not None] or ["g++"]


def _runs(program: str) -> bool:
    """Whether ``program --version`` runs and exits 0 (how inductor and Triton probe a compiler)."""
    import subprocess

    try:
        return subprocess.run([program, "--version"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              timeout=60).returncode == 0
    except (OSError, subprocess.SubprocessError):
        return False


# --------------------------------------------------------------------------- output folders
def _nearest_existing(path: Path) -> Path:
    """``path`` itself or its closest ancestor that exists."""
    path = Path(os.path.abspath(path))
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def check_writable(folder: str | Path, what: str = "output folder") -> None:
    """Make sure ``folder`` is (or can be created as) a writable directory, without creating it.

    Writes and deletes a probe file in ``folder`` or, if it does not exist yet, in its nearest
    existing ancestor (that is where it will be created). Permission bits alone are not trusted:
    read-only mounts, full quotas and ACLs only show when a write is attempted.
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise ConfigError(f"{what} {folder} exists and is not a directory; choose another path")
    base = _nearest_existing(folder)
    if not base.is_dir():
        raise ConfigError(f"{what} {folder} cannot be created: {base} is a file, not a directory")
    reason = _write_problem(base)
    if reason:
        raise ConfigError(f"{what} {folder} is not writable ({reason} in {base}); choose another path or fix "
                          "its permissions")


def _write_problem(base: Path) -> str | None:
    """None if a probe file can be written in the existing folder ``base``, else why not."""
    try:
        fd, probe = tempfile.mkstemp(prefix=".latentrl-probe-", dir=base)
        try:
            os.write(fd, b"probe")
        finally:
            os.close(fd)
            os.unlink(probe)
    except OSError as exc:
        return exc.strerror or type(exc).__name__
    return None


def check_free_space(folder: str | Path, need_bytes: int, what: str = "output folder") -> None:
    """Refuse to start when the disk holding ``folder`` has less than ``need_bytes`` free."""
    base = _nearest_existing(Path(folder))
    free = shutil.disk_usage(base).free
    if free < need_bytes:
        raise ConfigError(f"{what} {folder}: only {free / MIB:.0f} MiB free on its disk, this run needs about "
                          f"{need_bytes / MIB:.0f} MiB (checkpoints and logs); free space or choose another path")


def check_output_file(path: str | Path, what: str = "--out") -> None:
    """An output file's folder must be writable and the path must not be a directory."""
    path = Path(path)
    if path.is_dir():
        raise ConfigError(f"{what} {path} is a directory; give a file name")
    check_writable(path.parent if str(path.parent) else Path("."), f"{what} folder")


class NewOutput:
    """Context manager: if the block fails, remove the directories it created for ``folder``.

    Records the top-most missing ancestor of ``folder`` on entry; on an error, that directory is
    deleted with everything in it. A folder that existed before is never touched. Errors after
    :meth:`keep` (the command has produced something worth keeping, e.g. training started) and
    :class:`~latentrl.errors.NonFiniteError` (a training fault whose logs explain it) leave it in place.
    """

    def __init__(self, folder: str | Path):
        self.folder = Path(folder)
        self.created: Path | None = None
        self.kept = False

    def __enter__(self) -> NewOutput:
        path = Path(os.path.abspath(self.folder))
        top = None
        while not path.exists() and path != path.parent:
            top, path = path, path.parent
        self.created = top
        return self

    def keep(self) -> None:
        """From now on, leave the output in place even if the block fails."""
        self.kept = True

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None) -> None:
        bad_input = isinstance(exc, (LatentRLError, OSError)) and not isinstance(exc, NonFiniteError)
        if exc is not None and bad_input and not self.kept and self.created is not None and self.created.exists():
            shutil.rmtree(self.created, ignore_errors=True)


@contextmanager
def locked_output(folder: str | Path, what: str = "--out folder") -> Iterator[NewOutput]:
    """:class:`NewOutput` for ``folder`` while holding its :class:`~latentrl.runlock.RunLock`: one writer per folder.

    A second ``eval`` or ``optimize`` writing into the same folder is refused at once in one line
    naming the folder and the PID that holds it, and never removes that holder's folder.
    """
    from latentrl.safe_io import remove_temporaries  # torch-heavy; preflight's other checks stay light

    lock = RunLock(folder, what=what, hint="wait for it to finish or choose another --out")
    with NewOutput(folder) as output:
        try:
            lock.acquire()
        except ConfigError:
            output.keep()  # the folder belongs to the process holding the lock
            raise
        with lock:
            remove_temporaries(folder)  # what a killed writer of this folder left half-written
            yield output
