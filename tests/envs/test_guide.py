"""The route guide (latentrl.envs.guide): the policy's goal moved onto the route, only where an object is in the way."""

from __future__ import annotations

import pytest
import torch

from latentrl.envs.path import FollowPathEnv, WaypointPath
from latentrl.envs.reach import ReachLocationEnv
from latentrl.envs.reach_joint import ReachJointEnv
from latentrl.errors import ConfigError
from latentrl.motion.skeleton import PELVIS
from latentrl.scenes.route import RouteMap, RouteSettings
from latentrl.scenes.scene import Box, Scene

GOAL = WaypointPath(((0.0, 4.0, 0.0),), ("walk",))
WALL = Scene([Box(center=(0.0, 2.0), size=(2.0, 0.2, 1.5))])
FAR = Scene([Box(center=(6.0, 0.0), size=(0.5, 0.5, 1.0))])


def env_with(model, scene, route=None, n: int = 2) -> FollowPathEnv:
    env = FollowPathEnv(n, motion=model, paths=[GOAL], path_assignment="by_env", scene=scene, route=route,
                        autoreset_mode="Disabled")
    env.reset(seed=0)
    return env


def test_where_nothing_is_in_the_way_the_observation_is_the_unguided_one_bit_for_bit(tiny_model):
    plain, guided = env_with(tiny_model, FAR), env_with(tiny_model, FAR, route=0.5)
    actions = torch.randn(4, 2, tiny_model.latent_dim, generator=torch.Generator().manual_seed(0))
    assert torch.equal(plain.observation(), guided.observation())
    for a in actions:
        assert torch.equal(plain.step(a)[0], guided.step(a)[0])


def test_a_wall_in_the_way_turns_the_seen_goal_toward_its_end_at_the_routes_length(tiny_model):
    plain, guided = env_with(tiny_model, WALL), env_with(tiny_model, WALL, route=0.3)
    obs, seen = plain.observation(), guided.observation()
    fields = guided.observation_fields
    a, b, dist = fields["goal_dir"][0], fields["goal_dist"][1], fields["goal_dist"][0]
    assert torch.equal(seen[:, b:], obs[:, b:])  # text, motion and rays untouched
    assert not torch.allclose(seen[:, a:b], obs[:, a:b])
    pelvis = guided.history_world()[:, -1, PELVIS, :2].double()
    route = RouteMap(guided.scene.row(0), pelvis[0].numpy(), (0.0, 4.0), RouteSettings(clearance=0.3))
    point, left = route.carrot(pelvis[0].numpy())
    assert abs(point[0]) > 0.3 and route.in_sight(pelvis[0].numpy(), point)  # beside the wall, in clear sight
    away = torch.from_numpy(point) - pelvis[0]
    goal = torch.zeros(2, 3)
    goal[:, :2] = (pelvis[0] + away / away.norm() * left).float()
    assert torch.allclose(seen[:, a:b], guided.goal_features_of(goal), atol=1e-5)
    assert float(seen[0, dist]) == pytest.approx(min(left, guided.obs_goal_dist_clip), abs=1e-4)
    assert float(obs[0, dist]) < float(seen[0, dist])  # the route is longer than the line


def test_routes_are_planned_once_per_goal_and_scene(tiny_model):
    env = env_with(tiny_model, WALL, route=0.5)
    for _ in range(3):
        env.step(torch.zeros(env.num_envs, env.motion.latent_dim))
    assert env.guide.plans == env.num_envs  # one per env, not one per step
    env.scene.replace(Scene([Box(center=(0.0, 2.5), size=(2.0, 0.2, 1.5))]))
    env.observation()
    assert env.guide.plans == 2 * env.num_envs


def test_a_reach_env_with_random_obstacles_is_guided_and_steps(tiny_model):
    env = ReachLocationEnv(4, motion=tiny_model, scene={"random_obstacles": {}}, route=0.5)
    obs, _ = env.reset(seed=0)
    for _ in range(3):
        obs = env.step(torch.zeros(4, tiny_model.latent_dim))[0]
    assert torch.isfinite(obs).all() and env.guide.plans >= 4


def joystick_with(model, scene, route=None, heading_deg: float = 0.0):
    from latentrl.envs.joystick import CommandTimeline, JoystickEnv

    timeline = CommandTimeline("walk", ((0.0, heading_deg, 1.2),), 20.0)
    env = JoystickEnv(1, motion=model, commands=[timeline], command_assignment="by_env", scene=scene, route=route,
                      autoreset_mode="Disabled")
    env.reset(seed=0)
    return env


def test_a_joystick_commanded_into_a_wall_is_turned_toward_its_end_and_left_alone_where_the_way_is_clear(
        tiny_model):
    """The route leads to the point 3 m along the command; the command's direction (not its speed) turns toward the
    route's point in clear sight; with nothing in the way the observation is the joystick's own, step after step."""
    from latentrl.envs.joystick import ROUTE_AHEAD_M, command_observation

    plain, guided = joystick_with(tiny_model, FAR), joystick_with(tiny_model, FAR, route=0.5)
    for a in torch.randn(3, 1, tiny_model.latent_dim, generator=torch.Generator().manual_seed(0)):
        assert torch.equal(plain.observation(), guided.observation())
        plain.step(a), guided.step(a)
    assert guided.guide.plans == 0  # nothing in the way: no route planned, although the target moves every step
    plain, guided = joystick_with(tiny_model, WALL), joystick_with(tiny_model, WALL, route=0.5)
    obs, seen = plain.observation(), guided.observation()
    a, b = guided.observation_fields["command_dir"]
    speed = guided.observation_fields["command_speed"]
    assert torch.equal(seen[:, b:], obs[:, b:]) and float(seen[0, speed[0]]) == pytest.approx(1.2)
    history = guided.history_world()
    pelvis = history[:, -1, PELVIS, :2].double()
    target = guided.route_target(history)
    assert float((target[0, :2].double() - pelvis[0]).norm()) == pytest.approx(ROUTE_AHEAD_M[0], abs=1e-4)
    assert float(target[0, 1] - pelvis[0, 1]) == pytest.approx(ROUTE_AHEAD_M[0], abs=1e-4)  # heading 0: +y
    route = RouteMap(guided.scene.row(0), pelvis[0].numpy(), target[0, :2].double().numpy(), RouteSettings(0.5))
    point, _ = route.carrot(pelvis[0].numpy())
    assert abs(point[0]) > 0.5  # beside the wall
    away = torch.from_numpy(point).float() - pelvis[0].float()
    expected = command_observation(history, torch.atan2(away[1:], away[:1]), torch.tensor([1.2]))[:, :2]
    assert torch.allclose(seen[:, a:b], expected, atol=1e-4) and not torch.allclose(seen[:, a:b], obs[:, a:b])


def test_a_joystick_route_leads_past_an_object_the_command_points_into_not_into_it(tiny_model):
    """The target is the nearest point 3-6 m along the command that keeps the clearance: behind a deep block, not in
    it; with no such point, 3 m ahead."""
    deep = Scene([Box(center=(0.0, 3.5), size=(2.0, 2.0, 1.5))])  # y from 2.5 to 4.5
    env = joystick_with(tiny_model, deep, route=0.5)
    history = env.history_world()
    pelvis = history[0, -1, PELVIS, :2]
    ahead = float(env.route_target(history)[0, 1] - pelvis[1])
    assert ahead == pytest.approx(5.0, abs=0.26) and ahead >= 4.5 + 0.5 - pelvis[1] - 1e-3
    wall = Scene([Box(center=(0.0, 5.0), size=(2.0, 8.0, 1.5))])  # every point 3-6 m ahead is inside
    env = joystick_with(tiny_model, wall, route=0.5)
    history = env.history_world()
    assert float(env.route_target(history)[0, 1] - history[0, -1, PELVIS, 1]) == pytest.approx(3.0, abs=1e-4)


def test_a_moving_joystick_target_is_planned_anew_only_after_it_moved_a_cell(tiny_model):
    """The target 3 m ahead moves with every turn of the command: a few centimetres keep the route, a new cell plans."""
    env = joystick_with(tiny_model, WALL, route=0.5)
    env.observation()
    assert env.guide.plans == 1
    env._heading += 0.01  # the target moves 3 cm, inside its 0.5 m cell
    env.observation()
    assert env.guide.plans == 1
    env._heading += 0.5  # 1.4 m
    env.observation()
    assert env.guide.plans == 2


@pytest.mark.parametrize("make, message", [
    (lambda m: ReachJointEnv(1, motion=m, scene=WALL, route=0.5),
     "^route: the ReachJointEnv task has no place on the floor to guide to"),
    (lambda m: ReachLocationEnv(1, motion=m, route=0.5), "^route: needs a scene"),
    (lambda m: ReachLocationEnv(1, motion=m, scene=WALL, route=3.0),
     r"^route clearance: expected metres in \[0.0, 2.0\]"),
])
def test_bad_routes_are_refused_in_one_line(tiny_model, make, message):
    with pytest.raises(ConfigError, match=message) as err:
        make(tiny_model)
    assert "\n" not in str(err.value)


def test_play_heads_a_reach_or_joystick_policy_along_routes_when_asked_or_trained_so(tiny_model):
    pytest.importorskip("viser")
    from latentrl.viewer.live import play_env

    plain = {"config": {"env": {"texts": ["walk"]}}}
    stored = {"config": {"env": {"texts": ["walk"], "scene": {"random_obstacles": {}}, "route": 0.4}}}
    assert play_env(plain, tiny_model, None, "cpu", "reach", WALL).guide is None
    assert play_env(stored, tiny_model, None, "cpu", "reach", WALL).route.clearance == 0.4
    assert play_env(stored, tiny_model, None, "cpu", "reach", WALL, route=0.0).guide is None  # --route 0: off
    envs = [play_env(plain, tiny_model, None, "cpu", "reach", WALL, route=r) for r in (None, 0.5)]
    for env in envs:
        env.reset(seed=0)
        env.set_goal((0.0, 4.0))  # a click behind the wall
    fields = envs[1].observation_fields
    a, b = fields["goal_dir"][0], fields["goal_dist"][1]
    straight, routed = (env.observation() for env in envs)
    assert not torch.allclose(straight[:, a:b], routed[:, a:b])
    assert torch.equal(straight[:, b:], routed[:, b:])
    joystick = play_env(plain, tiny_model, None, "cpu", "joystick", WALL, route=0.5)  # steered by the keys
    joystick.reset(seed=0)
    a, b = joystick.observation_fields["command_dir"]
    turned = joystick.observation()[0, a:b]
    assert joystick.guide is not None and float(turned[0]) < 0.99  # the wall ahead turns the command aside
