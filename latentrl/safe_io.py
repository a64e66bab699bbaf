"""Loading files from strangers without executing them, and writing files atomically.

- :func:`load_torch` wraps ``torch.load(weights_only=True)`` (tensors and plain containers only).
- :func:`load_pickle` reads DART's pickles (mean/std tuples, text-embedding tables) through a
  restricted unpickler that admits tensors, numpy arrays and plain containers, nothing else.
- :func:`load_tyro_yaml` parses DART's ``args.yaml`` (YAML text inside YAML, with tyro and python
  tags) into plain dicts, lists and strings without constructing any Python object.
- :func:`atomic_write_bytes` / :func:`save_torch_atomic` write to a temporary file in the same
  folder, fsync, then ``os.replace`` it: a reader sees the old file or the new one, never half. The
  temporary file is created exclusively (never an existing file or link), and the rename replaces a
  symbolic link at the final name instead of writing through it. :func:`atomic_write_with` does the
  same for writers that take a file name (matplotlib figures, GIFs).
- :func:`open_no_follow` opens files that are written in place (the run lock, ``train.log``): it
  refuses a symbolic link, a hard-linked file or anything but a regular file at that name.
"""

from __future__ import annotations

import contextlib
import errno
import io
import json
import os
import pickle
import re
import signal
import stat
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
import yaml

from latentrl.errors import CheckpointError, ConfigError


# --------------------------------------------------------------------------- torch files
def load_torch(path: str | Path, map_location: str | torch.device = "cpu", what: str = "checkpoint") -> Any:
    """``torch.load(path, weights_only=True)`` with one-line errors naming the file."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{what} file not found: {path}")
    try:
        return torch.load(path, map_location=map_location, weights_only=True)
    except pickle.UnpicklingError as exc:
        text = " ".join(str(exc).split())
        found = re.search(r"GLOBAL ([\w.]+)", text)  # torch names the global it refused
        if found is None:  # the weights-only unpickler met bytes that are no pickle at all
            detail = re.search(r"WeightsUnpickler error: (.+?)(?: Check the documentation|$)", text)
            reason = (detail.group(1) if detail else text)[:160]
            raise CheckpointError(f"{path}: not a readable torch file (corrupt or truncated?): {reason}") from None
        raise CheckpointError(
            f"{path}: refused to load: the file holds Python objects other than tensors and plain "
            f"containers (it asks for {found.group(1)}; only weights_only=True files are read)"
        ) from None
    except Exception as exc:  # noqa: BLE001 - arbitrary bytes make the unpickler raise any type (IndexError, ...)
        reason = f"{type(exc).__name__}: {str(exc)[:160]}"
        raise CheckpointError(f"{path}: not a readable torch file (corrupt or truncated?): {reason}") from None


def save_torch_atomic(obj: Any, path: str | Path) -> Path:
    """``torch.save`` to a temporary sibling, fsync, then rename over ``path``."""
    buf = io.BytesIO()
    torch.save(obj, buf)
    return atomic_write_bytes(path, buf.getvalue())


@contextlib.contextmanager
def _signals_held():
    """Hold Ctrl-C and SIGTERM back until the block ends, then deliver them to the handlers they would have met.

    Why: a KeyboardInterrupt raised between ``mkstemp`` creating the temporary file and the ``try`` that removes
    it on failure would leave the file behind; the window is tiny, but an interrupted evaluation hit it. Python
    runs signal handlers in the main thread whichever thread the OS delivered the signal to (torch and tqdm
    start others), so the handlers themselves are swapped for a recorder here: masking the main thread alone let
    a SIGTERM delivered to another thread through.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    held = {}
    for signum in (signal.SIGINT, signal.SIGTERM):
        handler = signal.getsignal(signum)
        if handler is not None:  # None: installed outside Python, cannot be put back
            held[signum] = signal.signal(signum, lambda number, frame: caught.append(number))
    try:
        yield
    finally:
        for signum, handler in held.items():
            signal.signal(signum, handler)
        for signum in caught:
            signal.raise_signal(signum)


@contextlib.contextmanager
def _replacing(path: Path, suffix: str):
    """``(fd, name)`` of a fresh sibling of ``path`` that replaces it when the block ends; removed on failure.

    mkstemp opens with O_CREAT | O_EXCL (and O_NOFOLLOW where it exists) under a random name: never an
    existing file or a link someone placed in advance. The rename replaces a link at ``path``, never follows it.
    """
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp, handed_over = None, False
    try:
        with _signals_held():  # no interrupt between the file's creation and ``tmp`` naming it for the cleanup
            fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
        if hasattr(os, "fchmod"):  # mkstemp makes 0600; give the file normal permissions
            os.fchmod(fd, 0o666 & ~_umask())
        else:
            os.chmod(tmp, 0o666 & ~_umask())
        handed_over = True
        yield fd, Path(tmp)
        os.replace(tmp, path)
    except BaseException:
        if tmp is not None:
            with contextlib.suppress(OSError):
                if not handed_over:
                    os.close(fd)
            with contextlib.suppress(OSError):
                os.unlink(tmp)
        raise


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (same-folder temp file + fsync + ``os.replace``)."""
    path = Path(path)
    with _replacing(path, ".tmp") as (fd, _tmp), os.fdopen(fd, "wb") as f:
        f.write(data)
        f.flush()
        os.fsync(f.fileno())
    return path


def atomic_write_with(path: str | Path, write: Callable[[Path], Any]) -> Path:
    """Atomically write ``path`` with ``write(tmp)``, a writer that takes a file name (matplotlib, Pillow).

    ``tmp`` is a fresh, exclusively created, randomly named sibling with ``path``'s suffix (never a
    name someone could have linked in advance); it is renamed over ``path`` once ``write`` returns.
    """
    path = Path(path)
    with _replacing(path, f".tmp{path.suffix}") as (fd, tmp):
        os.close(fd)
        write(tmp)
    return path


_TEMPORARY = re.compile(r"^\..+\.[a-z0-9_]{8}\.tmp(\.[A-Za-z0-9]{1,8})?$")
"""The names :func:`_replacing` gives its temporary files: ``.<name>.<8 random characters>.tmp[.<suffix>]``."""


def remove_temporaries(folder: str | Path) -> list[Path]:
    """Delete the temporary files that atomic writes killed mid-way (SIGKILL) left in ``folder`` and its subfolders.

    Only names of :func:`_replacing`'s pattern, one folder level deep (an output folder's ``motions/``,
    ``renders/``). Call it only while holding the folder's lock: a live writer's file must not vanish.
    """
    folder = Path(folder)
    if not folder.is_dir() or folder.is_symlink():
        return []
    removed = []
    for sub in [folder, *(d for d in folder.iterdir() if d.is_dir() and not d.is_symlink())]:
        for path in sub.iterdir():
            if _TEMPORARY.match(path.name) and path.is_file() and not path.is_symlink():
                with contextlib.suppress(OSError):
                    path.unlink()
                    removed.append(path)
    return removed


def open_no_follow(path: str | Path, flags: int, what: str = "file", mode: int = 0o644) -> int:
    """``os.open(path, flags | O_NOFOLLOW)`` for a file written in place; ``ConfigError`` if it is not a plain file.

    A symbolic link at ``path`` would make the write land in the file it points to (a lock's
    truncation would empty it, a log would grow it); a hard link does the same to its other names;
    a FIFO or device is no file at all. All three are refused with one line naming ``path`` and
    ``what`` it is. Where the OS has no ``O_NOFOLLOW`` the link is checked with ``lstat`` first.
    """
    path = Path(path)
    nofollow = getattr(os, "O_NOFOLLOW", 0)
    if not nofollow and path.is_symlink():
        raise ConfigError(_link_refusal(path, what))
    try:  # O_NONBLOCK: a FIFO with no reader fails at once instead of hanging (regular files ignore it)
        fd = os.open(path, flags | nofollow | getattr(os, "O_NONBLOCK", 0), mode)
    except OSError as exc:
        if exc.errno == errno.ELOOP and path.is_symlink():
            raise ConfigError(_link_refusal(path, what)) from None
        if exc.errno == errno.ENXIO:
            raise ConfigError(f"{path}: the {what} is not a regular file; refused to write to it; remove it and "
                              "run again") from None
        raise
    info = os.fstat(fd)
    problem = None
    if not stat.S_ISREG(info.st_mode):
        problem = "is not a regular file"
    elif info.st_nlink > 1:
        problem = f"has {info.st_nlink} hard links (writing it would change the other names too)"
    if problem is not None:
        os.close(fd)
        raise ConfigError(f"{path}: the {what} {problem}; refused to write to it; remove it and run again")
    return fd


def _link_refusal(path: Path, what: str) -> str:
    try:
        target = os.readlink(path)
    except OSError:
        target = "?"
    return (f"{path}: the {what} is a symbolic link (to {target}); refused to write through it; "
            "remove the link and run again")


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Write ``text`` as UTF-8, atomically (temporary sibling, fsync, rename)."""
    return atomic_write_bytes(path, text.encode("utf-8"))


# --------------------------------------------------------------------------- pickles
def _tensor_from_legacy_bytes(data: bytes) -> Any:
    """Stand-in for ``torch.storage._load_from_bytes`` that refuses code (weights_only)."""
    return torch.load(io.BytesIO(data), map_location="cpu", weights_only=True)


_ALLOWED: dict[tuple[str, str], Any] = {
    ("collections", "OrderedDict"): __import__("collections").OrderedDict,
    ("torch._utils", "_rebuild_tensor_v2"): torch._utils._rebuild_tensor_v2,
    ("torch.storage", "_load_from_bytes"): _tensor_from_legacy_bytes,
    ("numpy.core.multiarray", "_reconstruct"): None,
    ("numpy._core.multiarray", "_reconstruct"): None,
    ("numpy", "ndarray"): np.ndarray,
    ("numpy", "dtype"): np.dtype,
    ("numpy.core.multiarray", "scalar"): None,
    ("numpy._core.multiarray", "scalar"): None,
    ("builtins", "set"): set,
    ("builtins", "frozenset"): frozenset,
    ("builtins", "tuple"): tuple,
    ("builtins", "list"): list,
    ("builtins", "dict"): dict,
    ("builtins", "complex"): complex,
    ("_codecs", "encode"): None,
}


def _numpy_attr(module: str, name: str):
    import importlib

    try:
        return getattr(importlib.import_module(module), name)
    except (ImportError, AttributeError):
        alt = (
            module.replace("numpy._core", "numpy.core")
            if "_core" in module
            else module.replace("numpy.core", "numpy._core")
        )
        return getattr(importlib.import_module(alt), name)


class _RestrictedUnpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str):
        key = (module, name)
        if key not in _ALLOWED:
            raise pickle.UnpicklingError(f"global '{module}.{name}' is not allowed")
        obj = _ALLOWED[key]
        if obj is None:
            if module == "_codecs":
                import codecs

                return codecs.encode
            return _numpy_attr(module, name)
        return obj

    def persistent_load(self, pid):
        raise pickle.UnpicklingError("persistent ids are not allowed in plain pickles")


def load_pickle(path: str | Path, what: str = "pickle") -> Any:
    """Read a pickle that may hold only tensors, numpy arrays and plain containers."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"{what} file not found: {path}")
    try:
        with open(path, "rb") as f:
            return _RestrictedUnpickler(f).load()
    except pickle.UnpicklingError as exc:
        raise CheckpointError(
            f"{path}: refused to unpickle: {exc} (only tensors, numpy arrays and plain containers are accepted)"
        ) from None
    except Exception as exc:  # noqa: BLE001 - arbitrary bytes make the unpickler raise any type
        raise CheckpointError(f"{path}: not a readable pickle (corrupt or truncated?): {str(exc)[:200]}") from None


# --------------------------------------------------------------------------- YAML
class _PlainLoader(yaml.SafeLoader):
    """SafeLoader that turns tyro/python tags into plain data instead of objects."""


def _tagged_mapping(loader: _PlainLoader, suffix: str, node: yaml.Node) -> Any:
    if isinstance(node, yaml.MappingNode):
        return loader.construct_mapping(node, deep=True)
    if isinstance(node, yaml.SequenceNode):
        return loader.construct_sequence(node, deep=True)
    return loader.construct_scalar(node)


def _python_tag(loader: _PlainLoader, suffix: str, node: yaml.Node) -> Any:
    if suffix == "tuple":
        return list(loader.construct_sequence(node, deep=True))
    if suffix.startswith("object/apply:pathlib") and isinstance(node, yaml.SequenceNode):
        parts = loader.construct_sequence(node, deep=True)
        return str(Path(*[str(p) for p in parts])) if parts else ""
    return _tagged_mapping(loader, suffix, node)


_PlainLoader.add_multi_constructor("!", _tagged_mapping)
_PlainLoader.add_multi_constructor("tag:yaml.org,2002:python/", _python_tag)


def load_plain_yaml(text: str, source: str = "<yaml>") -> Any:
    """Parse YAML into plain Python data; unknown tags become plain values, never objects."""
    try:
        return yaml.load(text, Loader=_PlainLoader)  # noqa: S506 - loader builds plain data only
    except yaml.YAMLError as exc:
        raise CheckpointError(f"{source}: invalid YAML: {str(exc).splitlines()[0]}") from None


def load_tyro_yaml(path: str | Path) -> dict:
    """DART's ``args.yaml``: a YAML string holding tyro YAML, parsed to nested dicts."""
    path = Path(path)
    if not path.is_file():
        raise CheckpointError(f"args file not found: {path}")
    outer = load_plain_yaml(read_text_file(path, "DART args file"), str(path))
    data = load_plain_yaml(outer, str(path)) if isinstance(outer, str) else outer
    if not isinstance(data, dict):
        raise CheckpointError(f"{path}: expected a mapping of DART arguments, got {type(data).__name__}")
    return data


# --------------------------------------------------------------------------- text and config files
MAX_ALIASES = 100  # YAML aliases (*name) per document: more is an alias bomb, never a config


def read_text_file(path: str | Path, what: str = "file", error: type[Exception] = CheckpointError) -> str:
    """A UTF-8 text file's content; one-line ``error`` if it is unreadable, binary or not UTF-8."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise error(f"{path}: cannot read the {what}: {exc.strerror or exc}") from None
    if b"\x00" in data:
        raise error(f"{path}: not a text {what} (it holds NUL bytes; binary or UTF-16?); expected UTF-8 text")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not a UTF-8 text {what} (byte 0x{data[exc.start]:02x} at offset {exc.start}); "
                    f"expected UTF-8 text") from None


def read_json_file(path: str | Path, what: str, max_bytes: int, error: type[Exception]) -> Any:
    """Parse a JSON file (a path suite, a command timeline, ...) with one-line ``error`` s naming it.

    Refuses a missing file, one larger than ``max_bytes`` (say how to split it), invalid JSON (with line and
    column), text that is not UTF-8, nesting too deep to parse and over-long number literals.
    """
    path = Path(path)
    if not path.is_file():
        if path.exists():  # a folder, /dev/zero, a FIFO: reading would fail or never end
            raise error(f"{path}: not a regular file ({'a folder' if path.is_dir() else 'a device or pipe'}); "
                        f"expected a {what}")
        raise error(f"{what} not found: {path}")
    size = path.stat().st_size
    if size > max_bytes:
        limit = f"{max_bytes >> 20} MiB" if max_bytes % (1 << 20) == 0 else f"{max_bytes:,} bytes"
        raise error(f"{path}: {size:,} bytes is larger than the {limit} a {what} may have; split it into several files")
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as exc:
        raise error(f"{path}: invalid JSON: {exc.msg} (line {exc.lineno}, column {exc.colno})") from None
    except UnicodeDecodeError:
        raise error(f"{path}: not a UTF-8 text file") from None
    except RecursionError:
        raise error(f"{path}: JSON nested too deeply for a {what}") from None
    except ValueError as exc:  # e.g. an integer literal longer than Python's digit limit
        raise error(f"{path}: invalid JSON: {str(exc)[:120]}") from None


class _StrictLoader(yaml.SafeLoader):
    """SafeLoader that refuses duplicate keys and more than :data:`MAX_ALIASES` aliases."""

    def compose_node(self, parent, index):
        if self.check_event(yaml.AliasEvent):
            self._aliases = getattr(self, "_aliases", 0) + 1
            if self._aliases > MAX_ALIASES:
                raise yaml.YAMLError(f"more than {MAX_ALIASES} aliases (*name); refused as a possible alias bomb")
        return super().compose_node(parent, index)

    def construct_mapping(self, node, deep=False):
        seen: set = set()
        for key_node, _ in node.value:
            key = self.construct_object(key_node, deep=True)
            try:
                duplicate = key in seen
                seen.add(key)
            except TypeError:  # unhashable key: SafeLoader reports it below
                continue
            if duplicate:
                raise yaml.YAMLError(f"duplicate key '{key}' (line {key_node.start_mark.line + 1}); "
                                     f"each key may appear once")
        return super().construct_mapping(node, deep=deep)


MAX_YAML_VALUES = 1_000_000  # values in a document once aliases are expanded


def _expanded_size(obj: Any, memo: dict[int, int]) -> int:
    """Number of values in ``obj`` with every shared (aliased) container counted at each use; memoised."""
    if not isinstance(obj, (dict, list)):
        return 1
    if id(obj) not in memo:
        memo[id(obj)] = 0  # a self-referencing alias counts once
        items = [*obj.keys(), *obj.values()] if isinstance(obj, dict) else obj
        memo[id(obj)] = 1 + sum(_expanded_size(x, memo) for x in items)
    return memo[id(obj)]


def load_strict_yaml(text: str) -> Any:
    """``yaml.safe_load`` that also refuses duplicate keys and alias bombs (raises ``yaml.YAMLError``).

    At most :data:`MAX_ALIASES` aliases and :data:`MAX_YAML_VALUES` values once they are expanded.
    """
    data = yaml.load(text, Loader=_StrictLoader)  # noqa: S506 - a SafeLoader subclass
    size = _expanded_size(data, {})
    if size > MAX_YAML_VALUES:
        raise yaml.YAMLError(f"expands to {size} values through its aliases, more than {MAX_YAML_VALUES}; "
                             f"refused as an alias bomb")
    return data
