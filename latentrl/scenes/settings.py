"""Checks shared by the random-scene specs: one-line errors naming the key.

Used by ``random_obstacles``, ``random_mazes`` and ``random_stairs``.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, TypeVar

from latentrl.errors import ConfigError, closest

T = TypeVar("T")


def check_range(key: str, value: Any, low: float, high: float, integer: bool = False) -> None:
    """``value`` is [min, max] with ``low <= min <= max <= high`` (integers or numbers), else a ConfigError."""
    kind = "integers" if integer else "numbers"
    ok = isinstance(value, (list, tuple)) and len(value) == 2 and all(
        isinstance(x, int if integer else (int, float)) and not isinstance(x, bool) and math.isfinite(x)
        for x in value)
    if not ok or not low <= value[0] <= value[1] <= high:
        raise ConfigError(f"{key}: expected [min, max] {kind} with {low:g} <= min <= max <= {high:g}, got {value}")


def check_number(key: str, value: Any, low: float, high: float, integer: bool = False) -> None:
    """``value`` is a number (an integer with ``integer``) in [low, high], else a ConfigError."""
    kind = int if integer else (int, float)
    if isinstance(value, bool) or not isinstance(value, kind) or not math.isfinite(value) or not low <= value <= high:
        raise ConfigError(f"{key}: expected {'an integer' if integer else 'a number'} in [{low:g}, {high:g}], "
                          f"got {value!r:.30}")


def settings_of(cls: type[T], raw: Any, name: str) -> T:
    """A dataclass ``cls`` from its YAML/JSON mapping ``raw`` (lists kept as lists), validated.

    Unknown keys and a non-mapping are one-line :class:`ConfigError` naming ``name``.
    """
    if not isinstance(raw, dict):
        raise ConfigError(f"{name}: expected a mapping of settings, got {raw!r:.40}")
    known = [f.name for f in dataclasses.fields(cls)]  # not __dataclass_fields__: it lists class variables too
    for k in raw:
        if k not in known:
            raise ConfigError(f"{name}.{k}: unknown setting{closest(str(k), known)}; expected {', '.join(known)}")
    spec = cls(**{k: (list(v) if isinstance(v, (list, tuple)) else v) for k, v in raw.items()})
    spec.validate()
    return spec
