"""docs/export.md's onnxruntime snippets run as pasted: the reach one on exports of the shipped walk policy made
with and without ``--text`` (its pelvis comes near the goal), the joystick, timed and ReachJoint ones on exports of
the shipped joystick, timed and ReachJoint policies (the pelvis follows the command; it reaches the waypoint; it comes
near its target), as the page says."""

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


def _section_snippet(title: str) -> str:
    return re.search(rf"## {title}\n.*?```python\n(.*?)```", DOC.read_text(encoding="utf-8"), flags=re.S).group(1)


def _export_and_run_section(policy: str, out: str, title: str) -> dict:
    """Export ``policy`` to ``out`` as the page does, then run the page's ``title`` section as pasted; its names."""
    assert main(["export", "onnx", policy, "--out", out, "--text", "walk"]) == 0
    names: dict = {"__name__": "__export_doc__"}
    exec(compile(_section_snippet(title), f"docs/export.md {title} block", "exec"), names)  # noqa: S102
    return names


def test_the_joystick_snippet_runs_as_pasted_and_follows_the_command(tmp_path, monkeypatch):
    """Straight on (+y) for 4 s, then a left turn: the pelvis goes +y first, then -x, as the page says."""
    monkeypatch.chdir(tmp_path)
    names = _export_and_run_section("joystick_walk_default", "joystick.onnx", "Joystick policies")
    pelvis = np.concatenate(names["frames"])[:, 0]
    assert pelvis.shape == (240, 3) and np.isfinite(pelvis).all()
    first, second = pelvis[119] - pelvis[0], pelvis[-1] - pelvis[119]
    assert first[1] > 3.0 and abs(first[0]) < 0.5  # 4 s at 1.2 m/s along +y
    assert second[0] < -3.0  # then along -x


def test_the_timed_snippet_runs_as_pasted_and_reaches_the_waypoint(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    names = _export_and_run_section("timed_walk_default", "timed.onnx", "Timed policies")
    pelvis = np.concatenate(names["frames"])[:, 0]
    assert pelvis.shape == (144, 3) and np.isfinite(pelvis).all()
    dist = np.linalg.norm(pelvis[:, :2] - names["goal"][0, :2], axis=1)
    assert dist.min() < 0.3 and dist[-1] < 0.3  # reaches the waypoint (DART's radius) and stays near it


def test_the_scene_snippet_runs_as_pasted_and_walks_around_the_pillars(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert main(["export", "onnx", "reach_obstacles_default", "--out", "obstacles.onnx", "--text", "walk"]) == 0
    names: dict = {"__name__": "__export_doc__"}
    exec(compile(_section_snippet("Scene policies"), "docs/export.md scene block", "exec"), names)  # noqa: S102
    joints = np.concatenate(names["frames"])
    assert joints.shape == (192, 22, 3) and np.isfinite(joints).all()
    assert np.linalg.norm(joints[:, 0, :2] - names["goal"][0, :2], axis=1).min() < 0.3
    for x, y, r in names["pillars"]:
        assert (np.linalg.norm(joints[:, :, :2] - np.array([x, y]), axis=-1) - r).min() > 0.0


def test_the_reach_joint_snippet_runs_as_pasted_and_brings_the_pelvis_near_its_target(tmp_path, monkeypatch):
    """The pelvis goal 2.5 s ahead: the graph is the policy alone, so near (the page: 26 cm at the goal frame)."""
    monkeypatch.chdir(tmp_path)
    names = _export_and_run_section("reach_joint_default", "reach_joint.onnx", "ReachJoint policies")
    pelvis = names["pelvis"]
    assert pelvis.shape == (80, 3) and np.isfinite(pelvis).all()
    assert np.linalg.norm(pelvis[0, :2] - names["target"][0, :2]) > 1.5
    assert np.linalg.norm(pelvis[-1, :2] - names["target"][0, :2]) < 0.5
    assert abs(float(names["error"]) - 0.261) < 0.05  # the page's figure
