"""The local height grid (``scene_height_grid``): known values on hand-made stairs, its place in the observation,
off by default, checked settings."""

import pytest
import torch

from latentrl.envs.reach import ReachLocationEnv
from latentrl.envs.scene import EnvScene, grid_offsets
from latentrl.errors import ConfigError
from latentrl.motion.skeleton import JOINT_NAMES
from latentrl.scenes import Box, Scene, Stairs

LEFT_HIP, RIGHT_HIP = JOINT_NAMES.index("left_hip"), JOINT_NAMES.index("right_hip")
# five 0.15 m steps of 0.3 m treads climbing +y from y = 1, 1.4 m wide (x in [-0.7, 0.7])
STAIRS = Scene((Stairs((0.0, 1.0), 90.0, 1.4, 0.15, 0.3, 5),))


def standing(x: float, y: float, facing_deg: float) -> torch.Tensor:
    """(1, 2, 22, 3) history joints: every joint at the pelvis (x, y, 0.9) but the hips, which set the facing."""
    joints = torch.zeros(1, 2, 22, 3)
    joints[..., 0], joints[..., 1], joints[..., 2] = x, y, 0.9
    a = torch.deg2rad(torch.tensor(facing_deg - 90.0))  # the right hip lies 90 degrees clockwise of the facing
    right = torch.stack((torch.cos(a), torch.sin(a))) * 0.1
    joints[..., RIGHT_HIP, :2] += right
    joints[..., LEFT_HIP, :2] -= right
    return joints


def test_offsets_run_back_to_front_and_right_to_left():
    off = grid_offsets(3, 0.5)
    assert off.tolist() == [[-0.5, -0.5], [-0.5, 0.0], [-0.5, 0.5], [0.0, -0.5], [0.0, 0.0], [0.0, 0.5],
                            [0.5, -0.5], [0.5, 0.0], [0.5, 0.5]]


def test_values_on_hand_made_stairs_facing_up_the_flight():
    scene = EnvScene(STAIRS, 1, torch.device("cpu"), 0.0)
    grid = scene.height_grid(standing(0.0, 1.2, 90.0), grid_offsets(7, 0.25)).reshape(7, 7)
    # the pelvis stands over step 0 (0.15 m); rows are y = 0.45 ... 1.95, columns x = +0.75 ... -0.75
    rows = torch.tensor([0.0, 0.0, 0.0, 0.15, 0.30, 0.45, 0.60]) - 0.15
    expected = rows[:, None].repeat(1, 7)
    expected[:, 0] = expected[:, -1] = -0.15  # x = +-0.75 lies beside the 1.4 m wide flight: the floor
    assert torch.allclose(grid, expected, atol=1e-6)


def test_values_follow_the_body_frame_and_are_clipped():
    scene = EnvScene(STAIRS, 1, torch.device("cpu"), 0.0)
    # on the floor at (-1, 1.45) facing +x, the flight's side (x = -0.7) just ahead
    grid = scene.height_grid(standing(-1.0, 1.45, 0.0), grid_offsets(3, 0.5)).reshape(3, 3)
    # rows: x = -1.5, -1.0, -0.5 (only the last is over the flight); columns: y = 0.95 (right), 1.45, 1.95 (left)
    assert torch.allclose(grid[:2], torch.zeros(2, 3))
    assert torch.allclose(grid[2], torch.tensor([0.0, 0.30, 0.60]), atol=1e-6)
    wall = EnvScene(Scene((Box((0.0, 1.0), (2.0, 0.2, 3.0)),)), 1, torch.device("cpu"), 0.0)
    ahead = wall.height_grid(standing(0.0, 0.0, 90.0), torch.tensor([[1.0, 0.0], [0.0, 0.0]]))
    assert ahead.tolist() == [[1.0, 0.0]]  # a 3 m wall reads as the clip, +1 m


def test_env_observes_the_grid_after_the_rays_and_only_when_asked(tiny_model):
    plain = ReachLocationEnv(2, motion=tiny_model, scene=STAIRS)
    assert "scene_height_grid" not in plain.observation_layout
    env = ReachLocationEnv(2, motion=tiny_model, scene=STAIRS, height_grid=5, height_grid_spacing=0.3)
    layout = env.observation_layout
    assert list(layout)[-2:] == ["scene_rays", "scene_height_grid"]
    start, stop = layout["scene_height_grid"]
    assert stop - start == 25 and stop == env.single_observation_space.shape[0]
    assert env.single_observation_space.shape[0] == plain.single_observation_space.shape[0] + 25
    obs, _ = env.reset(seed=0)
    want = env.scene.height_grid(env.history_world(), grid_offsets(5, 0.3))
    assert torch.equal(obs[:, start:stop], want)
    plain.reset(seed=0)
    assert torch.equal(obs[:, :start], plain.observation())  # the rest of the observation is unchanged
    obs, *_ = env.step(torch.zeros(2, 16))
    assert torch.equal(obs[:, start:stop], env.scene.height_grid(env.history_world(), grid_offsets(5, 0.3)))


@pytest.mark.parametrize("kwargs, message", [
    ({"height_grid": 4}, "height_grid: expected 0 (none) or an odd number of samples per side in [3, 15], got 4"),
    ({"height_grid": 17}, "got 17"),
    ({"height_grid": 5, "height_grid_spacing": 0.0}, "height_grid_spacing: expected metres in (0, 2], got 0.0"),
])
def test_bad_grids_are_one_line(tiny_model, kwargs, message):
    with pytest.raises(ConfigError) as err:
        ReachLocationEnv(1, motion=tiny_model, scene=STAIRS, **kwargs)
    assert message in str(err.value) and "\n" not in str(err.value)
    with pytest.raises(ConfigError, match="height_grid: needs a scene"):
        ReachLocationEnv(1, motion=tiny_model, height_grid=5)


def test_config_and_evaluation_carry_the_grid(tiny_model):
    from latentrl.envs.config import EnvConfig, build
    from latentrl.envs.path import WaypointPath
    from latentrl.evaluation.config import EvalSettings
    from latentrl.evaluation.runner import make_env

    cfg = EnvConfig(num_envs=2, scene="stairs_15", height_grid=7)
    cfg.validate()
    env = build(cfg, "cpu", motion=tiny_model)
    assert env.observation_layout["scene_height_grid"][1] - env.observation_layout["scene_height_grid"][0] == 49
    with pytest.raises(ConfigError, match="height_grid: needs a scene"):
        build(EnvConfig(num_envs=1, height_grid=7), "cpu", motion=tiny_model)
    with pytest.raises(ConfigError, match="height_grid_spacing: expected metres"):
        EnvConfig(scene="stairs_15", height_grid=7, height_grid_spacing=-1).validate()
    settings = EvalSettings(episodes=1, max_steps=1)
    settings.take_training_env(cfg)
    probe = make_env(tiny_model, [WaypointPath(((0.0, 1.0, 0.0),), ("walk",))], 1, settings)
    assert probe.single_observation_space.shape == env.single_observation_space.shape
