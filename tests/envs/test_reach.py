"""ReachLocation: DART's goal observation and goal sampling, with known answers."""

import math

import pytest
import torch

from latentrl.envs.goal import goal_features
from tests.envs.conftest import actions
from tests.helpers import rest_joints


def body_facing(yaw: float, at=(0.0, 0.0)) -> torch.Tensor:
    """(1, 22, 3) rest body turned by ``yaw`` (radians, counter-clockwise from facing +y)."""
    c, s = math.cos(yaw), math.sin(yaw)
    rot = torch.tensor([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return (rest_joints() @ rot.T + torch.tensor([at[0], at[1], 0.0]))[None]


IDENTITY = torch.eye(3)[None]


@pytest.mark.parametrize(
    "goal,expected_dir,expected_dist",
    [
        ((0.0, 3.0), (0.0, 1.0), 3.0),  # straight ahead
        ((-3.0, 3.0), (-math.sqrt(0.5), math.sqrt(0.5)), math.hypot(3, 3)),  # 45 deg left: inside the cone
        ((-3.0, 0.0), (-math.sin(math.radians(60)), 0.5), 3.0),  # 90 deg left: clipped to 60 deg
        ((3.0, -0.1), (math.sin(math.radians(60)), 0.5), math.hypot(3, 0.1)),  # right and behind: clipped right
        ((0.0, -3.0), (0.0, 1.0), 3.0),  # exactly behind: sign 0, straight ahead (DART)
        ((0.0, 9.0), (0.0, 1.0), 5.0),  # distance clipped at 5 m
    ],
)
def test_goal_features_known_answers(goal, expected_dir, expected_dist):
    out = goal_features(body_facing(0.0), IDENTITY, torch.tensor([[goal[0], goal[1], 0.0]]))
    torch.testing.assert_close(out[0, :3], torch.tensor([*expected_dir, 0.0]), atol=1e-5, rtol=0)
    assert out[0, 3].item() == pytest.approx(expected_dist, abs=1e-5)


def test_goal_direction_is_expressed_in_the_history_frame_zero():
    # the last frame faces +x (yaw -90 deg); the canonical frame 0 is turned by +30 deg
    body = body_facing(-math.pi / 2, at=(1.0, 2.0))
    a = math.radians(30)
    frame0 = torch.tensor([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])[None]
    out = goal_features(body, frame0, torch.tensor([[5.0, 2.0, 0.0]]))  # straight ahead, 4 m
    world_dir = torch.tensor([1.0, 0.0, 0.0])
    torch.testing.assert_close(out[0, :3], frame0[0].T @ world_dir, atol=1e-5, rtol=0)
    assert out[0, 3].item() == pytest.approx(4.0, abs=1e-5)


def test_goals_are_sampled_in_the_cone_and_distance_range(make_reach):
    env = make_reach(64, goal_angle_deg=60.0, goal_distance=(0.5, 5.0))
    env.reset(seed=0)
    last = env.history_world()[:, -1]
    pelvis = last[:, 0]
    right = last[:, 2] - last[:, 1]
    forward = torch.stack((-right[:, 1], right[:, 0]), -1)  # z x right, in xy
    to_goal = env.goal_world[:, :2] - pelvis[:, :2]
    dist = to_goal.norm(dim=1)
    assert dist.min() >= 0.5 - 1e-5 and dist.max() <= 5.0 + 1e-5
    angle = torch.atan2(forward[:, 0] * to_goal[:, 1] - forward[:, 1] * to_goal[:, 0], (forward * to_goal).sum(1))
    assert angle.abs().max() <= math.radians(60) + 1e-4
    assert (angle > 0.3).any() and (angle < -0.3).any()  # both sides
    assert torch.equal(env.goal_world[:, 2], torch.zeros(64))


def test_text_is_kept_when_a_goal_is_reached(make_reach):
    env = make_reach(4, texts=("walk", "run", "hop on left leg"), success_threshold=1e3)
    env.reset(seed=2)
    texts = env._text_idx.clone()
    for k in range(2):
        env.step(actions(4, k))
    assert torch.equal(env._text_idx, texts)


def test_registered_defaults_match_dart(make_reach):
    env = make_reach(1)
    assert env.max_episode_steps == 32 and env.success_threshold == 0.3 and env.terminate_distance == 100.0
    assert env.guidance_scale == 5.0 and env.action_bound == 4.0
    assert env.goal_distance == (0.5, 5.0) and env.goal_angle_deg == 60.0
