"""A policy runs on the motion model it was trained on, found by the hash its checkpoint stores.

"default" meant v2 until stop 22 and means v5 since; policies trained on v2 stored the name "default" and
v2's hash, and must still be given v2 (now "default-v2") without the user naming it.
"""

from pathlib import Path

import torch

from latentrl.evaluation.trained import stored_env, trained_motion
from latentrl.motion.checkpoint import default_model_path, embedded_name_for, embedded_sha256, file_sha256

ROOT = Path(__file__).resolve().parents[2]
V2_POLICY = ROOT / "policies" / "reach_walk_v2.pt"


def test_embedded_names_resolve_by_hash():
    v2 = file_sha256(default_model_path("default-v2"))
    assert embedded_sha256("default-v2") == v2 != embedded_sha256("default")
    assert embedded_name_for(v2) == "default-v2"
    assert embedded_name_for(embedded_sha256("default-v5")) == "default"  # first name of the file
    assert embedded_name_for("0" * 64) is None and embedded_name_for(None) is None


def test_a_policy_that_stored_default_before_v5_runs_on_v2():
    state = torch.load(V2_POLICY, weights_only=True)
    assert state["config"]["env"]["motion"] == "default"  # as it was written in stop 14
    assert state["motion"]["sha256"] == embedded_sha256("default-v2")
    assert stored_env(V2_POLICY).motion == "default-v2"
    assert trained_motion(V2_POLICY) == "default-v2"
    assert trained_motion(V2_POLICY, "default-v4") == "default-v4"  # a model the user names wins


def test_names_that_match_or_hashes_no_file_has_are_kept(tmp_path):
    state = torch.load(V2_POLICY, weights_only=True)
    state["motion"]["sha256"] = embedded_sha256("default")  # says default and was trained on today's default
    torch.save(state, tmp_path / "today.pt")
    assert stored_env(tmp_path / "today.pt").motion == "default"
    state["motion"]["sha256"] = "0" * 64  # trained on a file this installation lacks: the check_motion error
    torch.save(state, tmp_path / "foreign.pt")  # names it later, so the name is not guessed here
    assert stored_env(tmp_path / "foreign.pt").motion == "default"
