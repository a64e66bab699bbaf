"""Joystick: command timelines (files and errors), the command observation, random and scheduled commands."""

import json
import math
from pathlib import Path

import pytest
import torch

from latentrl.envs.goal import body_forward
from latentrl.envs.joystick import STEP_SECONDS, CommandTimeline, JoystickEnv, heading_deg, load_timelines
from latentrl.errors import DataError
from tests.envs.conftest import actions

SUITES = Path(__file__).resolve().parents[2] / "tasks" / "joystick"


@pytest.mark.parametrize("name", ["joystick_walk", "joystick_run"])
def test_shipped_timelines_load(name):
    timelines = load_timelines(SUITES / f"{name}.json")
    assert timelines and all(t.commands[0][0] == 0.0 for t in timelines)
    assert timelines[0].text == name.split("_")[1]


def write(tmp_path, data) -> Path:
    f = tmp_path / "commands.json"
    f.write_text(data if isinstance(data, str) else json.dumps(data))
    return f


GOOD = {"text": "walk", "duration": 10.0, "commands": [{"t": 0, "heading_deg": 0, "speed": 1.0},
                                                         {"t": 4, "heading_deg": 90, "speed": 1.2}]}


def entry(**changes):
    return {**GOOD, **changes}


def command(**changes):
    return {"t": 0, "heading_deg": 0, "speed": 1.0, **changes}


@pytest.mark.parametrize(
    "data,match",
    [
        ("{", r"invalid JSON"),
        ({"text": "walk"}, r"expected a list of timelines"),
        ([], r"holds no timelines"),
        ([GOOD, entry(speed=1)], r"entry 1: unknown field 'speed'; expected \['text', 'commands', 'duration'\]"),
        ([entry(texts="walk")], r"entry 0: unknown field 'texts' \(did you mean 'text'\?\)"),
        ([{"text": "walk", "commands": []}], r"entry 0: missing field 'duration'"),
        ([entry(text="")], r"entry 0: field 'text' must be a non-empty string"),
        ([entry(duration=-1)], r"entry 0: field 'duration' must be seconds in \(0, 3600\], got -1"),
        ([entry(commands=[])], r"entry 0: field 'commands' must be a non-empty list"),
        ([entry(commands=[command(t=1)])], r"entry 0, command 0: field 't' must be 0"),
        ([entry(commands=[command(), command(t=0)])], r"entry 0, command 1: field 't' must be seconds after"),
        ([entry(commands=[command(), command(t=12)])], r"command 1: field 't' must be .*before the duration \(10\)"),
        ([entry(commands=[command(heading_deg="left")])], r"command 0: field 'heading_deg' must be a finite"),
        ([entry(commands=[command(speed=-1)])], r"entry 0, command 0: field 'speed' must be m/s in \[0, 20\], got -1"),
        ([entry(commands=[command(speeed=1)])], r"command 0: unknown field 'speeed' \(did you mean 'speed'\?\)"),
        ([entry(commands=[{"t": 0, "speed": 1}])], r"command 0: missing field 'heading_deg'"),
    ],
)
def test_timeline_errors_name_file_entry_and_field(tmp_path, data, match):
    f = write(tmp_path, data)
    with pytest.raises(DataError, match=match) as err:
        load_timelines(f)
    assert str(err.value).startswith(str(f)) and "\n" not in str(err.value)


def test_missing_timeline_file():
    with pytest.raises(DataError, match="command timeline file not found: nowhere.json"):
        load_timelines("nowhere.json")


def test_heading_convention_zero_is_the_start_facing_and_positive_turns_left():
    tl = CommandTimeline("walk", ((0.0, 0.0, 1.0), (1.0, 90.0, 2.0)), 5.0)
    assert tl.at(0.5) == (0.0, 0.0, 1.0) and tl.at(1.0) == (1.0, 90.0, 2.0) and tl.at(4.9)[1] == 90.0
    assert heading_deg(torch.tensor([math.pi / 2, math.pi, 0.0, -math.pi / 2])).tolist() == pytest.approx(
        [0.0, 90.0, -90.0, 180.0])


def test_scheduled_commands_are_observed_relative_to_the_body_and_end_the_episode(tiny_model):
    timeline = CommandTimeline("run", ((0.0, 90.0, 1.5), (2 * STEP_SECONDS, -45.0, 0.5)), 3 * STEP_SECONDS)
    env = JoystickEnv(2, motion=tiny_model, commands=[timeline], command_assignment="by_env")
    obs, _ = env.reset(seed=0)
    assert [env.texts[i] for i in env._text_idx] == ["run", "run"]
    forward, _ = body_forward(env.history_world()[:, -1])
    facing = torch.atan2(forward[:, 1], forward[:, 0])
    relative = math.radians(90.0 + 90.0) - facing  # world angle of heading 90 (= -x) minus the facing
    torch.testing.assert_close(obs[:, 0], relative.cos())
    torch.testing.assert_close(obs[:, 1], relative.sin())
    assert obs[:, 2].tolist() == pytest.approx([1.5, 1.5])
    _, _, term, _, infos = env.step(actions(2, 0))
    assert not infos["command_changed"].any() and infos["command_heading_deg"].tolist() == pytest.approx([90, 90])
    obs, _, term, _, infos = env.step(actions(2, 1))  # t = 2 steps: the second command is in force
    assert infos["command_changed"].all() and infos["command_heading_deg"].tolist() == pytest.approx([-45, -45])
    assert infos["command_speed"].tolist() == pytest.approx([0.5, 0.5]) and not term.any()
    _, _, term, _, infos = env.step(actions(2, 2))
    assert term.all() and infos["is_success"].all()


def test_random_commands_change_within_their_ranges(tiny_model):
    env = JoystickEnv(8, motion=tiny_model, speed_range=(0.9, 1.1), heading_change_deg=30,
                      heading_change_seconds=(0.5, 0.6), max_episode_steps=100)
    env.reset(seed=0)
    forward, _ = body_forward(env.history_world()[:, -1])
    turn = torch.remainder(env._heading - torch.atan2(forward[:, 1], forward[:, 0]) + math.pi, 2 * math.pi) - math.pi
    assert turn.abs().max() <= math.radians(30) + 1e-5
    changed, previous = 0, env._heading.clone()
    for k in range(6):
        _, _, _, _, infos = env.step(actions(8, k))
        changed += int(infos["command_changed"].sum())
        step = torch.remainder(env._heading - previous + math.pi, 2 * math.pi) - math.pi
        assert step.abs().max() <= math.radians(30) + 1e-5
        previous = env._heading.clone()
        assert ((env._speed >= 0.9) & (env._speed <= 1.1)).all()
    assert changed >= 8 * 2  # every 2-3 steps
    assert not env._ep_goals.any()  # there is no goal to reach


def test_bad_joystick_arguments(tiny_model):
    from latentrl.errors import ConfigError

    with pytest.raises(ConfigError, match="speed_range"):
        JoystickEnv(1, motion=tiny_model, speed_range=(2.0, 1.0))
    with pytest.raises(ConfigError, match="heading_change_seconds"):
        JoystickEnv(1, motion=tiny_model, heading_change_seconds=(0.0, 1.0))
    with pytest.raises(ConfigError, match="command_assignment"):
        JoystickEnv(1, motion=tiny_model, command_assignment="cycle")
    with pytest.raises(ConfigError, match="the task has no reward term 'dist'"):
        JoystickEnv(1, motion=tiny_model, reward_weights={"dist": 1.0})
