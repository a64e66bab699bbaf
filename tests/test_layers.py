"""The import rules of docs/architecture.md, checked on the source (every import, lazy ones included).

1. Each package sits on a floor; a module may import its own floor and the floors below, never above.
2. A few packages are kept apart from neighbours on their own floor or below (``ppo`` never sees the
   motion model or the envs; ``motion`` is the frozen runtime and imports only the ground floor; ``optim``,
   the noise optimizer, shares the evaluation's floor and may use its metric kernels, never the reverse).
3. No import cycles, neither between modules nor between packages.

``latentrl/__init__.py`` (the version and the Gymnasium registration) is left out: every import of
``latentrl.x`` runs it anyway.
"""

from __future__ import annotations

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parents[1] / "latentrl"

FLOORS = (
    ("errors", "constants", "config", "safe_io", "preflight", "timing", "resources", "monitor", "runlock",
     "interrupts", "memory"),
    ("motion",),
    ("datasets", "render", "rewards", "scenes"),
    ("motion_training", "envs", "ppo", "physics"),
    ("evaluation", "optim"),
    ("viewer", "export"),
    ("app", "cli", "__main__"),
)
"""Ground floor first; a unit is a top-level module or subpackage of ``latentrl``."""

APART = {
    "motion": ("envs", "ppo", "evaluation", "datasets", "render", "app", "rewards", "motion_training"),
    "ppo": ("motion", "envs", "rewards", "datasets", "render", "evaluation", "motion_training"),
    "envs": ("ppo", "datasets", "motion_training"),
    "rewards": ("datasets", "render"),
    "motion_training": ("envs", "ppo", "rewards", "render"),
    "optim": ("motion_training", "datasets"),
    "evaluation": ("optim",),
    "scenes": ("datasets", "render", "rewards"),
    "physics": ("envs", "motion_training"),
}
"""unit -> units it must not import, whatever their floor."""


def module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imports_of(path: Path, root: Path, modules: set[str]) -> set[str]:
    """The ``modules`` that ``path`` imports: ``from a import b`` counts ``a.b`` if that is a module, else ``a``."""
    name = module_name(path, root)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join(anchor + ([base] if base else []))
            found.update(f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base for a in node.names)
    return found & modules - {name}


def import_graph(root: Path = PACKAGE) -> dict[str, set[str]]:
    """Module -> the modules of the package it imports (the root ``__init__`` left out)."""
    files = {module_name(p, root): p for p in root.rglob("*.py")}
    modules = set(files) - {root.name}
    return {name: imports_of(files[name], root, modules) for name in modules}


def unit(module: str) -> str:
    return module.split(".")[1]


def floor(name: str) -> int | None:
    return next((i for i, units in enumerate(FLOORS) if name in units), None)


def find_cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One cycle per strongly connected group of more than one node (Tarjan), as a sorted list of its nodes."""
    index, low, stack, on_stack, groups = {}, {}, [], set(), []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph.get(v, ()):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                groups.append(sorted(group))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return groups


def violations(root: Path = PACKAGE) -> list[str]:
    """Every broken rule, one line each (empty when the package keeps its floors)."""
    graph = import_graph(root)
    problems = []
    for src, targets in sorted(graph.items()):
        for dst in sorted(targets):
            a, b = unit(src), unit(dst)
            if a == b:
                continue
            fa, fb = floor(a), floor(b)
            if fa is None or fb is None:
                problems.append(f"{src} -> {dst}: '{a if fa is None else b}' has no floor in FLOORS")
            elif fb > fa:
                problems.append(f"{src} -> {dst}: floor {fa} ({a}) imports floor {fb} ({b})")
            if b in APART.get(a, ()):
                problems.append(f"{src} -> {dst}: {a} must not import {b}")
    problems += [f"module cycle: {' <-> '.join(c)}" for c in find_cycles(graph)]
    units: dict[str, set[str]] = {}
    for src, targets in graph.items():
        units.setdefault(unit(src), set()).update(unit(t) for t in targets if unit(t) != unit(src))
    problems += [f"package cycle: {' <-> '.join(c)}" for c in find_cycles(units)]
    return problems


def test_the_package_keeps_its_floors():
    assert violations() == []


def test_every_unit_has_a_floor():
    names = {p.stem for p in PACKAGE.glob("*.py") if p.stem != "__init__"}
    names |= {p.parent.name for p in PACKAGE.glob("*/__init__.py")}
    assert sorted(n for n in names if floor(n) is None) == []


def _plant(root: Path, files: dict[str, str]) -> Path:
    pkg = root / "latentrl"
    for rel, text in {"__init__.py": "", **files}.items():
        (pkg / rel).parent.mkdir(parents=True, exist_ok=True)
        (pkg / rel).write_text(text)
    return pkg


def test_the_checker_catches_planted_violations(tmp_path):
    pkg = _plant(tmp_path, {
        "motion/__init__.py": "",
        "motion/rollout.py": "def f():\n    from latentrl.envs.base import Env\n",  # upward and apart, lazily
        "envs/__init__.py": "",
        "envs/base.py": "from latentrl.motion import rollout\nEnv = 1\n",
        "ppo/__init__.py": "",
        "ppo/a.py": "from . import b\n",  # a relative cycle inside one package
        "ppo/b.py": "from latentrl.ppo import a\n",
        "errors.py": "",
    })
    found = violations(pkg)
    assert any("latentrl.motion.rollout -> latentrl.envs.base: floor 1 (motion) imports floor 3" in p for p in found)
    assert any("motion must not import envs" in p for p in found)
    assert "module cycle: latentrl.ppo.a <-> latentrl.ppo.b" in found
    assert any(p.startswith("module cycle: latentrl.envs.base") for p in found)
    assert "package cycle: envs <-> motion" in found


def test_the_checker_passes_a_clean_tree(tmp_path):
    pkg = _plant(tmp_path, {"motion/__init__.py": "from latentrl.errors import E\n", "errors.py": "E = 1\n",
                            "app/__init__.py": "import latentrl.motion\n"})
    assert violations(pkg) == []


ARCHITECTURE = PACKAGE.parent / "docs" / "architecture.md"


def documented_floors(text: str) -> dict[str, int]:
    """Unit -> floor from the module map of docs/architecture.md.

    Each table row gives its floor and, backticked in its package cell, its units (``app/`` and ``render.py``
    name the units ``app`` and ``render``).
    """
    import re

    found = {}
    for line in text.splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 4 and cells[0].isdigit():
            for name in re.findall(r"`([A-Za-z_]\w*)(?:/|\.py)?`", cells[1]):  # not `python -m latentrl`
                found[name] = int(cells[0])
    return found


def test_the_architecture_table_matches_the_enforced_floors():
    enforced = {name: i for i, units in enumerate(FLOORS) for name in units}
    assert documented_floors(ARCHITECTURE.read_text(encoding="utf-8")) == enforced


def test_the_table_parser_reads_rows_and_names():
    table = "| floor | package | what | may import |\n|---|---|---|---|\n| 0 | `errors`, `runlock` | x | y |\n" \
            "| 6 | `app/` (and `cli.py`, `python -m latentrl`) | x | `motion` |\n"
    assert documented_floors(table) == {"errors": 0, "runlock": 0, "app": 6, "cli": 6}
