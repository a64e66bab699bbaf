"""A policy runs on the motion model it was trained on, found by the name or hash its checkpoint stores.

"default" meant v2 until 2026-11-26 and means v5 since; policies trained on v2 stored the name "default" and
v2's hash. The models before v5 left the package on 2026-11-27 (zoo/README.md): a policy trained on one must
say which file it needs instead of running on today's default.
"""

from pathlib import Path

import pytest
import torch

from latentrl.app.cli import main
from latentrl.errors import CheckpointError
from latentrl.evaluation.trained import stored_env, trained_motion
from latentrl.motion.checkpoint import (
    RETIRED_MODELS,
    default_model_path,
    embedded_name_for,
    embedded_sha256,
    file_sha256,
    load_motion_model,
)

ROOT = Path(__file__).resolve().parents[2]
POLICY = ROOT / "policies" / "reach_walk_default.pt"
V2_SHA = RETIRED_MODELS["default-v2"][1]


def _policy_on(tmp_path, name: str, motion: str, sha256: str) -> Path:
    """The shipped walk policy, its stored env motion and model hash changed to those of an older model."""
    state = torch.load(POLICY, weights_only=True)
    state["config"]["env"]["motion"] = motion
    state["motion"]["sha256"] = sha256
    torch.save(state, tmp_path / name)
    return tmp_path / name


def test_embedded_names_resolve_by_hash():
    today = file_sha256(default_model_path("default"))
    assert embedded_sha256("default") == embedded_sha256("default-v5") == today
    assert embedded_name_for(today) == "default"  # first name of the file
    assert embedded_name_for(V2_SHA) == "default-v2"  # no longer shipped, still named
    assert embedded_name_for("0" * 64) is None and embedded_name_for(None) is None


def test_a_policy_that_stored_default_before_v5_names_v2(tmp_path, capsys):
    old = _policy_on(tmp_path, "old.pt", "default", V2_SHA)  # as policies trained on v2 were written
    assert stored_env(old).motion == "default-v2"
    assert trained_motion(old) == "default-v2"
    assert trained_motion(old, "my_model.pt") == "my_model.pt"  # a model the user names wins
    code = main(["eval", str(old), "--paths", "dart_walk_long", "--episodes", "1", "--max-steps", "2",
                 "--no-render", "--no-motions", "--out", str(tmp_path / "eval")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert "default_motion_v2.pt" in err[0] and "zoo/README.md" in err[0] and "--motion" in err[0], err


@pytest.mark.parametrize("name", sorted(RETIRED_MODELS))
def test_a_retired_model_name_says_which_file_to_restore(name):
    with pytest.raises(CheckpointError, match=rf"{RETIRED_MODELS[name][0]}.*zoo/README\.md"):
        load_motion_model(name)


def test_names_that_match_or_hashes_no_file_has_are_kept(tmp_path):
    today = _policy_on(tmp_path, "today.pt", "default", embedded_sha256("default"))
    assert stored_env(today).motion == "default"
    # trained on a file this installation lacks and no release had: the check_motion error names it later
    foreign = _policy_on(tmp_path, "foreign.pt", "default", "0" * 64)
    assert stored_env(foreign).motion == "default"
    assert stored_env(_policy_on(tmp_path, "v3.pt", "default-v3", RETIRED_MODELS["default-v3"][1])).motion == \
        "default-v3"
