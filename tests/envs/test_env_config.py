"""``EnvConfig``: per-task sections, keys of the earlier flat section, and the config stored with a policy."""

from pathlib import Path

import pytest
import torch

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


def test_joystick_and_timed_sections_round_trip_and_build(tmp_path, tiny_model):
    import dataclasses

    from latentrl.config import from_dict
    from latentrl.envs.joystick import JoystickEnv
    from latentrl.envs.timed import TimedPathEnv

    f = tmp_path / "joy.yaml"
    f.write_text("env: {task: joystick, num_envs: 2, texts: [run], joystick: {speed_range: [2.5, 4.0], "
                 "heading_change_deg: 45}}\n")
    cfg = load_config(TrainConfig, f, ["env.joystick.heading_change_seconds=[1.0,3.0]"])
    assert cfg.env.joystick.speed_range == [2.5, 4.0] and cfg.env.joystick.heading_change_seconds == [1.0, 3.0]
    again = from_dict(EnvConfig, dataclasses.asdict(cfg.env), "stored")  # what a checkpoint stores and eval reads
    assert again == cfg.env
    env = build(again, "cpu", motion=tiny_model)
    assert isinstance(env, JoystickEnv) and env.speed_range == (2.5, 4.0) and env.heading_change_deg == 45.0
    assert env.max_episode_steps == 75

    timed = stored_env_config({"env": {"task": "timed", "num_envs": 1, "timed": {"paths": "timed_walk",
                                                                                 "observe_next": True}}})
    assert timed.observe_next
    env = build(timed, "cpu", motion=tiny_model)
    assert isinstance(env, TimedPathEnv) and len(env.paths) == 3 and env.paths[0].times[0] == 3.5
    commands = EnvConfig(task="joystick", num_envs=1)
    commands.joystick.commands = "joystick_walk"
    assert len(build(commands, "cpu", motion=tiny_model).timelines) == 3


def test_bad_task_sections_name_the_dotted_key(tmp_path):
    import pytest

    from latentrl.errors import ConfigError

    f = tmp_path / "bad.yaml"
    f.write_text("env: {task: joystick, joystick: {speed_range: [1.5, 1.0]}}\n")
    with pytest.raises(ConfigError, match=r"env\.joystick\.speed_range: must be \[min, max\] m/s"):
        load_config(TrainConfig, f)
    f.write_text("env: {task: timed, timed: {time_left_clip: 0}}\n")
    with pytest.raises(ConfigError, match=r"env\.timed\.time_left_clip: must be > 0"):
        load_config(TrainConfig, f)


def test_mixed_skill_config_builds_a_path_env_with_a_text_per_waypoint(tiny_model, tmp_path):
    import pytest

    from latentrl.envs.path import FollowPathEnv
    from latentrl.errors import ConfigError

    mixed = TINY.parent / "policies" / "path_mixed_default.yaml"
    cfg = load_config(TrainConfig, mixed, ["env.num_envs=2"])
    cfg.ppo.plan(128)
    assert cfg.env.task == "path" and cfg.env.texts == ["walk", "run", "hop on left leg"]
    assert cfg.eval.paths == ["tasks/paths/mixed_skills.json"]
    env = build(cfg.env, "cpu", motion=tiny_model)
    assert isinstance(env, FollowPathEnv) and env.text_per_waypoint and env.paths is None
    assert env.random_segment == (2.0, 6.0) and env.random_turn_deg == 45.0 and env.next_at_last == "extend"
    with pytest.raises(ConfigError, match=r"env\.path\.random_segment: must be \[min, max\] metres"):
        load_config(TrainConfig, mixed, ["env.path.random_segment=[3.0,1.0]"])


def test_next_at_last_reaches_the_path_and_timed_envs_and_the_eval_settings(tiny_model):
    """``env.path.next_at_last`` / ``env.timed.next_at_last`` build envs with it, and eval takes it from the policy."""
    from latentrl.evaluation.config import EvalSettings

    for task in ("path", "timed"):
        cfg = EnvConfig(task=task, num_envs=1, texts=["walk"])
        getattr(cfg, task).next_at_last = "extend"
        cfg.validate()
        assert build(cfg, "cpu", motion=tiny_model).next_at_last == "extend"
        settings = EvalSettings()
        settings.take_training_env(cfg)
        assert settings.next_at_last == "extend"
    settings = EvalSettings()
    settings.take_training_env(EnvConfig(task="reach"))
    assert settings.next_at_last == "repeat"


def test_amp_samples_the_motion_in_bf16_keeps_float32_outputs_and_reaches_eval():
    """``env.amp: bf16``: the model samples under autocast (results move a little), the env's outputs stay float32,
    eval takes the setting from the policy, and a bad value is refused naming the field."""
    from latentrl.errors import ConfigError
    from latentrl.evaluation.config import EvalSettings
    from tests.envs.conftest import actions
    from tests.helpers import make_tiny_model

    plain_model, amp_model = make_tiny_model(), make_tiny_model()  # fresh: the env sets the model's amp_dtype
    cfg = EnvConfig(task="reach", num_envs=3, texts=["walk"], amp="bf16")
    cfg.validate()
    env = build(cfg, "cpu", motion=amp_model)
    plain = build(EnvConfig(task="reach", num_envs=3, texts=["walk"]), "cpu", motion=plain_model)
    assert amp_model.amp_dtype == torch.bfloat16 and plain_model.amp_dtype is None
    env.reset(seed=0)
    plain.reset(seed=0)
    obs, reward, *_ = env.step(actions(3))
    obs_plain, reward_plain, *_ = plain.step(actions(3))
    assert obs.dtype == reward.dtype == torch.float32
    assert not torch.equal(obs, obs_plain) and torch.allclose(obs, obs_plain, atol=0.2)
    settings = EvalSettings()
    settings.take_training_env(cfg)
    assert settings.amp == "bf16" and settings.motion_kwargs()["amp"] == "bf16"
    bad = EnvConfig(amp="int8")
    with pytest.raises(ConfigError, match="amp.*int8"):
        bad.validate()
    with pytest.raises(ConfigError, match="amp.*int8"):
        build(bad, "cpu", motion=plain_model)


def test_env_route_reaches_the_env_and_the_eval_settings_and_bad_values_name_the_key(tmp_path, tiny_model):
    from latentrl.errors import ConfigError
    from latentrl.evaluation.config import EvalSettings

    cfg = EnvConfig(task="reach", num_envs=2, scene={"random_obstacles": {}}, route=0.4)
    cfg.validate()
    env = build(cfg, "cpu", motion=tiny_model)
    assert env.route.clearance == 0.4 and env.guide is not None
    assert build(EnvConfig(task="reach", num_envs=2, scene={"random_obstacles": {}}), "cpu",
                 motion=tiny_model).guide is None
    settings = EvalSettings()
    settings.take_training_env(cfg)
    assert settings.route == 0.4 and settings.scene_kwargs(cfg.scene_spec())["route"] == 0.4
    f = tmp_path / "bad.yaml"
    for body, message in (("route: 0.5", r"env\.route: needs a scene \(env\.scene\)"),
                          ("scene: {random_obstacles: {}}, route: 3", r"env\.route: expected the route's clearance"),
                          ("scene: {random_obstacles: {}}, route: true", r"env\.route: Value 'True' of type 'bool'")):
        f.write_text(f"env: {{task: reach, {body}}}\n")
        with pytest.raises(ConfigError, match=message):
            load_config(TrainConfig, f)


def test_env_observe_scene_false_trains_blind_among_objects_and_the_eval_and_export_follow(tmp_path, tiny_model):
    from latentrl.envs.config import observes_scene
    from latentrl.errors import ConfigError
    from latentrl.evaluation.config import EvalSettings

    seeing = EnvConfig(task="reach", num_envs=2, scene={"random_obstacles": {}})
    blind = EnvConfig(task="reach", num_envs=2, scene={"random_obstacles": {}}, observe_scene=False, route=0.5)
    blind.validate()
    flat = build(EnvConfig(task="reach", num_envs=2), "cpu", motion=tiny_model)
    envs = {name: build(cfg, "cpu", motion=tiny_model) for name, cfg in (("seeing", seeing), ("blind", blind))}
    assert "scene_rays" in envs["seeing"].observation_layout and envs["seeing"].observe_scene
    assert "scene_rays" not in envs["blind"].observation_layout and not envs["blind"].observe_scene
    # blind, the observation is the flat env's size: a flat-floor policy warm-starts it as it is
    assert envs["blind"].observation_space.shape == flat.observation_space.shape
    assert envs["blind"].scene is not None and envs["blind"].guide is not None  # the objects are there all the same
    settings = EvalSettings()
    settings.take_training_env(blind)
    assert settings.scene_kwargs(blind.scene_spec())["observe_scene"] is False
    settings.take_training_env(seeing)
    assert settings.scene_kwargs(seeing.scene_spec())["observe_scene"] is True
    assert observes_scene({"scene": "maze_a"}) and not observes_scene({"scene": "maze_a", "observe_scene": False})
    assert not observes_scene({}) and not observes_scene(None)
    f = tmp_path / "bad.yaml"
    for body, message in (("observe_scene: false", r"env\.observe_scene: false needs a scene \(env\.scene\)"),
                          ("scene: {random_obstacles: {}}, observe_scene: false, height_grid: 5",
                           r"env\.height_grid: is observed with the scene; env\.observe_scene is false")):
        f.write_text(f"env: {{task: reach, {body}}}\n")
        with pytest.raises(ConfigError, match=message):
            load_config(TrainConfig, f)
