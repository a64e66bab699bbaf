"""Envs with a scene: flat envs unchanged, the scene_rays group, scene rewards, collision ends, random obstacles."""

import math

import pytest
import torch

from latentrl.config import load_config
from latentrl.envs.config import EnvConfig, build
from latentrl.envs.reach import ReachLocationEnv
from latentrl.envs.scene import NUM_RAYS, RAY_RANGE_M
from latentrl.errors import ConfigError
from latentrl.scenes import Box, Scene, scene_to_dict
from latentrl.scenes.random import RandomObstacles

WALL = Scene((Box((0.0, 2.0), (4.0, 0.2, 2.0)),))  # 2 m ahead of the start (pelvis at the origin, facing +y)
FAR = Scene((Box((100.0, 100.0), (1.0, 1.0, 1.0)),))


def make(tiny_model, n=3, **kw) -> ReachLocationEnv:
    return ReachLocationEnv(n, motion=tiny_model, **kw)


def actions(n: int, seed: int) -> torch.Tensor:
    return torch.randn(n, 16, generator=torch.Generator().manual_seed(seed))


def test_a_far_scene_leaves_the_flat_env_step_for_step(tiny_model):
    flat, scened = make(tiny_model), make(tiny_model, scene=FAR)
    size = flat.observation_space.shape[1]
    assert scened.observation_space.shape[1] == size + NUM_RAYS
    assert dict(scened.observation_layout) == {**flat.observation_layout, "scene_rays": (size, size + NUM_RAYS)}
    o1, _ = flat.reset(seed=5)
    o2, _ = scened.reset(seed=5)
    assert torch.equal(o1, o2[:, :size]) and torch.equal(o2[:, size:], torch.full((3, NUM_RAYS), RAY_RANGE_M))
    for step in range(12):  # past autoresets (tiny episodes below)
        a = actions(3, step)
        r1 = flat.step(a)
        r2 = scened.step(a)
        assert torch.equal(r1[0], r2[0][:, :size])
        for x, y in zip(r1[1:4], r2[1:4]):
            assert torch.equal(x, y)
        assert all(torch.equal(r1[4][k], r2[4][k]) for k in r1[4] if k.startswith("reward/"))
        assert float(r2[4]["reward/collision"].abs().sum()) == 0.0
    assert "reward/collision" not in r1[4] and flat.scene is None


def test_rays_see_the_wall_ahead(tiny_model):
    env = make(tiny_model, n=2, scene=WALL)
    obs, _ = env.reset(seed=0)
    rays = obs[:, env.observation_layout["scene_rays"][0]:]
    pelvis = env.history_world()[:, -1, 0]
    ahead = rays[:, NUM_RAYS // 2 - 1: NUM_RAYS // 2 + 1]  # the two rays either side of straight ahead
    straight = (1.9 - pelvis[:, 1])[:, None]
    assert torch.all(ahead >= straight - 1e-4) and torch.all(ahead <= straight / math.cos(math.pi / 30) + 1e-3)
    assert torch.allclose(rays[:, 0], torch.full((2,), RAY_RANGE_M))  # right (+x): along the wall, no hit
    assert torch.all(rays <= RAY_RANGE_M)


def test_collision_reward_and_termination(tiny_model):
    around = Scene((Box((0.0, 0.0), (1.0, 1.0, 2.0)),))  # the start stands inside it
    env = make(tiny_model, n=2, scene=around, reward_weights={"collision": 1.0}, terminate_on_collision=True,
               autoreset_mode="Disabled")
    env.reset(seed=0)
    _, reward, terminated, _, infos = env.step(actions(2, 0))
    assert torch.all(infos["reward/collision"] < 0) and torch.all(terminated)
    keep = make(tiny_model, n=2, scene=around, autoreset_mode="Disabled")
    keep.reset(seed=0)
    assert not keep.step(actions(2, 0))[2].any()
    with pytest.raises(ConfigError, match="terminate_on_collision: needs a scene"):
        make(tiny_model, terminate_on_collision=True)


def test_random_obstacles_per_episode(tiny_model):
    spec = RandomObstacles(count=[3, 8], clearance=0.5)
    env = make(tiny_model, n=32, scene=spec)
    env.reset(seed=1)
    s = env.scene.batch
    counts = s.object_counts()
    assert counts.min() >= 3 and counts.max() <= 8 and len(set(counts.tolist())) > 1
    start = env.history_world()[:, -1, 0, :2]
    goal = env.goal_world[:, :2]
    for p in (start, goal):
        gap_box = (s.box_center[..., :2] - p[:, None]).norm(dim=-1) - s.box_half[..., :2].norm(dim=-1)
        gap_cyl = (s.cyl_center[..., :2] - p[:, None]).norm(dim=-1) - s.cyl_radius
        assert torch.all(gap_box[s.box_mask] >= 0.5 - 1e-5) and torch.all(gap_cyl[s.cyl_mask] >= 0.5 - 1e-5)
    before = s.box_center.clone()
    env.reset(seed=1)
    assert torch.equal(env.scene.batch.box_center, before)  # same seed, same obstacles
    env.reset(seed=2, options={"reset_mask": torch.arange(32) == 0})
    changed = (env.scene.batch.box_center != before).any(dim=(1, 2))
    assert changed[0] and not changed[1:].any()


def test_a_goal_on_an_obstacle_drops_it(tiny_model):
    env = make(tiny_model, n=1, scene=RandomObstacles(count=[8, 8]))
    env.reset(seed=0)
    s = env.scene.batch
    k = int(s.box_mask[0].nonzero()[0, 0]) if s.box_mask.any() else None
    if k is None:
        pytest.skip("no box drawn")
    env._goal[0, :2] = s.box_center[0, k, :2]
    env.step(actions(1, 0))
    assert not env.scene.batch.box_mask[0, k]


def test_env_config_scene_from_a_file_a_generator_or_inline(tmp_path, tiny_model):
    import json

    room = tmp_path / "room.json"
    room.write_text(json.dumps(scene_to_dict(WALL)))
    f = tmp_path / "c.yaml"
    f.write_text(f"task: reach\nnum_envs: 2\nscene: {room}\nterminate_on_collision: true\n")
    cfg = load_config(EnvConfig, f)
    env = build(cfg, "cpu", motion=tiny_model)
    assert env.scene.spec == WALL and env.terminate_on_collision
    f.write_text("num_envs: 2\nscene: {random_obstacles: {count: [2, 4], size: [0.2, 0.5]}}\n")
    env = build(load_config(EnvConfig, f), "cpu", motion=tiny_model)
    assert env.scene.spec == RandomObstacles(count=[2, 4], size=[0.2, 0.5])
    assert build(EnvConfig(num_envs=1), "cpu", motion=tiny_model).scene is None


@pytest.mark.parametrize(("text", "message"), [
    ("scene: nowhere.json\n", "c.yaml: scene: scene file not found: nowhere.json"),
    ("scene: {random_obstacles: {count: [5, 2]}}\n",
     "c.yaml: scene: random_obstacles.count: expected [min, max] integers with 0 <= min <= max <= 64, got [5, 2]"),
    ("scene: {random_obstacles: {cout: [1, 2]}}\n",
     "c.yaml: scene: random_obstacles.cout: unknown setting (did you mean 'count'?); expected count, size, height, "
     "distance, angle_deg, cylinder_share, clearance"),
    ("scene: {random_obstacles: {clearance: -1}}\n",
     "c.yaml: scene: random_obstacles.clearance: expected a number in [0, 100], got -1"),
    ("scene: {format: latentrl.scene/1, objects: [{type: box, center: [0, 0], size: [1, 1, 0]}]}\n",
     "c.yaml: scene: env.scene: objects[0].size[2]: expected a number > 0, got 0"),
    ("scene: 3\n", "c.yaml: scene: expected a scene file, a latentrl.scene/1 object, {random_obstacles: {...}}, "
                   "{random_mazes: {...}} or {random_stairs: {...}}, got 3"),
    ("terminate_on_collision: true\n", "c.yaml: terminate_on_collision: needs a scene (env.scene)"),
    ("task: reach\nscene: {random_mazes: {}}\n",
     "c.yaml: scene: random_mazes: the env walks each course's route, which only the path task does (got task "
     "'reach')"),
    ("task: joystick\nscene: {random_stairs: {}}\n",
     "c.yaml: scene: random_stairs: the env walks each course's route, which only the path task does (got task "
     "'joystick')"),
    ("task: path\npath: {paths: dart_walk_long}\nscene: {random_mazes: {}}\n",
     "c.yaml: path.paths: random_mazes brings its own paths (each course's route); leave path.paths unset"),
    ("task: path\nscene: {random_stairs: {riser: [0.1, 0.5]}}\n",
     "c.yaml: scene: random_stairs.riser: expected [min, max] numbers with 0.02 <= min <= max <= 0.4, got [0.1, 0.5]"),
    ("task: path\nscene: {random_stairs: {step: [2, 3]}}\n",
     "c.yaml: scene: random_stairs.step: unknown setting (did you mean 'steps'?); expected count, riser, steps, "
     "tread, width, landing, turn, seed"),
    ("task: path\nscene: {random_stairs: {turn: 2}}\n",
     "c.yaml: scene: random_stairs.turn: expected a number in [0, 1], got 2"),
    ("task: path\nscene: {random_mazes: {cel: [1, 2]}}\n",
     "c.yaml: scene: random_mazes.cel: unknown setting (did you mean 'cell'?); expected count, cols, rows, cell, "
     "wall, seed"),
    ("task: path\nscene: {random_mazes: {cell: [1.0, 2.0]}}\n",
     "c.yaml: scene: random_mazes.cell: expected [min, max] numbers with 1.4 <= min <= max <= 10, got [1.0, 2.0]"),
    ("task: path\nscene: {random_mazes: {count: 0}}\n",
     "c.yaml: scene: random_mazes.count: expected an integer in [1, 4096], got 0"),
    ("task: path\nscene: {random_mazes: {}, random_obstacles: {}}\n",
     "c.yaml: scene: random_obstacles stands alone"),
])
def test_bad_env_scenes_are_one_line(tmp_path, text, message):
    f = tmp_path / "c.yaml"
    f.write_text(text)
    with pytest.raises(ConfigError) as info:
        load_config(EnvConfig, f)
    assert str(info.value).replace(str(tmp_path) + "/", "").startswith(message)
    assert "\n" not in str(info.value)
