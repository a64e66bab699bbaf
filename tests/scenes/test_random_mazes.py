"""Random mazes for training: a seeded pool, a maze and its route per path episode, one-line errors, eval of a
maze-trained policy on a suite without scenes (tiny model)."""

import pytest
import torch

from latentrl.config import load_config
from latentrl.envs.config import EnvConfig, build
from latentrl.envs.path import FollowPathEnv, WaypointPath
from latentrl.envs.reach import ReachLocationEnv
from latentrl.errors import ConfigError
from latentrl.evaluation.config import EvalSettings
from latentrl.evaluation.runner import make_env
from latentrl.scenes import Box, SceneBatch
from latentrl.scenes.courses import COURSES, RandomMazes


def test_the_pool_is_seeded_sized_as_asked_and_leaves_the_shipped_mazes_out():
    spec = RandomMazes(count=24, cols=[3, 4], rows=[2, 5], cell=[1.4, 1.6], seed=3)
    pool = spec.courses()
    assert [c.waypoints for c in pool] == [c.waypoints for c in spec.courses()]  # the same settings, the same pool
    assert [c.waypoints for c in pool] != [c.waypoints for c in RandomMazes(count=24, seed=4).courses()]
    shipped = {COURSES[n]().waypoints for n in COURSES if n.startswith("maze")}
    assert not shipped & {c.waypoints for c in RandomMazes(count=64).courses()}
    for c in pool:
        xs = sorted({round(x, 6) for x, _ in c.waypoints} | {0.0})
        ys = sorted({round(y, 6) for _, y in c.waypoints} | {0.0})
        cell = max(abs(x1 - x0) + abs(y1 - y0) for (x0, y0), (x1, y1) in
                   zip([(0.0, 0.0), *c.waypoints[:-1]], c.waypoints))
        assert 1.4 - 1e-6 <= cell <= 1.6 + 1e-6
        assert len(xs) <= 4 and len(ys) <= 5  # at most cols x rows cell centres
        assert all(isinstance(o, Box) for o in c.scene.objects)
        # every waypoint is a cell centre, (cell - wall) / 2 >= 0.6 m from every wall
        wps = torch.tensor([[(x, y, 0.5) for x, y in c.waypoints]])
        assert float(SceneBatch.from_scenes([c.scene]).sdf(wps).min()) >= 0.6 - 1e-6


def test_each_path_episode_walks_the_route_of_the_maze_it_drew(tiny_model):
    spec = RandomMazes(count=6, cols=[2, 4], rows=[2, 4], cell=[1.5, 2.0])
    env = FollowPathEnv(16, motion=tiny_model, scene={"random_mazes": {"count": 6, "cols": [2, 4], "rows": [2, 4],
                                                                       "cell": [1.5, 2.0]}})
    pool = spec.courses()
    env.reset(seed=0)

    def check() -> list[int]:
        drawn = []
        for i in range(env.num_envs):
            k = next(k for k, c in enumerate(pool) if c.scene.objects == env.scene.scene_of(i).objects)
            route = torch.tensor([(x, y, 0.0) for x, y in pool[k].waypoints])
            assert int(env._wp_len[i]) == len(route)
            assert torch.allclose(env._wp[i, : len(route)], route)
            row = SceneBatch.from_scenes([pool[k].scene])
            mine = env.scene.row(i)
            n = int(row.box_mask.sum())
            assert torch.equal(mine.box_mask[0, :n], row.box_mask[0]) and not mine.box_mask[0, n:].any()
            assert torch.allclose(mine.box_center[0, :n], row.box_center[0])
            drawn.append(k)
        return drawn

    first = check()
    assert len(set(first)) > 1  # envs draw different mazes
    assert torch.allclose(env.goal_world, env._wp[:, 0])
    env.reset(options={"reset_mask": torch.arange(16) < 8})
    second = check()
    assert second[8:] == first[8:] and second[:8] != first[:8]
    obs, *_ = env.step(torch.zeros(16, 16))
    assert obs.shape[1] == env.single_observation_space.shape[0] and torch.isfinite(obs).all()


def test_rays_see_the_first_wall_of_the_drawn_maze(tiny_model):
    env = FollowPathEnv(4, motion=tiny_model, scene={"random_mazes": {"count": 8}})
    env.reset(seed=1)
    rays = env.scene.rays(env.history_world())
    assert (rays < 4.0).any(dim=1).all()  # every start cell has a wall within the rays' range


def test_random_mazes_need_the_path_task_and_no_paths_of_its_own(tiny_model, tmp_path):
    with pytest.raises(ConfigError, match="random_mazes: the env walks each course's route, which only the path task"):
        ReachLocationEnv(2, motion=tiny_model, scene={"random_mazes": {"count": 2}})
    with pytest.raises(ConfigError, match="paths: random_mazes brings its own paths"):
        FollowPathEnv(2, motion=tiny_model, paths=[WaypointPath(((0.0, 1.0, 0.0),), ("walk",))],
                      scene={"random_mazes": {"count": 2}})
    f = tmp_path / "c.yaml"
    f.write_text("task: path\nnum_envs: 2\nscene: {random_mazes: {count: 3, cell: [1.5, 1.5]}}\n")
    env = build(load_config(EnvConfig, f), "cpu", motion=tiny_model)
    assert env.scene.spec == RandomMazes(count=3, cell=[1.5, 1.5]) and len(env.scene.courses) == 3


def test_eval_of_a_maze_policy_runs_a_suite_of_plain_paths_on_the_open_floor(tiny_model):
    settings = EvalSettings(episodes=1, max_steps=2)
    settings.scene = {"random_mazes": {"count": 2}}
    path = WaypointPath(((0.0, 3.0, 0.0),), ("walk",))
    env = make_env(tiny_model, [path], 2, settings)
    assert env.scene is not None and env.observe_scene and env.scene.spec.objects == ()
    env.reset(seed=0)
    assert torch.allclose(env.goal_world, torch.tensor([[0.0, 3.0, 0.0]] * 2))
