"""``eval/mean_reward``: the periodic evaluation's mean episode return, gathered by the shared episode loop."""

from types import SimpleNamespace

import matplotlib.pyplot as plt
import numpy as np
import pytest
import torch

from latentrl.evaluation.episodes import collect_returns, rollout
from latentrl.evaluation.runner import training_eval_hook
from latentrl.monitor import EVAL_MEAN_REWARD, EVAL_TRAJECTORIES, EvalReport, Monitor
from tests.evaluation.conftest import NEAR, fresh_policy, write_paths
from tests.ppo.helpers import scalars


class Staggered:
    """Env ``i`` earns ``0.5`` per step and completes at step ``i + 1``; steps after the end still pay (ignored)."""

    num_envs, device = 3, torch.device("cpu")

    def reset(self, seed=None):
        self.k = 0
        return torch.zeros(self.num_envs, 1), {}

    def step(self, action):
        self.k += 1
        end = torch.arange(self.num_envs) + 1 == self.k
        infos = {"is_success": end, "diverged": torch.zeros(self.num_envs, dtype=torch.bool)}
        return torch.zeros(self.num_envs, 1), torch.full((self.num_envs,), 0.5), end, torch.zeros_like(end), infos


def test_returns_stop_at_each_episodes_end():
    with collect_returns() as returns:
        out = rollout(Staggered(), lambda obs: obs, budget=5, seed=0)
    assert out["steps"].tolist() == [1, 2, 3] and returns == [0.5, 1.0, 1.5]
    rollout(Staggered(), lambda obs: obs, budget=5, seed=0)  # outside the block: the list is left alone
    assert returns == [0.5, 1.0, 1.5]


def test_training_hook_reports_the_mean_return(tmp_path, tiny_model):
    files = [write_paths(tmp_path, [NEAR])]
    env_cfg = SimpleNamespace(task="reach", guidance_scale=5.0, observe_next=False)
    eval_cfg = SimpleNamespace(episodes=2, max_steps=2, deterministic=True, text=None, success_target=None)
    report = training_eval_hook(files, tiny_model, env_cfg, eval_cfg)(fresh_policy(tiny_model))
    plt.close(report.figures[EVAL_TRAJECTORIES])
    assert np.isfinite(report.metrics["mean_reward"])
    monitor = Monitor(tmp_path / "run")
    monitor.log_eval(64, report)
    monitor.close()
    assert scalars(tmp_path / "run")[EVAL_MEAN_REWARD] == [(64, pytest.approx(report.metrics["mean_reward"]))]


def test_monitor_writes_eval_mean_reward(tmp_path):
    monitor = Monitor(tmp_path)
    monitor.log_eval(128, EvalReport({"mean_reward": 1.5, "success_rate": 0.25}))
    monitor.close()
    assert scalars(tmp_path)["eval/mean_reward"] == [(128, 1.5)]
