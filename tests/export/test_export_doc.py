"""docs/export.md's onnxruntime snippet runs as pasted on exports of the shipped walk policy made with and
without ``--text``, and its pelvis comes near the goal as the page says."""

import re
from pathlib import Path

import numpy as np
import pytest

from latentrl.app.cli import main

pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")

DOC = Path(__file__).resolve().parents[2] / "docs" / "export.md"
SNIPPET = re.search(r"## Running it with onnxruntime\n\n```python\n(.*?)```", DOC.read_text(encoding="utf-8"),
                    flags=re.S).group(1)


@pytest.mark.parametrize("text", [["--text", "walk"], []], ids=["text-baked", "text-input"])
def test_the_snippet_runs_as_pasted(text, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["export", "onnx", "reach_walk_default", "--out", "controller.onnx", *text]) == 0
    names: dict = {"__name__": "__export_doc__"}
    exec(compile(SNIPPET, "docs/export.md python block", "exec"), names)  # noqa: S102
    joints = np.concatenate(names["frames"])
    assert joints.shape == (240, 22, 3) and np.isfinite(joints).all()
    reach = np.linalg.norm(joints[:, 0, :2] - names["goal"][0, :2], axis=1).min()
    assert reach < 0.3  # within DART's success radius (the page quotes the run's closest pass)
