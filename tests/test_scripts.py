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


def test_skate_probe_integrates_decoded_deltas_into_positions():
    """``--integrate``: future joints rebuilt from the last history joints and the summed deltas; a motion whose
    deltas agree with its positions comes back unchanged, a foot whose deltas say "still" stays put."""
    import torch

    from latentrl.motion.representation import SLICES, joints_of

    spec = importlib.util.spec_from_file_location("tool_skate_probe", ROOT / "tools" / "skate_probe.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    torch.manual_seed(0)
    joints = torch.randn(2, 11, 22, 3).cumsum(1)
    frames = torch.zeros(2, 10, 276)
    frames[..., SLICES["joints"]] = joints[:, :10].flatten(-2)
    frames[..., SLICES["joints_delta"]] = (joints[:, 1:] - joints[:, :10]).flatten(-2)
    assert torch.allclose(module.integrated(frames), frames, atol=1e-5)
    jittered = frames.clone()
    jittered[:, 2:, SLICES["joints"]] += 0.01 * torch.randn(2, 8, 66)
    jittered[..., SLICES["joints_delta"]] = 0.0
    rebuilt = joints_of(module.integrated(jittered))
    assert torch.equal(rebuilt[:, 2:], rebuilt[:, 1:2].expand(-1, 8, -1, -1))
    assert torch.equal(rebuilt[:, :2], joints_of(jittered)[:, :2])
