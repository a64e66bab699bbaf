"""``latentrl play`` steered by keys (joystick policies) and by clicks forming a path (reach policies).

Key presses arrive as a page sends them: Viser hotkey commands triggered over the WebSocket by a raw
client. The command must turn and change speed as documented, stay within its bounds, and malformed
key messages must be ignored without stopping the server or its loop. The path test walks the shipped
reach policy through two clicked waypoints and requires the goal to advance only on reaching the first.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from tests.viewer.conftest import walk_controller
from tests.viewer.test_security import RawClient, wait_for


def joystick_controller(server):
    """``latentrl play``'s controller for the shipped joystick policy, built as the command builds it (not started)."""
    from latentrl.motion.checkpoint import load_motion_model
    from latentrl.ppo import load_policy
    from latentrl.resources import policy_file
    from latentrl.viewer.live import LiveController, play_env

    loaded = load_policy(policy_file("joystick_walk_default"), "cpu")
    env = play_env(loaded.checkpoint, load_motion_model("default"), None, "cpu", "joystick")
    return LiveController(server, env, loaded.policy, "test", env.texts[0], seed=0)


@pytest.fixture
def server(guarded_server):
    """These tests drive play's own server (tests/viewer/conftest.py)."""
    return guarded_server


def test_keys_sent_by_a_raw_client_steer_the_joystick_command(server, capsys):
    from latentrl.viewer.live import KEY_SPEED_STEP, KEY_TURN_DEG

    live = joystick_controller(server)
    env = live.env
    lo, hi = env.speed_range
    live.start()
    client = RawClient(server.get_port())

    def press(key):
        client.send(type="CommandTriggerMessage", uuid=live.keys[key]._impl.uuid)

    def command_becomes(heading, speed, what):
        wait_for(lambda: np.allclose(env.command, (heading, speed), atol=1e-4), f"{what}: {env.command}")

    try:
        heading, speed = env.command
        assert abs(heading) < 1e-4 and abs(speed - (lo + hi) / 2) < 1e-6 and not live.active
        press("A")
        command_becomes(KEY_TURN_DEG, speed, "A turns left")
        assert live.active
        press("arrowleft")
        command_becomes(2 * KEY_TURN_DEG, speed, "left arrow turns left")
        press("D")
        press("arrowright")
        press("arrowright")
        command_becomes(-KEY_TURN_DEG, speed, "D and right arrow turn right")
        press("W")
        command_becomes(-KEY_TURN_DEG, speed + KEY_SPEED_STEP, "W speeds up")
        for _ in range(12):
            press("arrowup")
        command_becomes(-KEY_TURN_DEG, hi, "the speed stops at the top of the trained range")
        for _ in range(20):
            press("S")
        command_becomes(-KEY_TURN_DEG, lo, "the speed stops at the bottom")
        for _ in range(13):  # 195 degrees to the left of -15: wraps to 180
            press("A")
        command_becomes(180.0, lo, "the heading wraps")
        press("space")
        wait_for(lambda: not live.active, "space stops")

        # malformed key messages: an unknown command, a uuid of the wrong type, none at all
        before = env.command
        client.send(type="CommandTriggerMessage", uuid="no-such-command")
        time.sleep(0.3)
        client.send(type="CommandTriggerMessage", uuid=12345)  # Viser cannot decode it and drops the connection
        time.sleep(0.5)
        client.close()
        client = RawClient(server.get_port())
        client.send(type="CommandTriggerMessage")
        time.sleep(0.5)
        client.close()
        for key in ("Q", "arrowleft ", None, 3, float("nan"), "x" * 10000):
            live.press(key)  # what the hotkey callback would get with any other key
        err = capsys.readouterr().err
        assert err.count("ignored key") == 6 and all(len(line) < 300 for line in err.splitlines()), err
        assert env.command == before and live.thread.is_alive()
        client = RawClient(server.get_port())
        press("W")
        command_becomes(180.0, lo + KEY_SPEED_STEP, "a good key after the bad ones")
    finally:
        client.close()
        live.stop.set()
        live.thread.join(5)


def test_the_joystick_policy_walks_where_the_keys_point(server):
    """Six presses of A turn the command to -x: the shipped policy walks that way."""
    live = joystick_controller(server)
    for _ in range(6):
        live.press("A")
    assert np.allclose(live.env.command[0], 90.0)
    start = live.pelvis().copy()
    for _ in range(15):  # 4 s of motion
        live._generate()
        while live.frames:
            live._show_next()
    moved = live.pelvis()[:2] - start[:2]
    assert moved[0] < -1.0 and abs(moved[1]) < abs(moved[0]), moved


def test_shift_clicks_form_a_path_followed_in_order(server):
    """A click sets the goal, shift-clicks append waypoints; the goal advances only when the current one is reached."""
    live = walk_controller(server)
    client = RawClient(server.get_port())
    live.start()
    first, second = np.array([0.0, 1.5]), np.array([1.2, 2.7])

    def click(xy, modifier):  # a ray from 3 m above straight down onto xy
        client.send(type="ScenePointerMessage", event_type="click", ray_origin=(float(xy[0]), float(xy[1]), 3.0),
                    ray_direction=(0.0, 0.0, -1.0), screen_pos=[[0.5, 0.5]], modifier=modifier)

    try:
        click((5.0, 5.0), None)
        wait_for(lambda: live.goal is not None and np.allclose(live.goal[:2], (5.0, 5.0)), "a click sets the goal")
        click(first, None)  # a plain click replaces the path
        wait_for(lambda: len(live.path) == 1 and np.allclose(live.goal[:2], first), "a click replaces the path")
        click(second, "shift")
        wait_for(lambda: len(live.path) == 2, "a shift-click appends a waypoint")
        assert np.allclose(live.goal[:2], first) and np.allclose(live.path[1][:2], second)
    finally:
        client.close()
        live.stop.set()
        live.thread.join(5)
    goals, reached_first_at = [], None
    for _ in range(40):
        with live.lock:
            live._generate()
            while live.frames:
                live._show_next()
        goals.append(live.goal[:2].copy())
        if reached_first_at is None and np.allclose(live.goal[:2], second):
            reached_first_at = live.pelvis()[:2].copy()
        if not live.active:
            break
    assert reached_first_at is not None, goals
    assert np.linalg.norm(reached_first_at - first) < 0.6, reached_first_at
    changes = [i for i in range(1, len(goals)) if not np.allclose(goals[i], goals[i - 1])]
    assert len(changes) == 1 and np.allclose(goals[0], first), goals
    assert not live.active and live.path == [], "the walk ends at the last waypoint"
    assert np.linalg.norm(live.pelvis()[:2] - second) < 0.6


def test_play_takes_joystick_and_reach_joint_policies_and_still_refuses_a_timed_one(capsys):
    """The joystick and ReachJoint policies get past the task check (as far as a busy port); a timed policy is one
    line, exit 2."""
    import socket

    from tests.viewer.test_commands import one_line_error

    pytest.importorskip("viser")
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        for name in ("joystick_walk_default", "reach_joint_default"):
            one_line_error(capsys, ["play", name, "--port", str(port)], f"--port {port}: already in use")
    one_line_error(capsys, ["play", "timed_walk_default"], "this policy's task is 'timed'")


def test_a_path_is_bounded_and_a_plain_click_replaces_it(server):
    from latentrl.viewer.live import MAX_WAYPOINTS

    live = walk_controller(server)
    live.add_waypoint((0.0, 1.0))  # no goal in force: the shift-click starts a path
    assert live.active and np.allclose(live.goal[:2], (0.0, 1.0)) and len(live.path) == 1
    for i in range(MAX_WAYPOINTS + 8):
        live.add_waypoint((0.1 * i, 2.0))
    assert len(live.path) == MAX_WAYPOINTS and "waypoint ignored" in live.message
    live.add_waypoint((60.0, 0.0))
    assert len(live.path) == MAX_WAYPOINTS and "more than 50 m" in live.message
    live.set_goal((-1.0, 1.0))
    assert len(live.path) == 1 and np.allclose(live.goal[:2], (-1.0, 1.0))
    live.reset()
    assert live.path == [] and live.goal is None and not live.active
