import ast
from pathlib import Path

import numpy as np

import latentrl
from latentrl.monitor import EvalReport, Monitor, RolloutStats
from tests.ppo.helpers import scalars, tags

ROOT = Path(latentrl.__file__).parent


def test_tags_and_steps(tmp_path):
    mon = Monitor(tmp_path)
    mon.log_rollout(10, RolloutStats(1.5, 7.0, None, 3))
    mon.log_train(10, {"approx_kl": 0.01, "value_loss": 0.5})
    mon.log_rewards(10, {"skate": -0.1, "reward/dist": 0.2})
    mon.log_time(10, fps=100.0, collection_s=0.5, update_s=0.25)
    image = np.zeros((4, 4, 3), np.uint8)
    mon.log_eval(20, EvalReport({"success_rate": 1.0, "floor_cm": 2.0}, {"eval/trajectories": image}))
    mon.log_sb3(30, {"train/loss": np.float32(0.3), "time/iterations": 3, "train/n_updates": 5, "custom/x": "text"},
                {"train/loss": ("stdout",)})
    mon.log_hparams({"ppo": {"learning_rate": 3e-4, "target_kl": None}, "policy": {"architecture": "dart|x"}})
    mon.close()
    found = scalars(tmp_path)
    assert set(found) == {"rollout/ep_rew_mean", "rollout/ep_len_mean", "train/approx_kl", "train/value_loss",
                          "reward/skate", "reward/dist", "time/fps", "time/collection_s", "time/update_s",
                          "eval/success_rate", "eval/floor_cm", "train/loss"}
    assert found["rollout/ep_len_mean"] == [(10, 7.0)] and found["train/loss"][0][0] == 30
    assert "eval/trajectories" in tags(tmp_path)["images"]
    assert "hyperparameters/text_summary" in tags(tmp_path)["tensors"]


def test_ppo_imports_only_downward():
    """House rule 2: ppo/ and monitor.py never import envs/, motion/, evaluation/ or the entry points."""
    banned = ("latentrl.envs", "latentrl.motion", "latentrl.evaluation", "latentrl.cli", "latentrl.bench",
              "latentrl.app", "latentrl.rewards", "latentrl.datasets", "latentrl.render")
    for path in [*sorted((ROOT / "ppo").glob("*.py")), ROOT / "monitor.py"]:
        for node in ast.walk(ast.parse(path.read_text())):
            names = [a.name for a in node.names] if isinstance(node, ast.Import) else (
                [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            for name in names:
                assert not name.startswith(banned), f"{path.name} imports {name}"
