"""TimedPath: timed path files and their errors, the time-left observation, arrival errors and random times."""

import json
from pathlib import Path

import pytest
import torch

from latentrl.envs.joystick import STEP_SECONDS
from latentrl.envs.timed import TimedPath, TimedPathEnv, load_timed_paths
from latentrl.errors import ConfigError, DataError
from tests.envs.conftest import actions

SUITES = Path(__file__).resolve().parents[2] / "tasks" / "timed"
GOOD = {"goal_location": [[0, 2, 0], [0, 4, 0]], "goal_text": ["walk", "walk"], "goal_time": [2.0, 4.5]}


def test_shipped_timed_suite_loads():
    paths = load_timed_paths(SUITES / "timed_walk.json")
    assert len(paths) == 3 and paths[0].times == (3.5, 6.5, 9.5) and paths[0].texts[0] == "walk"


def write(tmp_path, data) -> Path:
    f = tmp_path / "timed.json"
    f.write_text(json.dumps(data))
    return f


@pytest.mark.parametrize(
    "data,match",
    [
        ([{k: v for k, v in GOOD.items() if k != "goal_time"}], r"path 0: missing field 'goal_time'"),
        ([GOOD, {**GOOD, "goal_times": [1, 2]}], r"path 1: unknown field 'goal_times' \(did you mean 'goal_time'\?\)"),
        ([{**GOOD, "goal_time": [1.0]}], r"path 0: field 'goal_time' has 1 entries for 2 waypoints"),
        ([{**GOOD, "goal_time": [2.0, 1.0]}], r"path 0, waypoint 1: field 'goal_time' must be seconds after the "
                                               r"previous arrival \(2\) and at most 3600, got 1.0"),
        ([{**GOOD, "goal_time": [0, 1.0]}], r"path 0, waypoint 0: field 'goal_time'"),
        ([{**GOOD, "goal_time": "soon"}], r"path 0: field 'goal_time' must be a list of seconds"),
        ([{**GOOD, "goal_location": [[0, 2], [0, 4, 0]]}], r"path 0, waypoint 0: field 'goal_location'"),
    ],
)
def test_timed_path_errors_name_file_path_waypoint_and_field(tmp_path, data, match):
    f = write(tmp_path, data)
    with pytest.raises(DataError, match=match) as err:
        load_timed_paths(f)
    assert str(err.value).startswith(str(f))


def test_time_left_is_observed_and_arrival_error_rewarded(tiny_model):
    path = TimedPath(((0.0, 1.0, 0.0), (0.0, 2.0, 0.0)), ("walk", "walk"), (1.0, 3.0))
    env = TimedPathEnv(2, motion=tiny_model, paths=[path], path_assignment="by_env", max_episode_steps=20)
    obs, _ = env.reset(seed=0)
    field = slice(*env.observation_fields["time_left"])
    assert obs[:, field].flatten().tolist() == pytest.approx([1.0, 1.0])
    obs, *_ = env.step(actions(2, 0))
    assert obs[:, field].flatten().tolist() == pytest.approx([1.0 - STEP_SECONDS] * 2)
    # a radius that holds the whole body: the first waypoint is reached at the first new frame of the next step
    env.success_threshold = 100.0
    _, _, _, _, infos = env.step(actions(2, 1))
    arrival = (8 + 1) / 30
    assert infos["waypoint_reached"].all()
    assert infos["arrival_error_s"].tolist() == pytest.approx([arrival - 1.0] * 2, abs=1e-5)
    assert infos["reward/timing"].tolist() == pytest.approx([1 - abs(arrival - 1.0)] * 2, abs=1e-5)
    assert infos["time_left_s"].tolist() == pytest.approx([3.0 - 2 * STEP_SECONDS] * 2, abs=1e-5)


def test_random_paths_are_timed_within_the_speed_range(tiny_model):
    env = TimedPathEnv(6, motion=tiny_model, speed_range=(1.0, 2.0), random_waypoints=4)
    env.reset(seed=0)
    start = env.history_world()[:, -1, 0, :2]
    points = torch.cat((start[:, None], env._wp[:, :, :2]), 1)
    segment = (points[:, 1:] - points[:, :-1]).norm(dim=-1)
    duration = env._wp_time.diff(dim=1, prepend=torch.zeros(6, 1))
    speed = segment / duration
    assert (speed >= 1.0 - 1e-4).all() and (speed <= 2.0 + 1e-4).all()


def test_untimed_paths_are_refused(tiny_model):
    from latentrl.envs.path import WaypointPath

    with pytest.raises(ConfigError, match="path 0 has no arrival time per waypoint"):
        TimedPathEnv(1, motion=tiny_model, paths=[WaypointPath(((0.0, 1.0, 0.0),), ("walk",))])
