"""``EnvConfig``: per-task sections, keys of the earlier flat section, and the config stored with a policy."""

from pathlib import Path

from latentrl.app.train import TrainConfig
from latentrl.config import load_config
from latentrl.envs.config import EnvConfig, build, stored_env_config

TINY = Path(__file__).resolve().parents[2] / "configs" / "tiny.yaml"


def test_flat_keys_of_earlier_configs_land_in_their_task_section(tmp_path):
    old = tmp_path / "old.yaml"
    old.write_text("env: {task: path, num_envs: 2, observe_next: true, random_waypoints: 3}\n")
    cfg = load_config(TrainConfig, old, ["env.goal_angle_deg=30"])
    assert cfg.env.path.observe_next and cfg.env.path.random_waypoints == 3 and cfg.env.observe_next
    assert cfg.env.reach.goal_angle_deg == 30.0


def test_checkpoint_config_gives_the_eval_env_its_training_settings():
    stored = {"env": {"task": "path", "action_bound": 2.5, "guidance_scale": 3.0, "observe_next": True}}
    env = stored_env_config(stored)
    assert (env.action_bound, env.guidance_scale, env.observe_next) == (2.5, 3.0, True)
    assert stored_env_config({"ppo": {}}) is None and stored_env_config(None) is None


def test_build_maps_the_task_section_and_rewards_onto_the_env(tiny_model):
    cfg = EnvConfig(task="reach", num_envs=2)
    cfg.reach.goal_angle_deg = 20.0
    cfg.rewards.contact_threshold = 0.05
    env = build(cfg, "cpu", motion=tiny_model)
    assert env.goal_angle_deg == 20.0 and env.rewards.config.contact_threshold == 0.05
