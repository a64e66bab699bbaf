"""The scene skills of the procedural generator (crouch, crouch walk, sit down, stand up): known answers
on generated sequences, checked with the bench's own skill checks (latentrl/evaluation/skill_checks.py)."""

import functools

import numpy as np
import pytest
import torch

from latentrl.datasets.body import TOE_HEIGHT_M
from latentrl.datasets.locomotion import (
    FOLLOWERS,
    LOCOMOTION_SKILLS,
    NEIGHBOURS,
    SCENE_SKILLS,
    SKILLS,
    SYNONYMS,
    TEXT_TO_SKILL,
    LocomotionConfig,
    dataset_statistics,
    foot_skate,
    generate_dataset,
    generate_sequences,
)
from latentrl.datasets.locomotion.skills import SEAT_HEIGHT_RANGE
from latentrl.datasets.motion_text import read_sequence, validate_sequence
from latentrl.errors import ConfigError
from latentrl.evaluation.skill_checks import CROUCH_MIN_DROP_M, crouch_depth, pelvis_drop, seat_errors, sit_check

FPS = 30
POSTURE_SET = ("stand", "walk", "crouch", "crouch_walk", "sit_down", "stand_up")


@functools.cache
def posture_data(num=16, seconds=14.0, seed=5):
    """Sequences of standing, walking, crouching and sitting (so that every posture skill occurs often)."""
    return generate_sequences(LocomotionConfig(num_sequences=num, seconds_per_sequence=seconds, seed=seed,
                                               skills=POSTURE_SET))


def segments(seq):
    """[(start, end, skill)] in order."""
    return [(int(a), int(b), TEXT_TO_SKILL[str(t)])
            for a, b, t in zip(seq["seg_start"], seq["seg_end"], seq["seg_text"])]


def drop_of(seq):
    joints = torch.from_numpy(seq["joints"].astype(np.float64))
    return pelvis_drop(joints, float(seq["rest_joints"][0, 2])).numpy()


def test_scene_skills_are_off_by_default_and_reach_a_posture_only_the_way_back():
    assert LocomotionConfig().skills == LOCOMOTION_SKILLS
    assert set(SKILLS) == set(LOCOMOTION_SKILLS) | set(SCENE_SKILLS)
    for skill, nxt in FOLLOWERS.items():
        assert set(nxt) <= set(NEIGHBOURS[skill]), skill
    assert FOLLOWERS["crouch"] == ("crouch_walk", "stand_up") and FOLLOWERS["sit_down"] == ("stand_up",)
    assert "stand_up" not in FOLLOWERS["stand"] and "crouch" not in FOLLOWERS["stand_up"]
    assert SYNONYMS["crouch"][0] == "crouch" and SYNONYMS["crouch_walk"][0] == "crouch walk"
    assert SYNONYMS["sit_down"][0] == "sit down" and SYNONYMS["stand_up"][0] == "stand up"
    with pytest.raises(ConfigError, match="skill_weights: unknown skill 'crouhc'"):
        LocomotionConfig(skill_weights={"crouhc": 1.0}).validate()
    with pytest.raises(ConfigError, match="skill_weights.crouch: -1"):
        LocomotionConfig(skill_weights={"crouch": -1.0}).validate()


def test_posture_data_is_valid_planted_and_carries_every_text():
    seqs = posture_data()
    texts = set()
    for i, seq in enumerate(seqs):
        validate_sequence(seq, f"seq{i}.npz", check_fk=True)
        joints = seq["joints"].astype(np.float64)
        assert joints[..., 2].min() >= TOE_HEIGHT_M - 1e-3  # closing steps may dip < 1 mm (walk too)
        assert foot_skate(joints, horizontal=True).mean() * FPS * 100 < 0.1  # planted feet do not slide
        assert np.linalg.norm(np.diff(joints, axis=0), axis=-1).max() * FPS < 8.0  # no pops (m/s)
        texts |= set(map(str, seq["seg_text"]))
        for (_, b0, s0), (a1, _, s1) in zip(segments(seq)[:-1], segments(seq)[1:]):
            assert s1 in FOLLOWERS[s0] and a1 < b0  # a transition: labelled with both skills
    for skill in ("crouch", "crouch_walk", "sit_down", "stand_up"):
        assert set(SYNONYMS[skill]) <= texts, skill  # every prompt of the text table is in the data
    stats = dataset_statistics(seqs)["skills"]
    for skill in ("crouch", "sit_down", "stand_up"):
        assert stats[skill]["skate_xy_cm_s"] < 0.05 and stats[skill]["speed_m_s"] < 0.2, skill
    assert 0.3 < stats["crouch_walk"]["speed_m_s"] < 0.9


def test_crouch_lowers_the_pelvis_25_cm_and_the_labels_switch_with_the_posture():
    held = 0
    for seq in posture_data():
        drop = drop_of(seq)
        segs = segments(seq)
        for k, (a, b, skill) in enumerate(segs):
            prev_end = segs[k - 1][1] if k else 0
            next_start = segs[k + 1][0] if k + 1 < len(segs) else len(drop)
            if skill == "crouch":
                settled = prev_end + FPS if k and segs[k - 1][2] != "crouch_walk" else prev_end
                if next_start > settled:
                    assert drop[settled:next_start].min() >= CROUCH_MIN_DROP_M
                    held += next_start - settled
                if k and segs[k - 1][2] in ("stand", "walk"):  # still standing while the old label lasts
                    assert drop[a:prev_end].max() < 0.04
            if skill == "crouch_walk":
                assert drop[prev_end:next_start].min() >= CROUCH_MIN_DROP_M
            if skill == "stand_up" and k and segs[k - 1][2] == "crouch":
                assert drop[a:prev_end].min() >= CROUCH_MIN_DROP_M  # rises only once "stand up" is alone
                if next_start < b:
                    assert drop[next_start:b].max() < 0.04  # upright before the next skill's label
    assert held >= 5 * FPS
    # the check the bench uses on a rollout asked to crouch: the drop held over its last half second
    seq = generate_sequences(LocomotionConfig(num_sequences=1, seconds_per_sequence=3.0, skills=("crouch",)))[0]
    depth = crouch_depth(torch.from_numpy(seq["joints"]), float(seq["rest_joints"][0, 2]))
    assert float(depth) >= CROUCH_MIN_DROP_M


def test_sitting_rests_the_pelvis_on_the_stored_seat():
    seated = 0
    seen_seats = 0
    for seq in posture_data():
        segs = segments(seq)
        sits = [k for k, s in enumerate(segs) if s[2] == "sit_down"]
        if not sits:
            assert "seats" not in seq
            continue
        seats = seq["seats"]
        assert seats.shape == (len(sits), 4) and seats.dtype == np.float32
        assert np.all((seats[:, 2] >= SEAT_HEIGHT_RANGE[0]) & (seats[:, 2] <= SEAT_HEIGHT_RANGE[1]))
        joints = torch.from_numpy(seq["joints"].astype(np.float64))
        drop = drop_of(seq)
        for seat, k in zip(seats, sits):
            a, b, _ = segs[k]
            prev_end = segs[k - 1][1] if k else 0
            next_start = segs[k + 1][0] if k + 1 < len(segs) else len(drop)
            height, xy = (e.numpy() for e in seat_errors(joints, torch.from_numpy(seat)))
            down = slice(prev_end + round(1.4 * FPS), next_start)  # the descent takes at most 1.4 s
            if down.stop > down.start:
                assert np.abs(height[down]).max() <= 0.05 and xy[down].max() <= 0.10
                seated += down.stop - down.start
            if k:  # standing while "stand still" still labels it, and rising only under "stand up"
                assert drop[a:prev_end].max() < 0.04
            if next_start < len(drop):
                assert np.abs(height[next_start:b]).max() <= 0.05
            seen_seats += 1
    assert seen_seats >= 3 and seated >= 3 * FPS
    # the bench's check: a sequence that ends seated passes it, the same motion against a moved seat fails
    seq = generate_sequences(LocomotionConfig(num_sequences=1, seconds_per_sequence=4.0, seed=2,
                                              skills=("sit_down",)))[0]
    joints, seat = torch.from_numpy(seq["joints"]), torch.from_numpy(seq["seats"][0])
    assert bool(sit_check(joints, seat)["seated"])
    assert not bool(sit_check(joints, seat + torch.tensor([0.15, 0.0, 0.0, 0.0]))["seated"])
    assert not bool(sit_check(joints, seat + torch.tensor([0.0, 0.0, 0.08, 0.0]))["seated"])


def test_seats_round_trip_through_files_and_skill_weights_share_the_frames(tmp_path):
    cfg = LocomotionConfig(num_sequences=6, seconds_per_sequence=10.0, seed=1, skills=POSTURE_SET)
    seqs = generate_sequences(cfg)
    paths = generate_dataset(cfg, tmp_path)
    with_seats = 0
    for seq, path in zip(seqs, paths):
        loaded = read_sequence(path)
        assert ("seats" in loaded) == ("seats" in seq)
        if "seats" in seq:
            np.testing.assert_array_equal(loaded["seats"], seq["seats"])
            with_seats += 1
    assert with_seats >= 1
    full = dataset_statistics(generate_sequences(LocomotionConfig(num_sequences=12, seed=3, skills=SKILLS)))
    light = dataset_statistics(generate_sequences(LocomotionConfig(
        num_sequences=12, seed=3, skills=SKILLS, skill_weights={s: 0.3 for s in SCENE_SKILLS})))

    def scene_share(stats):
        frames = {k: v["frames"] for k, v in stats["skills"].items()}
        return sum(frames.get(s, 0) for s in SCENE_SKILLS) / sum(frames.values())

    assert scene_share(light) < 0.7 * scene_share(full)
