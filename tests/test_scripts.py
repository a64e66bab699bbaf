"""scripts/ holds what users run (the Quickstart's run.sh, the GPU check); tools/ holds the maintainers' probes
and release helpers, which must still import (a moved module broke bench_onnx.py once)."""

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
TOOLS = sorted((ROOT / "tools").glob("*.py"))


def test_scripts_hold_only_what_users_run():
    assert sorted(p.name for p in (ROOT / "scripts").iterdir()) == ["gpu_check.sh", "run.sh"]


@pytest.mark.parametrize("script", TOOLS, ids=lambda p: p.name)
def test_tool_imports(script):
    spec = importlib.util.spec_from_file_location(f"tool_{script.stem}", script)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)  # module level only: every tool runs its work under __main__
    assert callable(getattr(module, "main", None))
