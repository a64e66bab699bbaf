"""Random staircases for training: a seeded pool within its ranges, a staircase, its terrain and its route per path
episode, and the maze and stairs configs trained and judged on their shipped suites by default (tiny model)."""

import json
from pathlib import Path

import pytest
import torch

from latentrl.envs.path import FollowPathEnv
from latentrl.scenes import Box, SceneBatch, Stairs
from latentrl.scenes.courses import COURSES, POOLS, SUITES, RandomMazes, RandomStairs


def test_the_pool_is_seeded_and_every_staircase_keeps_its_ranges():
    spec = RandomStairs(count=40, riser=[0.12, 0.18], steps=[2, 4], tread=[0.3, 0.32], width=[1.3, 1.5],
                        landing=[1.1, 1.3], turn=0.5, seed=5)
    pool = spec.courses()
    assert [c.scene for c in pool] == [c.scene for c in spec.courses()]  # the same settings, the same pool
    assert [c.scene for c in pool] != [c.scene for c in RandomStairs(count=40, seed=6).courses()]
    turned = 0
    for c in pool:
        up, landing, down = c.scene.objects
        assert isinstance(up, Stairs) and isinstance(landing, Box) and isinstance(down, Stairs)
        assert 0.12 <= up.riser <= 0.18 and 2 <= up.count <= 4 and 0.3 <= up.tread <= 0.32
        assert 1.3 <= up.width <= 1.5 and (up.riser, up.count, up.tread) == (down.riser, down.count, down.tread)
        assert landing.size[2] == pytest.approx(up.riser * up.count)  # the landing is the top step's height
        turned += down.direction_deg == 180.0
        # the route climbs the flight, crosses the landing, goes down and leaves on the floor
        batch = SceneBatch.from_scenes([c.scene])
        heights = batch.height(torch.tensor([[[x, y] for x, y in c.waypoints]]))[0]
        assert float(heights[1]) == pytest.approx(up.riser * up.count) and float(heights[-1]) == 0.0
    assert 0 < turned < len(pool)  # both kinds at turn 0.5
    assert POOLS == {"random_mazes": RandomMazes, "random_stairs": RandomStairs}
    assert {pool.suite for pool in POOLS.values()} == {"maze", "stairs"} <= set(SUITES)
    shipped = {COURSES[n]().scene for n in COURSES if n.startswith("stairs")}
    assert not shipped & {c.scene for c in RandomStairs(count=64).courses()}


def test_each_path_episode_walks_the_route_of_the_staircase_it_drew(tiny_model):
    spec = {"count": 5, "steps": [3, 3], "turn": 0.0}
    env = FollowPathEnv(8, motion=tiny_model, scene={"random_stairs": spec})
    pool = RandomStairs(**spec).courses()
    env.reset(seed=0)
    drawn = set()
    for i in range(env.num_envs):
        k = next(k for k, c in enumerate(pool) if c.scene.objects == env.scene.scene_of(i).objects)
        route = torch.tensor([(x, y, 0.0) for x, y in pool[k].waypoints])
        assert int(env._wp_len[i]) == len(route) and torch.allclose(env._wp[i, : len(route)], route)
        drawn.add(k)
    assert len(drawn) > 1
    obs, *_ = env.step(torch.zeros(8, 16))
    assert obs.shape[1] == env.single_observation_space.shape[0] and torch.isfinite(obs).all()
    # each env's terrain is its own staircase: the landing under the route's second point, the floor at the start
    for i in range(env.num_envs):
        top = env.scene.row(i).height(env._wp[i: i + 1, 1:2, :2])[0, 0]
        assert float(top) == pytest.approx(env.scene.scene_of(i).objects[1].size[2])
        assert float(env.scene.row(i).height(torch.zeros(1, 1, 2))[0, 0]) == 0.0


@pytest.mark.parametrize(("config", "pool", "suite", "metrics"), [
    ("path_maze_default", "random_mazes", "maze", {"collision", "scene_penetration_max_cm"}),
    ("path_stairs_default", "random_stairs", "stairs", {"penetration_mm", "floating_mm", "collision"}),
])
def test_a_course_pool_config_trains_and_evaluates_on_its_shipped_suite_by_default(eval_files, tmp_path, capsys,
                                                                                   config, pool, suite, metrics):
    from latentrl.app.cli import main

    path = Path(__file__).resolve().parents[2] / "configs" / "policies" / f"{config}.yaml"
    sets = [f"env.motion={eval_files['motion']}", "env.num_envs=4", "env.max_episode_steps=4", "ppo.num_steps=4",
            "ppo.total_steps=16", "ppo.num_minibatches=2", "ppo.update_epochs=1", "ppo.eval_every=0",
            "ppo.init_from=null", "policy.latent_dim=32", f"env.scene.{pool}.count=4", "threads=1"]
    run = tmp_path / "run"
    assert main(["train", str(path), "--run-dir", str(run), "--no-progress",
                 *[x for s in sets for x in ("--set", s)]]) == 0, capsys.readouterr().err
    out = tmp_path / "ev"
    assert main(["eval", str(run / "final.pt"), "--episodes", "1", "--max-steps", "2", "--device", "cpu",
                 "--out", str(out), "--no-progress"]) == 0, capsys.readouterr().err
    report = json.loads((out / "report.json").read_text())
    assert list(report["suites"]) == [suite]
    assert metrics <= set(report["overall"]["metrics"])
