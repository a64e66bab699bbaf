"""Configs are dataclasses beside their code; YAML files hold their values.

:func:`load_config` merges, in order: the dataclass defaults, a YAML file, and dotted
``key=value`` overrides (``--set ppo.learning_rate=1e-4``), using OmegaConf's structured configs
for type checking. Every problem is one :class:`~latentrl.errors.ConfigError` line naming the
file and the dotted key (with a "did you mean" for typos). After merging, each dataclass in the
tree may check its ranges in a ``validate()`` method. A config class may name renamed keys in an
``ALIASES`` class attribute (old dotted key -> new dotted key); files and overrides that use an old
key still load.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any, TypeVar

from latentrl.errors import ConfigError

T = TypeVar("T")


def _error(source: str, exc: Exception) -> ConfigError:
    key = getattr(exc, "full_key", None) or getattr(exc, "key", None)
    msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    # OmegaConf appends "full_key: ..." lines; keep the first, most useful one
    where = f"{source}: {key}: " if key else f"{source}: "
    return ConfigError(where + msg)


def _first_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split("\n")[:1]).strip() or type(exc).__name__
    return text[:200]


def load_config(cls: type[T], path: str | Path | None = None, overrides: Sequence[str] = ()) -> T:
    """Build a ``cls`` instance from defaults, an optional YAML file and dotted overrides."""
    import yaml
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    aliases = getattr(cls, "ALIASES", {})
    merged = OmegaConf.structured(cls)
    if path is not None:
        path = Path(path)
        if not path.is_file():
            raise ConfigError(f"config file not found: {path}")
        from latentrl.safe_io import load_strict_yaml, read_text_file

        text = read_text_file(path, "config file", ConfigError)
        try:
            data = load_strict_yaml(text)
        except (yaml.YAMLError, RecursionError) as exc:
            raise ConfigError(f"{path}: invalid YAML: {_first_line(exc)}") from None
        if data is None:  # an empty file would silently start the defaults (e.g. a 200 M-step run)
            raise ConfigError(f"{path}: holds no settings (empty file); give at least one field, or copy "
                              f"a shipped config such as configs/quick.yaml")
        if not isinstance(data, dict):
            raise ConfigError(f"{path}: expected a mapping of config fields, got {type(data).__name__}")
        data = apply_aliases(data, aliases)
        try:
            merged = OmegaConf.merge(merged, OmegaConf.create(data))
        except OmegaConfBaseException as exc:
            raise _error(str(path), exc) from None
    for item in overrides:
        if "=" not in item:
            raise ConfigError(f"override '{item}': expected key=value (e.g. ppo.learning_rate=1e-4)")
        key, _, value = item.partition("=")
        try:
            merged = OmegaConf.merge(merged, OmegaConf.from_dotlist([f"{aliases.get(key.strip(), key)}={value}"]))
        except OmegaConfBaseException as exc:
            raise _error(f"override '{item}'", exc) from None
        except (yaml.YAMLError, ValueError, RecursionError) as exc:  # OmegaConf parses the value as YAML
            raise ConfigError(f"override '{item}': invalid YAML value: {_first_line(exc)}") from None
    try:
        obj = OmegaConf.to_object(merged)
    except OmegaConfBaseException as exc:
        raise _error(str(path or "config"), exc) from None
    validate_tree(obj, str(path or "config"))
    return obj


def from_dict(cls: type[T], data: dict, source: str) -> T:
    """A ``cls`` instance from a plain dict (e.g. a config stored in a checkpoint), checked like a file."""
    from omegaconf import OmegaConf
    from omegaconf.errors import OmegaConfBaseException

    try:
        obj = OmegaConf.to_object(OmegaConf.merge(OmegaConf.structured(cls), OmegaConf.create(data)))
    except OmegaConfBaseException as exc:
        raise _error(source, exc) from None
    validate_tree(obj, source)
    return obj


def apply_aliases(data: dict, aliases: dict[str, str]) -> dict:
    """A copy of the nested ``data`` with every old dotted key of ``aliases`` moved to its new place."""
    import copy

    data = copy.deepcopy(data)
    for old, new in aliases.items():
        *where, name = old.split(".")
        node = data
        for part in where:
            node = node.get(part) if isinstance(node, dict) else None
        if not isinstance(node, dict) or name not in node:
            continue
        value = node.pop(name)
        *where, name = new.split(".")
        node = data
        for part in where:
            node = node.setdefault(part, {})
        node.setdefault(name, value)
    return data


def non_finite(value: Any) -> bool:
    """Whether ``value`` is, or a list, tuple or dict holds (at any depth), a NaN or infinite float."""
    if isinstance(value, float):
        return not math.isfinite(value)
    if isinstance(value, (list, tuple)):
        return any(non_finite(v) for v in value)
    if isinstance(value, dict):
        return any(non_finite(v) for v in value.values())
    return False


def validate_tree(obj: Any, source: str, prefix: str = "") -> None:
    """Call ``validate()`` on every dataclass in the tree; re-raise with file and dotted key.

    After a dataclass's own ``validate()`` (whose messages name the range), every float field of it, and
    every float in a list or dict field, must be finite: no config value means anything as NaN or +/-inf
    (``ppo.adam_eps: .inf`` trained with zero updates).
    """
    if not dataclasses.is_dataclass(obj):
        return
    for f in dataclasses.fields(obj):
        validate_tree(getattr(obj, f.name), source, f"{prefix}{f.name}.")
    check = getattr(obj, "validate", None)
    if callable(check):
        try:
            check()
        except ConfigError as exc:
            raise ConfigError(f"{source}: {prefix}{exc}") from None
    for f in dataclasses.fields(obj):
        value = getattr(obj, f.name)
        if non_finite(value):
            expected = "a finite number" if isinstance(value, float) else "finite numbers only"
            raise ConfigError(f"{source}: {prefix}{f.name}: must be {expected} (not NaN or inf), got {str(value)[:80]}")


def require(condition: bool, field: str, message: str) -> None:
    """Raise ``ConfigError('field: message')`` unless ``condition`` holds (for ``validate()``)."""
    if not condition:
        raise ConfigError(f"{field}: {message}")


def to_yaml(obj: Any) -> str:
    """YAML text of a config dataclass (what runs save as their resolved config)."""
    from omegaconf import OmegaConf

    return OmegaConf.to_yaml(OmegaConf.structured(obj))


def to_dict(obj: Any) -> dict:
    """Plain nested dict of a config dataclass (tuples become lists)."""
    from omegaconf import OmegaConf

    return OmegaConf.to_container(OmegaConf.structured(obj))


MAX_THREADS = 1024
"""CPU threads a config may ask torch for (more only thrashes; 100,000 would take minutes to start)."""

MAX_SEED = 2**32 - 1
"""Seeds lie in [0, 2**32 - 1]: numpy's ``np.random.seed`` and torch generators accept no more."""


def is_finite_number(value: object) -> bool:
    """A real number from a JSON or YAML file: an int or float, finite, and not a bool (``True`` is an int)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def seed_problem(value: object) -> str | None:
    """Why ``value`` is not a usable random seed, or None."""
    if isinstance(value, bool) or not isinstance(value, int):
        return f"expected an integer seed, got {value!r}"
    if not 0 <= value <= MAX_SEED:
        return f"must lie in [0, 2**32 - 1 = {MAX_SEED}], got {value}"
    return None


def require_seed(value: object, field: str = "seed") -> None:
    """Raise ``ConfigError('field: ...')`` unless ``value`` is a usable random seed."""
    problem = seed_problem(value)
    require(problem is None, field, str(problem))
