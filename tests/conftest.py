import os
from pathlib import Path

import pytest
import torch

ROOT = Path(__file__).resolve().parents[1]
SHARED = Path(os.environ.get("LATENTRL_SHARED", ROOT.parent / "shared"))
PARITY = SHARED / "reference" / "dart_parity_A"



def pytest_addoption(parser):
    parser.addoption("--kills", type=int, default=None, metavar="N",
                     help="tests/test_kill_loop.py: SIGKILLs per command (train, eval, optimize, motion train); "
                          "default: the CI counts; 50 for the full loop (docs/robustness.md)")


@pytest.fixture(scope="session")
def kill_count(request) -> int | None:
    """``--kills N`` (the kill loop's count per command), or None for each loop's CI count."""
    count = request.config.getoption("--kills")
    if count is not None and count < 1:
        raise pytest.UsageError(f"--kills {count}: expected a count >= 1")
    return count


@pytest.fixture(scope="session")
def parity_dir() -> Path:
    if not (PARITY / "expected.pt").is_file():
        pytest.skip(f"DART parity data not found at {PARITY} (set LATENTRL_SHARED to the shared folder)")
    return PARITY


@pytest.fixture(scope="session")
def tiny_model():
    """A small random-weight motion model with a hashed text encoder and a synthetic seed."""
    from tests.helpers import make_tiny_model

    return make_tiny_model()


@pytest.fixture(scope="session")
def eval_files(tmp_path_factory, tiny_model) -> dict[str, Path]:
    """``motion``: the tiny model saved as a file; ``policy``: a PPO checkpoint trained 'on' it (iteration 0)."""
    from latentrl.motion.checkpoint import file_sha256, save_motion_model
    from latentrl.ppo.checkpoint import make_checkpoint, save_checkpoint
    from tests.evaluation.conftest import fresh_policy

    root = tmp_path_factory.mktemp("eval_files")
    motion = save_motion_model(tiny_model, root / "tiny_motion.pt")
    policy = fresh_policy(tiny_model)
    state = make_checkpoint(trainer="native", iteration=0, env_steps=0, elapsed_s=0.0, policy=policy,
                            optimizer=torch.optim.Adam(policy.parameters()), config={"test": True},
                            motion={"path": str(motion), "sha256": file_sha256(motion)})
    return {"motion": motion, "policy": save_checkpoint(state, root / "policy.pt")}


# Tiny networks: one intra-op thread avoids OpenMP stalls on a busy 2-core machine, and keeps results
# identical between runs made inside module fixtures and inside tests.
torch.set_num_threads(1)


@pytest.fixture(autouse=True)
def _one_thread():
    """Commands set torch's thread count from their configs; every test starts (and ends) at one."""
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(1)
