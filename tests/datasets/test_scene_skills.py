"""The scene skills of the procedural generator (crouch, crouch walk, sit down, stand up, stairs,
reach, wave, pick up): known answers
on generated sequences, checked with the bench's own skill checks (latentrl/evaluation/skill_checks.py)."""

import functools
import math

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
from latentrl.datasets.locomotion.skills import RISER_RANGE, SEAT_HEIGHT_RANGE, TREAD_RANGE
from latentrl.datasets.motion_text import read_sequence, validate_sequence
from latentrl.errors import ConfigError
from latentrl.evaluation.skill_checks import (
    CROUCH_MIN_DROP_M,
    crouch_depth,
    hand_distance,
    pelvis_drop,
    reach_check,
    reach_target,
    seat_behind,
    seat_errors,
    sit_check,
    stair_check,
    stairs_ahead,
    tread_clearance,
    wave_check,
)
from latentrl.motion.skeleton import FOOT_JOINTS

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
    full = dataset_statistics(generate_sequences(LocomotionConfig(num_sequences=24, seed=3, skills=SKILLS)))
    light = dataset_statistics(generate_sequences(LocomotionConfig(
        num_sequences=24, seed=3, skills=SKILLS, skill_weights={s: 0.25 for s in SCENE_SKILLS})))

    def scene_share(stats):
        frames = {k: v["frames"] for k, v in stats["skills"].items()}
        return sum(frames.get(s, 0) for s in SCENE_SKILLS) / sum(frames.values())

    assert scene_share(light) < 0.8 * scene_share(full)


# --- stairs -----------------------------------------------------------------------------------------------

STAIR_SET = ("stand", "walk", "stairs_up", "stairs_down")


@functools.cache
def stair_data(num=20, seconds=14.0, seed=3):
    return generate_sequences(LocomotionConfig(num_sequences=num, seconds_per_sequence=seconds, seed=seed,
                                               skills=STAIR_SET))


def planted(seq, speed_m_s=0.15):
    """(T, 2) foot joints moving slower than ``speed_m_s`` to the next frame (the last frame: False)."""
    toe = seq["joints"][:, list(FOOT_JOINTS)].astype(np.float64)
    speed = np.linalg.norm(np.diff(toe, axis=0), axis=-1) * FPS
    return np.concatenate([speed < speed_m_s, np.zeros((1, 2), bool)])


def runs(mask):
    """[start, end) ranges where ``mask`` is True."""
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.astype(np.int8), [0]))))
    return list(zip(edges[::2], edges[1::2]))


def stair_frames(seq):
    """(T,) frames labelled by a stairs text alone, and (T,) frames with any stairs label."""
    count, stairs = np.zeros(len(seq["joints"]), int), np.zeros(len(seq["joints"]), bool)
    for a, b, skill in segments(seq):
        count[a:b] += 1
        stairs[a:b] |= skill in ("stairs_up", "stairs_down")
    return stairs & (count == 1), stairs


def test_stairs_put_planted_feet_flat_on_the_treads_of_the_stored_flights():
    checked, texts = 0, set()
    for seq in stair_data():
        validate_sequence(seq, "stairs.npz", check_fk=True)
        texts |= set(map(str, seq["seg_text"]))
        only, labelled = stair_frames(seq)
        if "stairs" not in seq:
            assert not labelled.any()
            continue
        rows, ground = seq["stairs"], seq["foot_floor"].astype(np.float64)
        assert rows.shape[1] == 8 and ground.shape == (len(seq["joints"]), 2)
        assert np.all((rows[:, 4] >= RISER_RANGE[0]) & (rows[:, 4] <= RISER_RANGE[1]))
        assert np.all((rows[:, 5] >= TREAD_RANGE[0]) & (rows[:, 5] <= TREAD_RANGE[1])) and np.all(rows[:, 6] >= 1)
        assert ground.min() >= 0.0 and rows[:, 7].min() >= 0.0  # the lowest ground is the floor
        toe = seq["joints"][:, list(FOOT_JOINTS)].astype(np.float64)
        clear = toe[..., 2] - ground
        assert np.linalg.norm(np.diff(seq["joints"], axis=0), axis=-1).max() * FPS < 10.0  # no pops (m/s)
        down = planted(seq, speed_m_s=0.05) & only[:, None]  # still feet (a swing is faster)
        assert down.sum() > FPS
        assert clear[down].min() >= -0.01  # penetration <= 1 cm
        assert clear[down].mean() <= 0.03 and clear[down].max() <= 0.04  # float <= 3 cm (toe joint 2 cm up)
        assert clear.min() >= -0.01  # no foot joint inside a step, in any frame (swings clear the tread edges)
        # planted feet do not slide on the treads: no creep over a run of still frames (< 1 mm per frame)
        still = planted(seq, speed_m_s=0.03) & only[:, None]
        for leg in range(2):
            for a, b in runs(still[:, leg]):
                if b - a >= 5:
                    assert np.linalg.norm(toe[b - 1, leg, :2] - toe[a, leg, :2]) < 0.003
        # the ground under a planted foot changes only under a stairs label (the labels switch with the terrain)
        for leg in range(2):
            frames = np.flatnonzero(planted(seq)[:, leg])
            changes = frames[1:][np.abs(np.diff(ground[frames, leg])) > 1e-6]
            assert labelled[changes].all()
        checked += 1
    assert checked >= 4
    assert set(SYNONYMS["stairs_up"]) | set(SYNONYMS["stairs_down"]) <= texts


@pytest.mark.parametrize("skill", ["stairs_up", "stairs_down"])
def test_stair_check_passes_the_data_and_fails_a_misplaced_flight(skill):
    seq = generate_sequences(LocomotionConfig(num_sequences=1, seconds_per_sequence=5.0, seed=2, skills=(skill,)))[0]
    joints, row = torch.from_numpy(seq["joints"].astype(np.float64)), torch.from_numpy(seq["stairs"][0])
    result = stair_check(joints, row)
    assert bool(result["ok"]) and float(result["penetration_m"]) <= 0.001 and float(result["float_m"]) <= 0.025
    # the flight's geometry gives the stored terrain height under the feet
    clear = tread_clearance(joints, row).numpy()
    np.testing.assert_allclose(joints[:, list(FOOT_JOINTS), 2].numpy() - clear, seq["foot_floor"], atol=1e-5)
    climb = float(joints[-1, 0, 2] - joints[0, 0, 2])
    assert (climb > 0.5) == (skill == "stairs_up") and abs(climb) > 0.5
    walking = (1.0 if skill == "stairs_up" else -1.0) * torch.stack((torch.cos(row[2]), torch.sin(row[2])))
    moved = row.clone()
    moved[:2] -= 0.5 * row[5] * walking  # half a tread back: every edge now lies under a planted toe
    assert not bool(stair_check(joints, moved)["ok"])
    moved = row.clone()
    moved[7] += 0.05  # 5 cm higher: the feet sink into the treads
    assert not bool(stair_check(joints, moved)["ok"])


# --- hands: reach, wave, pick up --------------------------------------------------------------------------

HAND_SET = ("stand", "walk", "reach_left", "reach_right", "wave", "pick_up")


@functools.cache
def hand_data(num=24, seconds=14.0, seed=5):
    return generate_sequences(LocomotionConfig(num_sequences=num, seconds_per_sequence=seconds, seed=seed,
                                               skills=HAND_SET))


def heading_frame(joints, frame):
    """(right, forward) unit vectors of the body at ``frame`` from the hip axis."""
    right = joints[frame, 2, :2] - joints[frame, 1, :2]
    right = right / np.linalg.norm(right)
    return right, np.array([-right[1], right[0]])


def test_reaches_put_the_hand_on_a_reachable_target_in_every_direction():
    directions, texts, checked = set(), set(), 0
    arm = None
    for seq in hand_data():
        validate_sequence(seq, "hands.npz", check_fk=True)
        texts |= set(map(str, seq["seg_text"]))
        joints = seq["joints"].astype(np.float64)
        assert foot_skate(joints, horizontal=True).mean() * FPS * 100 < 0.1  # feet stay planted
        assert np.linalg.norm(np.diff(joints, axis=0), axis=-1).max() * FPS < 8.0  # no pops (m/s)
        rest = seq["rest_joints"].astype(np.float64)
        arm = np.linalg.norm(rest[18] - rest[16]) + np.linalg.norm(rest[20] - rest[18])
        segs = segments(seq)
        for x, y, z, hand, first, last in seq.get("reaches", np.zeros((0, 6))):
            hand, first, last = int(hand), int(first), int(last)
            target = np.array([x, y, z])
            dist = hand_distance(torch.from_numpy(joints), torch.from_numpy(target), hand).numpy()
            assert dist[first:last + 1].max() < 0.02  # the hand holds its target at the apex
            assert float(reach_check(torch.from_numpy(joints), torch.from_numpy(target), hand)["reached"])
            shoulder = joints[(first + last) // 2, 16 + hand]
            offset = target - shoulder
            assert np.linalg.norm(offset) <= 0.96 * arm  # within the arm's length
            owner = [s for a, b, s in segs if a <= first and last < b]
            assert owner and owner[0] in ("reach_left", "reach_right", "pick_up")
            assert hand == {"reach_left": 0, "reach_right": 1}.get(owner[0], hand)
            if owner[0] == "pick_up":
                assert z - 0.0 < 0.2  # the hand at the floor
                continue
            right, forward = heading_frame(joints, (first + last) // 2)
            out = offset[:2] @ right * (1 if hand else -1)
            up = offset[2] / np.linalg.norm(offset)
            directions.add("up" if up > 0.6 else "down" if up < -0.6 else "side" if out > offset[:2] @ forward
                           else "forward")
            checked += 1
        for k, (a, _, skill) in enumerate(segs):  # the arm hangs while the previous label (stand) lasts
            if skill in ("reach_left", "reach_right", "wave", "pick_up") and k and segs[k - 1][2] == "stand":
                hang = slice(a, segs[k - 1][1])
                for hand in (0, 1):
                    assert np.all(joints[hang, 20 + hand, 2] < joints[hang, 16 + hand, 2] - 0.3)
    assert checked >= 6 and directions == {"forward", "up", "down", "side"}
    for skill in ("reach_left", "reach_right", "wave", "pick_up"):
        assert set(SYNONYMS[skill]) <= texts, skill


def test_wave_raises_a_hand_and_swings_it():
    waves = 0
    for seq in hand_data():
        joints = torch.from_numpy(seq["joints"].astype(np.float64))
        segs = segments(seq)
        for a, b, skill in segs:
            if skill != "wave" or b - a < 2 * FPS:
                continue
            clip = joints[a:b]
            result = [wave_check(clip, hand) for hand in (0, 1)]
            hand = int(result[1]["raised"] > result[0]["raised"])
            assert float(result[hand]["raised"]) > 0.2 and 1.0 <= float(result[hand]["swings_hz"]) <= 3.5
            assert float(result[1 - hand]["raised"]) == 0.0
            waves += 1
    assert waves >= 2
    seq = generate_sequences(LocomotionConfig(num_sequences=1, seconds_per_sequence=3.0, skills=("stand",)))[0]
    still = [wave_check(torch.from_numpy(seq["joints"].astype(np.float64)), hand) for hand in (0, 1)]
    assert all(float(r["raised"]) == 0.0 for r in still)


# --- scenes placed for a rollout the way the data places them ---------------------------------------------


def test_seat_and_stairs_placed_from_a_standing_frame_match_the_data():
    seats = 0
    for seq in posture_data():
        segs = segments(seq)
        joints = torch.from_numpy(seq["joints"].astype(np.float64))
        for k, (_, _, skill) in enumerate(segs):
            if skill != "sit_down" or not k or segs[k - 1][2] != "stand" or "seats" not in seq:
                continue
            stored = torch.from_numpy(seq["seats"][[i for i, s in enumerate(segs) if s[2] == "sit_down"].index(k)])
            standing = joints[segs[k - 1][1] - 1]  # the last frame before the descent
            placed = seat_behind(standing, height=float(stored[2]))
            assert torch.linalg.vector_norm(placed[:2] - stored[:2]) < 0.06
            assert abs(math.remainder(float(placed[3] - stored[3]), 2 * math.pi)) < math.radians(5)
            settled = slice(segs[k - 1][1] + round(1.4 * FPS), segs[k + 1][0] if k + 1 < len(segs) else len(joints))
            if settled.stop - settled.start >= 15:
                assert bool(sit_check(joints[settled], placed)["seated"])
            seats += 1
    assert seats >= 2
    flights = 0
    for seq in stair_data():
        segs = segments(seq)
        joints = torch.from_numpy(seq["joints"].astype(np.float64))
        only, _ = stair_frames(seq)
        for k, (a, b, skill) in enumerate(segs):
            if skill != "stairs_up" or not k or segs[k - 1][2] != "stand":
                continue
            standing = joints[a]  # still standing: the first step starts after the cross-fade's middle
            placed = stairs_ahead(standing, up=True)
            rows = [torch.from_numpy(r.astype(np.float64)) for r in seq["stairs"] if r[7] == seq["foot_floor"][a].min()
                    and abs(math.remainder(float(r[2] - placed[2]), 2 * math.pi)) < math.radians(3)]
            assert len(rows) == 1  # the flight this block climbs: from the ground it stands on, straight ahead
            row = rows[0]
            placed = stairs_ahead(standing, float(row[4]), float(row[5]), int(row[6]), up=True)
            direction = torch.stack((torch.cos(row[2]), torch.sin(row[2])))
            assert abs(float((placed[:2] - row[:2]) @ direction)) < 0.03  # the same first edge
            down = planted(seq, 0.05)[a:b] & only[a:b, None]
            clear = tread_clearance(joints[a:b], placed)
            assert (clear[torch.from_numpy(down)] - 0.02).abs().max() < 0.005  # the flight the feet stand on
            flights += 1
    assert flights >= 2


def test_reach_targets_placed_from_a_standing_frame():
    seq = generate_sequences(LocomotionConfig(num_sequences=1, seconds_per_sequence=2.0, skills=("stand",)))[0]
    standing = torch.from_numpy(seq["joints"][0].astype(np.float64))
    rest = seq["rest_joints"].astype(np.float64)
    arm = np.linalg.norm(rest[18] - rest[16]) + np.linalg.norm(rest[20] - rest[18])
    for hand in (0, 1):
        shoulder = standing[16 + hand]
        targets = {d: reach_target(standing, hand, d, fraction=0.8) for d in ("forward", "up", "down", "side")}
        for target in targets.values():
            assert float(torch.linalg.vector_norm(target - shoulder)) == pytest.approx(0.8 * arm, abs=1e-6)
        assert targets["up"][2] > shoulder[2] + 0.3 and targets["down"][2] < shoulder[2] - 0.3
        assert float(targets["forward"][2]) == pytest.approx(float(shoulder[2]))
        outward = (targets["side"][0] - shoulder[0]) * (standing[2, 0] - standing[1, 0])  # along the hip axis
        assert float(outward) * (1 if hand else -1) > 0
    with pytest.raises(ValueError, match="direction 'behind'"):
        reach_target(standing, 0, "behind")
