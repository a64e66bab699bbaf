"""``latentrl export onnx`` refuses a broken policy with exit 2 in one line and writes nothing.

Each checkpoint is the shipped walk policy with one value broken and its hashes recomputed (so it loads
as a checkpoint written with that value would): a NaN weight, an inf weight, a NaN stored guidance
scale, an infinite stored action bound. Tracing and checking happen in memory, so ``--out`` never
appears when the export fails.
"""

import copy
from pathlib import Path

import pytest
import torch

from latentrl.app.cli import main
from latentrl.ppo.checkpoint import config_hash, weights_sha256

pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")

ROOT = Path(__file__).resolve().parents[2]
WALK_POLICY = ROOT / "policies" / "reach_walk_default.pt"


@pytest.fixture(scope="module")
def walk_state():
    return torch.load(WALK_POLICY, map_location="cpu", weights_only=True)


def first_weight(state: dict) -> str:
    """The first weight matrix of the policy (the same name every time)."""
    return next(k for k in state["policy"] if k.endswith("weight") and state["policy"][k].dim() == 2)


def damaged(walk_state: dict, tmp_path: Path, how: str) -> tuple[Path, str]:
    """A copy of the walk policy with ``how`` broken, and the name the refusal must give."""
    state = copy.deepcopy(walk_state)
    name = first_weight(state)
    if how in ("nan weight", "inf weight"):
        state["policy"][name][0, 0] = float("nan") if how == "nan weight" else float("inf")
        expected = f"policy weight '{name}' holds 1 non-finite value(s) ({how.split()[0].replace('nan', 'NaN')})"
    elif how == "nan guidance":
        state["config"]["env"]["guidance_scale"] = float("nan")
        expected = "guidance_scale"
    else:
        state["config"]["env"]["action_bound"] = float("inf")
        expected = "action_bound"
    state["policy_sha256"], state["config_hash"] = weights_sha256(state["policy"]), config_hash(state["config"])
    path = tmp_path / f"{how.replace(' ', '_')}.pt"
    torch.save(state, path)
    return path, expected


@pytest.mark.parametrize("how", ["nan weight", "inf weight", "nan guidance", "inf action bound"])
def test_a_broken_policy_is_refused_in_one_line_and_leaves_no_file(how, walk_state, tmp_path, capsys):
    policy, expected = damaged(walk_state, tmp_path, how)
    out = tmp_path / "out" / "controller.onnx"
    out.parent.mkdir()
    assert main(["export", "onnx", str(policy), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert str(policy) in err and expected in err, err
    assert list(out.parent.iterdir()) == []  # neither the file nor a temporary


def test_an_existing_file_at_out_is_kept_when_the_export_is_refused(walk_state, tmp_path, capsys):
    """A refused export does not replace (or remove) what ``--out`` held before."""
    policy, _ = damaged(walk_state, tmp_path, "nan weight")
    out = tmp_path / "controller.onnx"
    out.write_bytes(b"an earlier export")
    assert main(["export", "onnx", str(policy), "--out", str(out)]) == 2
    capsys.readouterr()
    assert out.read_bytes() == b"an earlier export"


@pytest.mark.parametrize("name, inputs", [("joystick_walk_default", ["command_heading_deg", "command_speed"]),
                                          ("timed_walk_default", ["goal", "time_left"])])
def test_a_joystick_or_timed_policy_exports_by_name_with_its_task_inputs(name, inputs, tmp_path, capsys):
    """Once refused by their task, shipped joystick and timed policies export, with the inputs their env observes."""
    import onnx

    out = tmp_path / "controller.onnx"
    assert main(["export", "onnx", name, "--out", str(out)]) == 0
    assert "wrote" in capsys.readouterr().out
    names = [i.name for i in onnx.load(str(out)).graph.input]
    assert names == ["history", "world_rotation", "world_translation", "airborne", *inputs, "text_embedding"]


def test_a_shipped_policy_exports_by_name(tmp_path, capsys):
    out = tmp_path / "controller.onnx"
    assert main(["export", "onnx", "reach_walk_default", "--out", str(out)]) == 0
    assert out.stat().st_size > 0 and "wrote" in capsys.readouterr().out


def test_a_scene_policy_with_a_height_grid_is_refused_in_one_line(tmp_path, capsys):
    state = torch.load(ROOT / "policies" / "reach_obstacles_default.pt", map_location="cpu", weights_only=True)
    state["config"]["env"]["height_grid"] = 5
    state["policy_sha256"], state["config_hash"] = weights_sha256(state["policy"]), config_hash(state["config"])
    policy = tmp_path / "grid.pt"
    torch.save(state, policy)
    out = tmp_path / "controller.onnx"
    assert main(["export", "onnx", str(policy), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "observes a height grid (env.height_grid 5)" in err, err
    assert not out.exists()


def test_a_policy_trained_blind_among_objects_exports_without_scene_rays(walk_state, tmp_path, capsys):
    """``env.observe_scene: false``: the graph takes the flat walk's inputs (the engine supplies the route's point
    as the goal), not rays the policy never observed."""
    import onnx

    state = copy.deepcopy(walk_state)
    state["config"]["env"].update(scene={"random_obstacles": {}}, observe_scene=False, route=0.5)
    state["config_hash"] = config_hash(state["config"])
    policy = tmp_path / "blind.pt"
    torch.save(state, policy)
    out = tmp_path / "controller.onnx"
    assert main(["export", "onnx", str(policy), "--out", str(out)]) == 0, capsys.readouterr().err
    names = [i.name for i in onnx.load(str(out)).graph.input]
    assert "scene_rays" not in names and "goal" in names
