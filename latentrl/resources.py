"""The files latentrl ships inside its package, found through :mod:`importlib.resources`.

``latentrl/configs/`` holds the training configs (``configs/motion/`` the motion-training ones,
``configs/policies/`` those of the shipped policies), ``latentrl/tasks/paths/`` the waypoint-path
suites (``tasks/joystick/`` the command timelines, ``tasks/timed/`` the timed paths),
``latentrl/policies/`` the shipped policies (``<name>.pt`` and its card ``<name>.md``). A
checkout also has ``configs``, ``tasks`` and ``policies`` links at its root, so ``latentrl train
configs/quick.yaml`` works there as well as ``latentrl train quick`` anywhere, and ``latentrl eval
policies/reach_walk_default.pt`` as well as ``latentrl eval reach_walk_default``.

A file argument is looked up, in order: as given (relative to the working directory), then
relative to the package (``configs/quick.yaml``, ``tasks/paths/dart_walk_long.json``), then as a
packaged name (``quick``, ``motion/default``, ``dart_walk_long``).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

CONFIGS = "configs"
POLICIES = "policies"
PATH_SUITES = ("tasks", "paths")


def packaged(*parts: str) -> Path:
    """``latentrl/<parts...>`` inside the installed package (a real file-system path)."""
    root = resources.files("latentrl")
    for part in parts:
        root = root.joinpath(part)
    return Path(str(root))


def suites_folder(kind: str = "paths") -> Path:
    """The folder of the shipped suites of a task: ``latentrl/tasks/paths`` (also ``joystick``, ``timed``)."""
    return packaged(PATH_SUITES[0], kind)


def config_file(spec: str | Path) -> Path:
    """A config file by path, by path inside the package, or by packaged name (``quick``, ``motion/tiny``).

    Returns ``spec`` itself when nothing matches, so the caller's "not found" message names what was given.
    """
    return find_file(spec, (packaged(), packaged(CONFIGS)), ".yaml")


def task_file(spec: str | Path, kind: str = "paths") -> Path | None:
    """A task file by path, by path inside the package, or by suite name in ``tasks/<kind>``; None if there is none."""
    found = find_file(spec, (packaged(), suites_folder(kind)), ".json")
    return found if found.is_file() else None


def policy_file(spec: str | Path) -> Path:
    """A policy checkpoint by path, by path inside the package, or by shipped name (``reach_walk_default``).

    Returns ``spec`` itself when nothing matches, so the caller's "not found" message names what was given.
    """
    return find_file(spec, (packaged(), packaged(POLICIES)), ".pt")


def is_packaged(path: str | Path) -> bool:
    """Whether ``path`` lies inside the installed package (where outputs must not go)."""
    try:
        Path(path).resolve().relative_to(packaged().resolve())
    except ValueError:
        return False
    return True


def find_file(spec: str | Path, roots: tuple[Path, ...], suffix: str) -> Path:
    """``spec`` if it is a file, else the first ``root / spec`` (or ``root / spec + suffix``) that is one."""
    given = Path(spec).expanduser()
    if given.is_file() or given.is_absolute():
        return given
    for root in roots:
        for cand in (root / given, root / f"{given}{suffix}"):
            if cand.is_file():
                return cand
    return given
