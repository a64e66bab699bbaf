"""The per-segment skill check: known answers on hand-made motions, segments of recorded episodes, report fields."""

import json
import math

import numpy as np
import pytest
import torch

from latentrl.envs.path import FollowPathEnv, WaypointPath
from latentrl.evaluation import report as R
from latentrl.evaluation import skills as K
from latentrl.evaluation.runner import EvalSettings, SuiteResult, policy_fn, run_path
from latentrl.motion.clip import MotionClip
from tests.evaluation.conftest import FAR, fresh_policy

FPS = 30


def make_clip(parts, feet=None) -> MotionClip:
    """A clip in the primitive layout: ``parts`` is ``[(steps, text, speed m/s), ...]``, one goal per part.

    The pelvis walks along +y at each part's speed, 0.9 m up. ``feet`` (a function of the frame index ->
    (left down, right down)) places foot joints 10/11 on the floor or 20 cm above it; default both down.
    """
    steps = sum(n for n, _, _ in parts)
    frames = 2 + 8 * steps
    joints = np.zeros((frames, 22, 3), np.float32)
    texts, goals, y = ["", ""], [], 0.0
    for k, (n, text, _) in enumerate(parts):
        texts += [text] * 8 * n
        goals += [(float(k), 10.0, 0.0)] * n
    speeds = [0.0, 0.0] + [s for n, _, s in parts for _ in range(8 * n)]
    for t in range(frames):
        y += speeds[t] / FPS
        joints[t, 0] = (0.0, y, 0.9)
        left, right = feet(t) if feet else (True, True)
        joints[t, 10] = (-0.1, y, 0.0 if left else 0.2)
        joints[t, 11] = (0.1, y, 0.0 if right else 0.2)
    return MotionClip(joints, FPS, texts, goals=np.asarray(goals, np.float32))


def test_texts_map_to_skill_families():
    assert [K.skill_of(t) for t in ("run", "jog forward", "Running fast", "walk", "walk backwards")] == [
        "run", "run", "run", "walk", "walk"]
    assert K.skill_of("hop on left leg") == "hop_left" and K.skill_of("hop on right leg") == "hop_right"
    assert K.skill_of("hop") is None and K.skill_of("dance") is None and K.skill_of("hop left and right") is None


@pytest.mark.parametrize(("text", "speed", "match"), [
    ("run", 3.0, True), ("run", 1.0, False), ("jog", 2.0, True),
    ("walk", 1.0, True), ("walk", 3.0, False), ("walk", 0.2, False),
    ("dance", 1.0, None),
])
def test_speed_rule_known_answers(text, speed, match):
    [seg] = K.judge_clip(make_clip([(8, text, speed)]))  # 64 frames, 2.1 s
    assert seg["measured"] and seg["match"] is match
    assert seg["speed_m_s"] == pytest.approx(speed, rel=1e-4)
    assert seg["skill"] == K.skill_of(text) and seg["waypoint"] == 0 and seg["text"] == text


def test_hop_rule_known_answers():
    left_down = make_clip([(8, "hop on left leg", 1.0)], feet=lambda t: (True, False))
    assert K.judge_clip(left_down)[0]["match"] is True
    assert K.judge_clip(left_down)[0]["left_only"] == 1.0 and K.judge_clip(left_down)[0]["right_only"] == 0.0
    right_down = make_clip([(8, "hop on left leg", 1.0)], feet=lambda t: (False, True))
    assert K.judge_clip(right_down)[0]["match"] is False
    mirrored = make_clip([(8, "hop on right leg", 1.0)], feet=lambda t: (False, True))
    assert K.judge_clip(mirrored)[0]["match"] is True
    assert K.judge_clip(make_clip([(8, "hop on left leg", 1.0)]))[0]["match"] is False  # both feet down: walking
    # Left alone in half the frames, right alone in 20% (> 10%): not a hop on the left leg.
    alternating = make_clip([(8, "hop on left leg", 1.0)], feet=lambda t: (t % 10 < 5, t % 10 >= 8))
    seg = K.judge_clip(alternating)[0]
    assert seg["left_only"] >= K.HOP_STANCE_MIN_SHARE and seg["right_only"] > K.HOP_OTHER_MAX_SHARE
    assert seg["match"] is False


def test_segments_split_at_goal_changes_and_skip_transitions():
    clip = make_clip([(2, "walk", 1.0), (6, "run", 3.0), (5, "walk", 1.0)])
    segs = K.segments(clip)
    assert [(s.waypoint, s.text, s.start, s.stop) for s in segs] == [(0, "walk", 2, 18), (1, "run", 18, 66),
                                                                     (2, "walk", 66, 106)]
    entries = K.judge_clip(clip)
    assert not entries[0]["measured"] and entries[0]["match"] is None  # 16 frames < 1 s
    assert entries[0]["start_s"] == pytest.approx(2 / 30) and entries[0]["duration_s"] == pytest.approx(16 / 30)
    # The run segment's first 0.5 s are left out: its mean is 3 m/s, not dragged down by the walk before it.
    assert entries[1]["speed_m_s"] == pytest.approx(3.0, rel=1e-4) and entries[1]["match"] is True
    assert entries[2]["match"] is True
    assert K.match_share(entries) == 1.0
    table = K.per_text(entries)
    assert list(table) == ["run", "walk"]  # measured segments only, in order of first use
    assert table["walk"]["segments"] == 1 and table["run"]["matched"] == 1


def test_a_walking_motion_labelled_run_does_not_match():
    entries = K.judge_clip(make_clip([(8, "walk", 1.2), (8, "run", 1.2), (8, "dance", 1.2)]))
    assert [e["match"] for e in entries] == [True, False, None]
    assert K.match_share(entries) == 0.5  # the unjudged "dance" does not count
    assert math.isnan(K.match_share(entries[2:]))


def test_segments_of_a_recorded_episode(tiny_model):
    """The env records the goal in force per step; segments follow its waypoint index and text."""
    path = WaypointPath(((0.0, 0.0, 0.0), (0.0, 40.0, 0.0)), ("walk", "run"))  # the first is reached in step 1
    env = FollowPathEnv(1, motion=tiny_model, paths=[path], path_assignment="by_env", record_history=True,
                        autoreset_mode="Disabled")
    env.reset(seed=0)
    for _ in range(5):
        *_, infos = env.step(torch.zeros(1, env.single_action_space.shape[0]))
    assert int(infos["waypoint_index"][0]) == 1
    segs = K.segments(env.export_clip(0))
    assert [(s.waypoint, s.text, s.start, s.stop) for s in segs] == [(0, "walk", 2, 10), (1, "run", 10, 42)]


def test_evaluation_reports_segments_in_json_and_markdown(tiny_model, tmp_path):
    far = WaypointPath(tuple(tuple(map(float, w)) for w in FAR["goal_location"]), tuple(FAR["goal_text"]))
    settings = EvalSettings(episodes=2, max_steps=6)
    result = run_path(policy_fn(fresh_policy(tiny_model)), tiny_model, far, settings, suite="far")
    for ep in result.episodes:
        assert [(s["waypoint"], s["text"], s["measured"]) for s in ep.segments] == [(0, "walk", False),
                                                                                    (1, "run", True)]
    suite = SuiteResult("far", "far.json", [result])
    data = R.build_report([suite], settings, policy={"path": "p.pt"}, motion={"source": "m.pt"})
    js, md = R.write_report(tmp_path, data)
    loaded = json.loads(js.read_text())
    matched = [ep.segments[1]["match"] for ep in result.episodes]
    for block in (loaded["suites"]["far"], loaded["suites"]["far"]["paths"][0], loaded["overall"]):
        assert block["segment_skill_match"] == pytest.approx(sum(matched) / 2)
        assert set(block["skills"]) == {"run"} and block["skills"]["run"]["segments"] == 2
    assert len(loaded["suites"]["far"]["paths"][0]["episodes"][0]["segments"]) == 2
    text = md.read_text()
    assert "## Skill per segment" in text and "| far | run | 2 | 2 |" in text
    assert f"speed >= {K.RUN_MIN_SPEED_M_S:g} m/s" in text
    assert R.load_report(tmp_path)["overall"]["segment_skill_match"] == loaded["overall"]["segment_skill_match"]
    assert "| **overall** | all | 2 | 2 |" in text
    for block in (loaded["overall"], *loaded["suites"].values()):  # a report written before the skill check
        del block["segment_skill_match"], block["skills"]
    assert "predates the skill check" in R.report_markdown(loaded)


def test_feet_on_a_box_top_count_as_down_on_the_terrain():
    """A hop on a 0.3 m platform: the flat floor sees no contact at all; the scene's terrain sees the hop."""
    from latentrl.scenes import Box, Scene, SceneBatch

    clip = make_clip([(8, "hop on left leg", 0.5)], feet=lambda t: (True, False))
    clip.joints[..., 2] += 0.3  # the whole body 0.3 m up, standing on the box below
    platform = SceneBatch.from_scenes([Scene((Box((0.0, 1.0), (2.0, 4.0, 0.3)),))])
    flat, = K.judge_clip(clip)
    assert flat["left_only"] == 0.0 and flat["match"] is False
    on_box, = K.judge_clip(clip, platform)
    assert on_box["left_only"] == 1.0 and on_box["right_only"] == 0.0 and on_box["match"] is True
    # Off the box (the walk starts at y = 0 and the box spans y -1..3): a scene elsewhere changes nothing.
    far = SceneBatch.from_scenes([Scene((Box((20.0, 20.0), (1.0, 1.0, 0.3)),))])
    assert K.judge_clip(clip, far) == [flat]
