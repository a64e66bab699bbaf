"""zoo/: the motion models and policies that left the package stay listed, reproducible and restorable.

zoo/README.md names each old model and policy, its config and card, and the commit whose tree still holds
the exact weights; these tests keep that index true (the restore test needs a clone with that commit).
"""

import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from latentrl.app.cli import main
from latentrl.app.train import TrainConfig
from latentrl.config import load_config
from latentrl.motion.checkpoint import RETIRED_MODELS, file_sha256
from latentrl.motion_training.trainer import MotionTrainConfig

ROOT = Path(__file__).resolve().parents[1]
ZOO = ROOT / "zoo"
README = (ZOO / "README.md").read_text()
CARDS = sorted(p.stem for p in (ZOO / "cards").glob("*.md"))
COMMIT = re.search(r"commit `([0-9a-f]{7,40})`", README).group(1)


def test_every_card_has_its_config_and_a_line_in_the_readme():
    assert len(CARDS) == 11
    for name in CARDS:
        assert (ZOO / "configs" / "policies" / f"{name}.yaml").is_file(), name
        assert f"(cards/{name}.md)" in README and f"(configs/policies/{name}.yaml)" in README, name
        model = "default-v" + name.rsplit("_v", 1)[1]
        card = (ZOO / "cards" / f"{name}.md").read_text()
        assert RETIRED_MODELS[model][1][:16] in card, name  # the card names its model by hash
        assert f"--motion zoo/weights/{RETIRED_MODELS[model][0]}" in card, name


def test_every_retired_model_is_listed_with_its_hash_and_config():
    for name, (file, sha) in RETIRED_MODELS.items():
        version = name.removeprefix("default-")
        assert f"latentrl/assets/{file}" in README and sha[:16] in README, name
        assert (ZOO / "configs" / "motion" / f"{version}.yaml").is_file(), name


def test_zoo_configs_load():
    for path in sorted((ZOO / "configs" / "policies").glob("*.yaml")):
        cfg = load_config(TrainConfig, path)
        assert cfg.env.motion.startswith("zoo/weights/default_motion_v"), path
        cfg.ppo.plan(cfg.env.num_envs)
    for path in sorted((ZOO / "configs" / "motion").glob("*.yaml")):
        load_config(MotionTrainConfig, path)
    candidates = sorted((ZOO / "configs" / "candidates").glob("*.yaml"))  # policies on unshipped models
    assert candidates
    for path in candidates:
        cfg = load_config(TrainConfig, path)
        assert cfg.env.motion.startswith("zoo/weights/") and cfg.ppo.init_from.startswith("runs/"), path
        cfg.ppo.plan(cfg.env.num_envs)


def _git(*args: str, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(["git", "-C", str(ROOT), *args], capture_output=True, **kw)


@pytest.fixture(scope="module")
def history():
    if shutil.which("git") is None or _git("cat-file", "-e", f"{COMMIT}^{{commit}}").returncode != 0:
        pytest.skip(f"commit {COMMIT} is not in this clone (shallow or no git)")


def test_the_named_commit_holds_every_old_file(history):
    paths = [f"latentrl/assets/{file}" for file, _ in RETIRED_MODELS.values()]
    paths += [f"latentrl/policies/{name}.pt" for name in CARDS]
    missing = [p for p in paths if _git("cat-file", "-e", f"{COMMIT}:{p}").returncode != 0]
    assert not missing, missing


def test_a_restored_old_policy_runs_on_its_restored_model(history, tmp_path):
    """The README's own example: restore reach_walk_v2 and default_motion_v2 from git, evaluate one short episode."""
    model, policy = tmp_path / "default_motion_v2.pt", tmp_path / "reach_walk_v2.pt"
    model.write_bytes(_git("show", f"{COMMIT}:latentrl/assets/default_motion_v2.pt", check=True).stdout)
    policy.write_bytes(_git("show", f"{COMMIT}:latentrl/policies/reach_walk_v2.pt", check=True).stdout)
    assert file_sha256(model) == RETIRED_MODELS["default-v2"][1]
    code = main(["eval", str(policy), "--motion", str(model), "--paths", "dart_walk_long", "--episodes", "1",
                 "--max-steps", "2", "--no-render", "--no-motions", "--out", str(tmp_path / "eval")])
    assert code == 0
    report = json.loads((tmp_path / "eval" / "report.json").read_text())
    assert report["motion"]["sha256"] == RETIRED_MODELS["default-v2"][1]
