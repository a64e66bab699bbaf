"""FollowPath: DART's path files, parser errors, waypoint progression and random paths."""

import json
import math
from pathlib import Path

import pytest
import torch

from latentrl.envs.path import FollowPathEnv, WaypointPath, load_paths
from latentrl.errors import DataError
from tests.envs.conftest import actions

PATHS = Path(__file__).resolve().parents[2] / "tasks" / "paths"


@pytest.mark.parametrize(
    "name,count,text",
    [
        ("dart_walk_long", 5, "walk"),
        ("dart_run_long", 5, "run"),
        ("dart_hop_long", 5, "hop on left leg"),
        ("dart_demo_walk", 1, "walk"),
        ("dart_random", 3, "walk"),
    ],
)
def test_dart_suites_load(name, count, text):
    paths = load_paths(PATHS / f"{name}.json")
    assert len(paths) == count and paths[0].texts[0] == text
    assert all(len(p.waypoints) == len(p.texts) for p in paths)


def test_walk_suite_first_path_is_straight_to_twenty_metres():
    first = load_paths(PATHS / "dart_walk_long.json")[0]
    assert first.waypoints == tuple((0.0, 4.0 * (k + 1), 0.0) for k in range(5))


def write(tmp_path, data) -> Path:
    f = tmp_path / "paths.json"
    f.write_text(data if isinstance(data, str) else json.dumps(data))
    return f


GOOD = {"goal_location": [[0, 1, 0], [1, 2, 0]], "goal_text": ["walk", "run"]}


@pytest.mark.parametrize(
    "data,match",
    [
        ({"goal_location": []}, r"paths.json: expected a list of paths"),
        ([], r"holds no paths"),
        ([GOOD, "oops"], r"path 1: expected an object"),
        ([{"goal_location": [[0, 1, 0]]}], r"path 0: missing field 'goal_text'"),
        ([{**GOOD, "goal_txt": []}], r"path 0: unknown field 'goal_txt' \(did you mean 'goal_text'\?\)"),
        (
            [GOOD, {"goal_location": [[0, 1, 0], [1, 2]], "goal_text": ["a", "b"]}],
            r"path 1, waypoint 1: field 'goal_location' must be \[x, y, z\] finite numbers within .* m, got \[1, 2\]",
        ),
        ([{"goal_location": [[0, "x", 0]], "goal_text": ["a"]}], r"path 0, waypoint 0: field 'goal_location'"),
        (
            [{"goal_location": [[0, 1, 0]], "goal_text": [3]}],
            r"path 0, waypoint 0: field 'goal_text' must be a non-empty",
        ),
        ([{"goal_location": [[0, 1, 0]], "goal_text": ["a", "b"]}], r"path 0: field 'goal_text' has 2 entries for 1"),
        ([{"goal_location": [], "goal_text": []}], r"path 0: field 'goal_location' must be a non-empty list"),
        ("[{]", r"invalid JSON: .*line 1"),
    ],
)
def test_malformed_path_files_name_path_waypoint_and_field(tmp_path, data, match):
    with pytest.raises(DataError, match=match):
        load_paths(write(tmp_path, data))


def test_missing_path_file(tmp_path):
    with pytest.raises(DataError, match="path file not found"):
        load_paths(tmp_path / "nope.json")


def path_env(model, paths, **kwargs) -> FollowPathEnv:
    return FollowPathEnv(kwargs.pop("num_envs", 2), motion=model, paths=paths, **kwargs)


def test_waypoints_advance_switch_text_and_finish(tiny_model):
    path = WaypointPath(((0.0, 1.0, 0.0), (1.0, 2.0, 0.0), (2.0, 2.0, 0.0)), ("walk", "run", "hop on left leg"))
    env = path_env(tiny_model, [path], success_threshold=1e3, max_episode_steps=10)  # every step reaches one
    obs, _ = env.reset(seed=0)
    text = slice(*env.observation_layout["text"])
    emb = {t: tiny_model.encode_text([t])[0] for t in path.texts}
    assert torch.equal(obs[0, text], emb["walk"])
    obs, _, term, _, infos = env.step(actions(2, 0))
    assert infos["waypoint_reached"].all() and infos["waypoint_index"].tolist() == [1, 1]
    assert not term.any() and not infos["is_success"].any() and torch.equal(obs[0, text], emb["run"])
    torch.testing.assert_close(env.goal_world[0], torch.tensor([1.0, 2.0, 0.0]))
    obs, _, term, _, infos = env.step(actions(2, 1))
    assert torch.equal(obs[1, text], emb["hop on left leg"]) and not term.any()
    obs, _, term, _, infos = env.step(actions(2, 2))
    assert term.all() and infos["is_success"].all() and infos["episode"]["goals"].tolist() == [3, 3]
    assert infos["reward/success"].tolist() == [1.0, 1.0]
    assert env.waypoint_index.tolist() == [0, 0] and torch.equal(obs[0, text], emb["walk"])  # autoreset


def test_observe_next_adds_the_following_waypoint(tiny_model):
    paths = load_paths(PATHS / "dart_demo_walk.json")
    env = path_env(tiny_model, paths, num_envs=1, observe_next=True)
    assert env.observation_layout["goal"] == (0, 8)
    assert list(env.observation_fields)[:4] == ["goal_dir", "goal_dist", "next_goal_dir", "next_goal_dist"]
    obs, _ = env.reset(seed=0)
    pelvis = env.history_world()[:, -1, 0]
    torch.testing.assert_close(obs[0, 3], (torch.tensor([0.0, 4.0]) - pelvis[0, :2]).norm())
    torch.testing.assert_close(obs[0, 7], (torch.tensor([4.0, 4.0]) - pelvis[0, :2]).norm().clamp(max=5.0))


@pytest.mark.parametrize("mode", ["repeat", "extend"])
def test_next_at_last_repeats_or_extends_the_last_segment(tiny_model, mode):
    """At the last waypoint next_goal shows it again (repeat) or the last segment continued (extend); before
    the last, both show the following waypoint."""
    paths = [WaypointPath(((0.0, 3.0, 0.0), (4.0, 3.0, 0.0)), ("walk", "walk")),
             WaypointPath(((0.0, 2.0, 0.0),), ("walk",))]
    env = path_env(tiny_model, paths, num_envs=2, path_assignment="by_env", observe_next=True, next_at_last=mode)
    env.reset(seed=0)
    start = env.history_world()[1, -1, 0]
    torch.testing.assert_close(env._waypoint(1)[0], torch.tensor([4.0, 3.0, 0.0]))  # not yet the last
    beyond = {"repeat": torch.tensor([0.0, 2.0, 0.0]),
              "extend": torch.tensor([2 * 0.0 - start[0], 2 * 2.0 - start[1], 0.0])}[mode]
    torch.testing.assert_close(env._waypoint(1)[1], beyond)  # a one-waypoint path extends the start->goal line
    env._wp_index[0] = 1  # env 0 now heads for its last waypoint
    expected = {"repeat": torch.tensor([4.0, 3.0, 0.0]), "extend": torch.tensor([8.0, 3.0, 0.0])}[mode]
    torch.testing.assert_close(env._waypoint(1)[0], expected)
    torch.testing.assert_close(env._waypoint()[0], torch.tensor([4.0, 3.0, 0.0]))


def test_next_at_last_rejects_unknown_modes(tiny_model):
    with pytest.raises(Exception, match="next_at_last"):
        path_env(tiny_model, None, num_envs=1, observe_next=True, next_at_last="loop")


def test_by_env_assignment_and_texts_from_files(tiny_model):
    paths = load_paths(PATHS / "dart_random.json")
    env = path_env(tiny_model, PATHS / "dart_random.json", num_envs=4, path_assignment="by_env")
    env.reset(seed=0)
    assert set(env.texts) == {"walk", "run", "hop on left leg"}
    for i in range(4):
        p = paths[i % 3]
        assert torch.equal(env.goal_world[i], torch.tensor(p.waypoints[0]))
        assert env.texts[env._text_idx[i]] == p.texts[0]


def test_random_paths_are_smooth_and_seeded(tiny_model):
    kw = {
        "num_envs": 8,
        "random_waypoints": 4,
        "random_segment": (1.0, 2.0),
        "random_turn_deg": 30.0,
        "texts": ("walk", "run"),
    }
    env = path_env(tiny_model, None, **kw)
    env.reset(seed=5)
    pelvis = env.history_world()[:, -1, 0, :2]
    pts = torch.cat((pelvis[:, None], env._wp[:, :, :2]), 1)
    seg = pts.diff(dim=1)
    length = seg.norm(dim=-1)
    assert length.min() >= 1.0 - 1e-5 and length.max() <= 2.0 + 1e-5
    heading = torch.atan2(seg[..., 1], seg[..., 0])
    turn = torch.remainder(heading.diff(dim=1) + math.pi, 2 * math.pi) - math.pi
    assert turn.abs().max() <= math.radians(30) + 1e-4
    assert all(len(set(env._wp_text[i].tolist())) == 1 for i in range(8))  # one text per path by default
    other = path_env(tiny_model, None, **kw)
    other.reset(seed=5)
    assert torch.equal(env._wp, other._wp)
