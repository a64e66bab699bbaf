"""Every ```python block of README.md runs as pasted (a newcomer's first contact with the API)."""

import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
BLOCKS = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S)


def test_readme_has_python_examples():
    assert len(BLOCKS) >= 2


@pytest.mark.parametrize("code", BLOCKS, ids=[f"block{i}" for i in range(len(BLOCKS))])
def test_readme_python_block_runs_as_pasted(code, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # a fresh namespace and folder: nothing defined elsewhere may leak in
    exec(compile(code, "README.md python block", "exec"), {"__name__": "__readme__"})  # noqa: S102
