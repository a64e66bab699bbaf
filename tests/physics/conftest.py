from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def sampled_walk(tmp_path_factory) -> Path:
    """A 2 s walk sampled from the default motion model with ``latentrl motion sample`` (features included)."""
    from latentrl.app.cli import main

    out = tmp_path_factory.mktemp("physics") / "walk.npz"
    assert main(["motion", "sample", "--text", "walk", "--seconds", "2", "--seed", "3", "--out", str(out)]) == 0
    return out
