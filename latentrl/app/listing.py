"""Body of ``latentrl list``: what ships, so names are found without reading the package's folders.

Each section prints the names the other commands take: task ids (``gymnasium.make``), shipped policies
(``latentrl eval NAME``), configs (``latentrl train NAME``), suites (``--paths NAME``, ``latentrl optimize NAME``)
and the prompts of a motion model (``--text``). Policies are read without loading a network (their stored
config only); the prompts section loads the motion model, since a DART checkpoint keeps its table beside it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from latentrl.errors import ConfigError

SECTIONS = ("tasks", "policies", "configs", "suites", "prompts")
"""What ``latentrl list SECTION`` accepts; no section prints them all, in this order."""

SUITE_KINDS = ("paths", "joystick", "timed", "joint_goals", "sit", "constraints")
"""Folders of ``latentrl/tasks``: waypoint paths, command timelines, timed paths, joint goals, seats, noise-optimization
constraints."""


@dataclass
class ListRequest:
    """``latentrl list``: which section (None: all) and whose prompts."""

    section: str | None = None
    motion: str = "default"


def list_command(req: ListRequest) -> int:
    """Print the requested sections; an unknown section is a one-line ``ConfigError`` (exit 2)."""
    if req.section is not None and req.section not in SECTIONS:
        raise ConfigError(f"unknown section '{req.section}' of latentrl list (expected one of {', '.join(SECTIONS)})")
    chosen = SECTIONS if req.section is None else (req.section,)
    blocks = {"tasks": _tasks, "policies": _policies, "configs": _configs, "suites": _suites,
              "prompts": lambda: _prompts(req.motion)}
    for i, name in enumerate(chosen):
        if i:
            print()
        for line in blocks[name]():
            print(line)
    return 0


def _table(rows: list[tuple[str, ...]]) -> list[str]:
    """Rows as left-aligned columns, two spaces apart."""
    widths = [max(len(r[c]) for r in rows) for c in range(len(rows[0]))] if rows else []
    return ["  " + "  ".join(cell.ljust(w) for cell, w in zip(r, widths)).rstrip() for r in rows]


def _tasks() -> list[str]:
    from latentrl.envs.tasks import TASKS

    rows = [("task", "gymnasium id", "suites (tasks/<kind>)", "eval default")]
    rows += [(s.name, s.gym_id or "-", s.suite_kind, ", ".join(s.suites) or "-") for s in TASKS.values()]
    return ["tasks (env.task in configs; gymnasium.make(id) or gymnasium.make_vec(id, num_envs=N)):", *_table(rows)]


def _policies() -> list[str]:
    from latentrl.evaluation.trained import motion_of, stored_env
    from latentrl.resources import POLICIES, packaged

    rows = [("policy", "task", "motion", "texts", "card")]
    for file in sorted(packaged(POLICIES).glob("*.pt")):
        env = stored_env(file)
        card = file.with_suffix(".md")
        rows.append((file.stem, env.task if env else "?", motion_of(env), ", ".join(env.texts) if env else "?",
                     f"{POLICIES}/{card.name}" if card.is_file() else "-"))
    return ["policies (latentrl/policies/NAME.pt; latentrl eval NAME):", *_table(rows)]


def _configs() -> list[str]:
    from latentrl.resources import CONFIGS, packaged

    root = packaged(CONFIGS)
    rows = [("config", "command", "task", "texts")]
    for file in sorted(root.rglob("*.yaml"), key=lambda p: (len(p.relative_to(root).parts), str(p))):
        name = file.relative_to(root).with_suffix("").as_posix()
        if name.startswith("motion/"):
            rows.append((name, "latentrl motion train", "-", "-"))
            continue
        if name.startswith("physics/"):
            rows.append((name, "latentrl physics train-tracker", "-", "-"))
            continue
        env = _yaml_env(file)
        texts = ", ".join(map(str, env.get("texts", ["walk"])))
        rows.append((name, "latentrl train", str(env.get("task", "reach")), texts))
    return ["configs (by name or path):", *_table(rows)]


def _yaml_env(file: Path) -> dict:
    """The ``env`` section of a config file as written (no defaults, no validation; {} if it has none)."""
    import yaml

    data = yaml.safe_load(file.read_text(encoding="utf-8")) or {}
    env = data.get("env") if isinstance(data, dict) else None
    return env if isinstance(env, dict) else {}


def _suites() -> list[str]:
    from latentrl.envs.tasks import TASKS
    from latentrl.resources import suites_folder

    rows = [("kind", "taken by", "suites")]
    for kind in SUITE_KINDS:
        tasks = [s.name for s in TASKS.values() if s.suite_kind == kind]
        user = f"eval --paths ({', '.join(tasks)})" if tasks else "optimize SUITE"
        names = sorted(p.stem for p in suites_folder(kind).glob("*.json"))
        rows.append((kind, user, ", ".join(names) or "-"))
    return ["suites (latentrl/tasks/<kind>/<name>.json; by name):", *_table(rows)]


def _prompts(motion: str) -> list[str]:
    from latentrl.motion.checkpoint import load_motion_model

    model = load_motion_model(motion)
    prompts = getattr(model.text_encoder, "prompts", None)
    head = f"prompts of motion model '{motion}' (--text):"
    if not prompts:
        return [head, f"  any text (encoder {getattr(model.text_encoder, 'name', type(model.text_encoder).__name__)})"]
    return [head, *(f"  {p}" for p in prompts)]
