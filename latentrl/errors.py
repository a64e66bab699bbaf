"""The LatentRLError family: every error a user can cause carries one clear line.

The CLI prints ``str(error)`` and exits with ``error.exit_code``; no traceback unless ``--debug``.
Messages name the file, field or value and say what was expected (house rule 8).
"""

from __future__ import annotations


class LatentRLError(Exception):
    """Base class for errors caused by user input, files or configuration."""

    exit_code = 2


class ConfigError(LatentRLError):
    """A config file, field or override is invalid."""


class CheckpointError(LatentRLError):
    """A checkpoint or model file is missing, malformed, unsafe or incompatible."""


class TextError(LatentRLError):
    """A text prompt cannot be encoded by the configured text encoder."""


class DataError(LatentRLError):
    """A dataset, motion or path file is malformed."""


class NonFiniteError(LatentRLError):
    """A computation produced NaN or infinite values where finite ones were required."""

    exit_code = 3


def closest(name: str, options: list[str] | tuple[str, ...]) -> str:
    """Return a ' (did you mean X?)' hint for ``name`` among ``options``, or ''."""
    import difflib

    match = difflib.get_close_matches(name, list(options), n=1, cutoff=0.5)
    return f" (did you mean '{match[0]}'?)" if match else ""


def check_fields(item: object, fields: tuple[str, ...], where: str) -> None:
    """Refuse a JSON entry that is not an object with exactly ``fields``: one line naming the field.

    Why one function: every suite format (joystick timelines, joint goals, ...) checks its entries this way, and
    their messages should read alike.
    """
    if not isinstance(item, dict):
        raise DataError(f"{where}: expected an object with fields {list(fields)}, got {type(item).__name__}")
    for key in item:
        if key not in fields:
            raise DataError(f"{where}: unknown field '{key}'{closest(str(key), fields)}; expected {list(fields)}")
    for key in fields:
        if key not in item:
            raise DataError(f"{where}: missing field '{key}'")
