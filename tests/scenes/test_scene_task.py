"""The reach-among-obstacles task: its config loads and builds, its suite is the generator's."""

from pathlib import Path

import torch

from latentrl.app.train import TrainConfig
from latentrl.config import load_config
from latentrl.envs.config import build
from latentrl.envs.path import load_paths
from latentrl.evaluation import suites
from latentrl.scenes.random import RandomObstacles

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "reach_obstacles.yaml"


def test_the_config_builds_a_reach_env_among_obstacles(tiny_model):
    cfg = load_config(TrainConfig, CONFIG, ["env.num_envs=4"])
    assert cfg.env.scene_spec() == RandomObstacles(count=[3, 8])
    env = build(cfg.env, "cpu", motion=tiny_model)
    assert env.rewards.weights["collision"] == 10.0 and "scene_rays" in env.observation_layout
    env.reset(seed=0)
    assert int(env.scene.batch.object_counts().min()) >= 3
    _, _, _, _, infos = env.step(torch.zeros(4, 16))
    assert infos["reward/collision"].shape == (4,)
    assert cfg.eval.paths == ["tasks/paths/reach_obstacles.json"]


def test_the_suite_holds_single_goals_ahead():
    paths = load_paths(suites.default_folder() / "reach_obstacles.json")
    assert paths == suites.reach_obstacles() and all(len(p.waypoints) == 1 for p in paths)
    for p in paths:
        x, y, _ = p.waypoints[0]
        assert 2.99 <= (x * x + y * y) ** 0.5 <= 5.01 and y > abs(x) * 0.99  # within 45 degrees of +y
