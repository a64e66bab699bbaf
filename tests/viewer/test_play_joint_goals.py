"""``latentrl play`` of a ReachJoint policy: clicked joint goals at a time, scored as a goal file's are.

The env's queue is checked against known answers (each goal's error is its joint's distance at its own frame of
the frames shown; appended goals fall due their gap after the goal before; a full queue makes room by dropping
done goals), the controller on the shipped pelvis policy with refinement (the clicked goals land within its
radius), and clicks as a page sends them (the panel's joint and seconds; bad panel values are ignored in one line).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from latentrl.envs.reach_joint import JOINTS, goal_frame
from latentrl.motion.representation import FUTURE_LENGTH
from latentrl.optim.refine import RefineSettings
from tests.viewer.test_security import RawClient, wait_for


@pytest.fixture(scope="module")
def shipped():
    from latentrl.motion.checkpoint import load_motion_model
    from latentrl.ppo import load_policy
    from latentrl.resources import policy_file

    return load_policy(policy_file("reach_joint_default"), "cpu"), load_motion_model("default")


def joint_env(shipped):
    from latentrl.viewer.live import play_env

    loaded, model = shipped
    return play_env(loaded.checkpoint, model, None, "cpu", "reach_joint")


def frames_of(env, steps: int) -> np.ndarray:
    """Step ``env`` with zero noise ``steps`` times; (steps x 8, 22, 3) the frames (frame m is index m - 1)."""
    out = []
    for _ in range(steps):
        _, _, terminated, _, _ = env.step(torch.zeros(1, env.single_action_space.shape[0]))
        assert not bool(terminated[0]), "a queue never ends the episode"
        out.append(env.last_frames[0].cpu().numpy())
    return np.concatenate(out)


def test_queued_goals_fall_due_at_their_frames_and_score_as_their_joints_distance(shipped):
    env = joint_env(shipped)
    env.reset(seed=0)
    assert type(env).__name__ == "SteeredReachJointEnv" and env.pending() == 0
    assert env.planar_joint("pelvis") and env.planar_joint("left_foot") and not env.planar_joint("left_hand")
    assert env.add_goal("pelvis", (0.2, 1.0), 0.5)  # frame 15: step 2
    assert env.add_goal("left_hand", (0.3, 1.6, 1.1), 0.6, append=True)  # 18 frames after: frame 33, step 5
    assert env.add_goal("left_foot", (0.1, 2.0), 0.2, append=True)  # frame 39, step 5 too
    assert env.pending() == 3 and [g["frames"] for g in env.queued_goals()] == [15, 33, 39]
    frames = frames_of(env, 5)
    scored = env.scored_goals()
    assert [j for j, _ in scored] == ["pelvis", "left_hand", "left_foot"] and env.pending() == 0
    pelvis = np.linalg.norm(frames[15 - 1, JOINTS["pelvis"], :2] - (0.2, 1.0))
    hand = np.linalg.norm(frames[33 - 1, JOINTS["left_hand"]] - (0.3, 1.6, 1.1))
    foot = np.linalg.norm(frames[39 - 1, JOINTS["left_foot"], :2] - (0.1, 2.0))
    assert np.allclose([e for _, e in scored], [pelvis, hand, foot], atol=1e-5)
    assert env.queued_goals() == []
    # a new plain click replaces the queue and counts from now
    assert env.add_goal("head", (0.0, 2.0, 1.5), 1.0)
    assert env.pending() == 1 and env.queued_goals()[0]["frames"] == goal_frame(1.0)


def test_a_goal_after_an_asap_one_gets_its_time_when_that_one_is_due(shipped):
    env = joint_env(shipped)
    env.reset(seed=0)
    env.add_goal("pelvis", (0.0, 0.6), None)  # asap: 0.6 m at the trained max speed
    first = env.queued_goals()[0]["frames"]
    assert first is not None and first == math.ceil(np.linalg.norm(
        env.history_world()[0, -1, JOINTS["pelvis"], :2].cpu().numpy() - (0.0, 0.6)) / env.max_speed * 30)
    env.add_goal("pelvis", (0.0, 1.2), 0.3, append=True)
    assert env.queued_goals()[1]["frames"] == first + goal_frame(0.3)  # the asap one's time is known: eager
    env.add_goal("pelvis", (0.0, 2.0), None, append=True)
    env.add_goal("pelvis", (0.0, 2.5), 0.4, append=True)
    assert env.queued_goals()[3]["frames"] is None  # after an asap goal not yet current: not known
    steps = 0
    while env.pending() > 2:  # until the second asap goal is current
        frames_of(env, 1)
        steps += 1
        assert steps < 40
    third, fourth = (g["frames"] for g in env.queued_goals())
    assert third is not None and fourth == third + goal_frame(0.4)


def test_a_full_queue_makes_room_by_dropping_done_goals(shipped):
    from latentrl.viewer.joint_queue import MAX_QUEUED

    env = joint_env(shipped)
    env.reset(seed=0)
    for i in range(MAX_QUEUED):
        assert env.add_goal("pelvis", (0.0, 0.1 * i), 0.1, append=True)
    assert env.pending() == MAX_QUEUED and not env.add_goal("pelvis", (0.0, 5.0), 0.1, append=True)
    frames_of(env, 2)  # goals due at frames 3, 6, 9, 12, 15: five done
    assert env.pending() == MAX_QUEUED - 5 and len(env.scored_goals()) == 5
    assert env.add_goal("pelvis", (0.0, 5.0), 0.1, append=True)
    queued = env.queued_goals()
    assert len(queued) == MAX_QUEUED - 4 and np.allclose(queued[-1]["target"][:2], (0.0, 5.0))
    assert [g["frames"] for g in queued[:2]] == [18 - 2 * FUTURE_LENGTH, 21 - 2 * FUTURE_LENGTH]
    with pytest.raises(Exception, match="goal joint: expected one of"):
        env.add_goal("tail", (0.0, 1.0), 1.0)


def test_the_shipped_pelvis_policy_lands_clicked_goals_with_refinement(shipped, guarded_server, capsys):
    """Two clicked spots 2 s apart: with 16 refinement steps both land within the radius (card: 1-2 cm)."""
    from latentrl.viewer.joint_play import JointGoalController

    loaded, _ = shipped
    env = joint_env(shipped)
    live = JointGoalController(guarded_server, env, loaded.policy, "test", "walk",
                               refinement=RefineSettings(steps=16), deterministic=True)
    assert live.refining.value and live.joint.value == "pelvis"
    live.set_goal((0.3, 1.5))
    live.add_waypoint((0.6, 2.8))
    assert env.pending() == 2 and live.goal is not None and np.allclose(live.goal[:2], (0.3, 1.5))
    for _ in range(20):
        live._generate()
        while live.frames:
            live._show_next()
        if not live.active:
            break
    errors = [e for _, e in env.scored_goals()]
    assert len(errors) == 2 and max(errors) < env.radius, errors
    assert not live.active and "2 goal(s): mean error" in live.message and live.goal is None
    assert "pelvis goal" in capsys.readouterr().out
    live.reset()
    assert env.pending() == 0 and not live.active


def test_clicks_from_a_page_queue_goals_for_the_panels_joint_and_bad_panel_values_are_ignored(
        shipped, guarded_server, capsys):
    from latentrl.viewer.joint_play import JointGoalController

    loaded, _ = shipped
    env = joint_env(shipped)
    live = JointGoalController(guarded_server, env, loaded.policy, "test", "walk")
    assert not live.refining.value  # a policy storing no refinement starts without it
    assert live.refine_steps.value == 16
    client = RawClient(guarded_server.get_port())  # the loop is not started: the queue stays as clicked

    def click(xy, modifier):  # a ray from 3 m above straight down onto xy
        client.send(type="ScenePointerMessage", event_type="click", ray_origin=(float(xy[0]), float(xy[1]), 3.0),
                    ray_direction=(0.0, 0.0, -1.0), screen_pos=[[0.5, 0.5]], modifier=modifier)

    try:
        client.gui(live.joint, "right_hand")
        client.gui(live.height, 1.3)
        client.gui(live.seconds, 1.5)
        wait_for(lambda: live.joint.value == "right_hand" and live.seconds.value == 1.5 and live.height.value == 1.3,
                 "the panel takes the page's values")
        click((0.4, 1.0), None)
        wait_for(lambda: env.pending() == 1, "a click queues a goal")
        with live.lock:
            goal = env.queued_goals()[0]
        assert goal["joint"] == "right_hand" and np.allclose(goal["target"], (0.4, 1.0, env.floor_height + 1.3))
        assert goal["frames"] == goal_frame(1.5)
        client.gui(live.joint, "left_foot")
        client.gui(live.seconds, 0.0)
        wait_for(lambda: live.joint.value == "left_foot" and live.seconds.value == 0.0, "the panel's new values")
        click((0.2, 1.4), "shift")
        wait_for(lambda: env.pending() == 2, "a shift-click appends a goal")
        with live.lock:
            foot = env.queued_goals()[1]
        assert foot["joint"] == "left_foot" and np.allclose(foot["target"], (0.2, 1.4, env.floor_height))
        client.gui(live.seconds, 99.0)  # a page may send anything: beyond the slider
        wait_for(lambda: live.seconds.value == 99.0, "the bad value arrives")
        click((1.0, 1.0), "shift")
        wait_for(lambda: "ignored a goal" in capsys.readouterr().err, "a bad panel value is one line")
        assert env.pending() == 2
        client.gui(live.refine_steps, 4)
        wait_for(lambda: live.refine_steps.value == 4, "the refinement steps arrive")
        live.refining.value = True
        with live.lock:
            live._action()
        assert live.settings.steps == 4
        client.gui(live.refine_steps, 1000)  # beyond the slider (Viser itself drops values of another type)
        wait_for(lambda: live.refine_steps.value == 1000, "the bad steps arrive")
        with live.lock:
            live._action()
        assert live.settings.steps == 4 and live.refine_steps.value == 4
        assert "ignored refine steps '1000': expected 1-64" in capsys.readouterr().err
    finally:
        client.close()

