import functools

import numpy as np
import pytest
import torch

from latentrl.datasets.body import (
    TOE_HEIGHT_M,
    axis_angle_to_matrix_np,
    forward_kinematics_np,
    make_body,
    matrix_to_axis_angle_np,
)
from latentrl.datasets.locomotion import (
    LOCOMOTION_SKILLS,
    NEIGHBOURS,
    SKILLS,
    SYNONYMS,
    TEXT_TO_SKILL,
    LocomotionConfig,
    dataset_statistics,
    foot_skate,
    generate_dataset,
    generate_sequences,
    texts_for,
)
from latentrl.datasets.motion_text import read_meta, read_sequence, validate_sequence
from latentrl.errors import ConfigError, DataError
from latentrl.motion.rotations import axis_angle_to_matrix, matrix_to_axis_angle
from latentrl.motion.skeleton import FOOT_JOINTS, forward_kinematics

FPS = 30


@functools.cache
def single(skill, seconds=6.0, seed=0):
    """One sequence that holds a single skill throughout (no neighbours in the skill set)."""
    cfg = LocomotionConfig(num_sequences=1, seconds_per_sequence=seconds, seed=seed, skills=(skill,))
    return generate_sequences(cfg)[0]


def joints_of(seq):
    return seq["joints"].astype(np.float64)


def heading(joints):
    """(T,) unwrapped heading (rad, counter-clockwise from +y) from the right_hip - left_hip direction."""
    across = joints[:, 2, :2] - joints[:, 1, :2]
    return np.unwrap(np.arctan2(across[:, 1], across[:, 0]))


def touchdowns(foot_z):
    """Frames where a foot joint comes down onto its stance height."""
    down = foot_z <= TOE_HEIGHT_M + 1e-4
    return np.flatnonzero(down[1:] & ~down[:-1]) + 1


def pelvis_speed(joints):
    return np.linalg.norm(np.diff(joints[:, 0, :2], axis=0), axis=-1) * FPS


# --- tables and config ------------------------------------------------------------------------------------


def test_skill_tables_are_consistent():
    assert set(SYNONYMS) == set(SKILLS) == set(NEIGHBOURS)
    assert sum(len(t) for t in SYNONYMS.values()) == len(TEXT_TO_SKILL)  # no text names two skills
    assert SYNONYMS["walk"][0] == "walk" and SYNONYMS["run"][0] == "run"
    assert SYNONYMS["hop_left"][0] == "hop on left leg" and SYNONYMS["stand"][0] == "stand still"
    assert "walk slowly" in texts_for("walk", 0.9) and "walk slowly" not in texts_for("walk", 1.5)
    assert "walk fast" in texts_for("walk", 1.5) and "jog" not in texts_for("run", 3.8)
    for skill, near in NEIGHBOURS.items():
        assert all(skill in NEIGHBOURS[n] for n in near), skill  # transitions go both ways


def test_config_errors_name_the_field():
    with pytest.raises(ConfigError, match="LocomotionConfig.skills: unknown skill 'hop_lft'.*hop_left"):
        generate_sequences(LocomotionConfig(skills=("walk", "hop_lft")))
    with pytest.raises(ConfigError, match="LocomotionConfig.transition_seconds"):
        LocomotionConfig(transition_seconds=(0.6, 0.3)).validate()


# --- body -------------------------------------------------------------------------------------------------


def test_rest_skeleton_follows_the_conventions():
    body = make_body(1.75)
    rest = body.rest_joints
    assert rest[0, 2] == pytest.approx(0.53 * 1.75)  # pelvis height 0.53 H
    assert rest[2, 0] - rest[1, 0] == pytest.approx(0.10 * 1.75)  # right hip at +x, hips 0.1 H apart
    np.testing.assert_allclose(rest[list(FOOT_JOINTS), 2], TOE_HEIGHT_M)
    assert np.all(rest[list(FOOT_JOINTS), 1] > rest[[7, 8], 1] + 0.1)  # toes ahead of the ankles (+y)
    assert rest[15, 2] > rest[12, 2] > rest[9, 2] > rest[0, 2]
    assert body.thigh + body.shank + 0.039 * 1.75 == pytest.approx(0.50 * 1.75)
    upper_arm = np.linalg.norm(rest[18] - rest[16])
    assert upper_arm == pytest.approx(0.186 * 1.75, rel=0.01)


def test_numpy_twins_match_torch_rotations_and_fk():
    aa = np.random.default_rng(0).normal(0, 1.2, (50, 22, 3))
    aa[0, 0] = 0.0
    rot = axis_angle_to_matrix_np(aa)
    np.testing.assert_allclose(rot, axis_angle_to_matrix(torch.from_numpy(aa)).numpy(), atol=1e-12)
    np.testing.assert_allclose(axis_angle_to_matrix_np(matrix_to_axis_angle_np(rot)), rot, atol=1e-10)
    np.testing.assert_allclose(matrix_to_axis_angle_np(rot), matrix_to_axis_angle(torch.from_numpy(rot)).numpy(),
                               atol=1e-9)
    rest, transl = make_body(1.7).rest_joints, np.random.default_rng(1).normal(0, 1, (50, 3))
    fk, _ = forward_kinematics(torch.from_numpy(rest), torch.from_numpy(rot), torch.from_numpy(transl))
    np.testing.assert_allclose(forward_kinematics_np(rest, rot, transl), fk.numpy(), atol=1e-12)


# --- generated motion -------------------------------------------------------------------------------------


def test_same_seed_same_data_other_seed_other_data():
    cfg = LocomotionConfig(num_sequences=2, seconds_per_sequence=5.0, seed=3)
    a, b = generate_sequences(cfg), generate_sequences(cfg)
    for sa, sb in zip(a, b):
        for field in sa:
            np.testing.assert_array_equal(sa[field], sb[field])
    c = generate_sequences(LocomotionConfig(num_sequences=2, seconds_per_sequence=5.0, seed=4))
    assert not np.allclose(a[0]["transl"], c[0]["transl"])


@pytest.mark.parametrize("skill", SKILLS)
def test_every_skill_is_valid_and_keeps_stance_feet_still(skill):
    seq = single(skill)
    validate_sequence(seq, f"{skill}.npz", check_fk=True)  # joints = FK(poses) to 1e-4 m
    joints = joints_of(seq)
    assert joints[..., 2].min() >= TOE_HEIGHT_M - 1e-5  # nothing below the floor (or the toe plane)
    dart_skate = foot_skate(joints).mean() * FPS * 100  # DART's calc_skate, cm/s
    sliding = foot_skate(joints, horizontal=True).mean() * FPS * 100
    assert dart_skate < 0.5, f"{skill}: skate {dart_skate:.3f} cm/s"
    assert sliding < 0.1, f"{skill}: horizontal skate {sliding:.3f} cm/s"
    assert set(map(str, seq["seg_text"])) <= set(SYNONYMS[skill])


def test_a_sliding_foot_does_skate():
    joints = joints_of(single("stand")).copy()
    joints[:, 10, 1] += np.arange(len(joints)) * 0.01  # left toe slides 30 cm/s along the floor
    assert foot_skate(joints).mean() * FPS * 100 > 5.0


def test_walking_is_plantigrade_with_a_human_cadence():
    joints = joints_of(single("walk"))
    feet_z = joints[:, list(FOOT_JOINTS), 2]
    np.testing.assert_allclose(feet_z.min(axis=1), TOE_HEIGHT_M, atol=1e-4)  # always one foot down
    steps = sum(len(touchdowns(feet_z[:, i])) for i in range(2)) / (len(joints) / FPS)
    assert 1.6 <= steps <= 2.2
    speed = pelvis_speed(joints).mean()
    assert 0.75 <= speed <= 1.65


def test_run_is_faster_than_walk_with_flight_and_higher_cadence():
    run, walk = joints_of(single("run")), joints_of(single("walk"))
    assert pelvis_speed(run).mean() > 2.4 > 1.7 > pelvis_speed(walk).mean()
    feet_z = run[:, list(FOOT_JOINTS), 2]
    steps = sum(len(touchdowns(feet_z[:, i])) for i in range(2)) / (len(run) / FPS)
    assert 2.5 <= steps <= 3.1
    assert np.mean(feet_z.min(axis=1) > 0.03) > 0.05  # flight: both feet off the floor


@pytest.mark.parametrize("skill, stance, free", [("hop_left", 0, 1), ("hop_right", 1, 0)])
def test_hop_uses_one_foot_with_small_ballistic_hops(skill, stance, free):
    joints = joints_of(single(skill))
    feet_z = joints[:, list(FOOT_JOINTS), 2]
    assert np.mean(feet_z[:, stance] <= TOE_HEIGHT_M + 1e-4) > 0.3  # the stance foot touches down
    assert feet_z[FPS:, free].min() > 0.1  # the free foot stays up (after the first second)
    downs = touchdowns(feet_z[:, stance])
    rate = (len(downs) - 1) / ((downs[-1] - downs[0]) / FPS)
    assert 1.7 <= rate <= 2.3
    takeoffs = np.flatnonzero((feet_z[1:, stance] > TOE_HEIGHT_M + 1e-4) & (feet_z[:-1, stance] <= TOE_HEIGHT_M + 1e-4))
    rises = [joints[a:b, 0, 2].max() - joints[a, 0, 2] for a, b in zip(takeoffs, downs[downs > takeoffs[0]])]
    assert 0.04 <= np.median(rises) <= 0.16


def test_jump_forward_takes_off_with_both_feet():
    joints = joints_of(single("jump_forward", seconds=8.0))
    feet_z = joints[:, list(FOOT_JOINTS), 2]
    air = feet_z.min(axis=1) > 0.05
    assert air.any() and np.array_equal(air, feet_z.max(axis=1) > 0.05)  # both feet leave and land together
    standing = np.median(joints[:, 0, 2])
    assert joints[:, 0, 2].max() - standing > 0.15  # flight apex
    assert joints[:, 0, 2].min() < standing - 0.12  # crouch and landing absorption
    assert np.linalg.norm(joints[-1, 0, :2] - joints[0, 0, :2]) > 0.5


def test_stand_is_still_with_both_feet_down():
    joints = joints_of(single("stand"))
    assert pelvis_speed(joints).max() < 0.1
    np.testing.assert_allclose(joints[:, list(FOOT_JOINTS), 2], TOE_HEIGHT_M, atol=1e-4)
    height = make_body(1.0).rest_joints[0, 2]  # 0.53 H: pelvis height over body height
    body_height = joints[0, 15, 2] / 0.905
    assert joints[:, 0, 2].mean() / body_height == pytest.approx(height, abs=0.01)


@pytest.mark.parametrize("skill, sign", [("turn_left", 1.0), ("turn_right", -1.0)])
def test_turns_curve_the_right_way(skill, sign):
    joints = joints_of(single(skill))
    yaw = heading(joints)
    rate = np.degrees(np.polyfit(np.arange(len(yaw)) / FPS, yaw, 1)[0])  # deg/s, + = counter-clockwise
    assert 25 <= sign * rate <= 95
    travel = joints[-1, 0, :2] - joints[0, 0, :2]
    forward0 = np.array([-np.sin(yaw[0]), np.cos(yaw[0])])
    assert sign * (forward0[0] * travel[1] - forward0[1] * travel[0]) > 0  # the path bends to the turning side


@pytest.mark.parametrize("skill, side", [("sidestep_left", -1.0), ("sidestep_right", 1.0), ("walk_backward", 0.0)])
def test_sidesteps_and_backwards_move_the_right_way(skill, side):
    joints = joints_of(single(skill))
    yaw = heading(joints).mean()
    right, forward = np.array([np.cos(yaw), np.sin(yaw)]), np.array([-np.sin(yaw), np.cos(yaw)])
    travel = joints[-1, 0, :2] - joints[0, 0, :2]
    seconds = (len(joints) - 1) / FPS
    if side:
        assert 0.2 <= side * (travel @ right) / seconds <= 0.45
        assert abs(travel @ forward) < 0.3
    else:
        assert -1.05 <= (travel @ forward) / seconds <= -0.45


def test_transitions_are_labelled_with_both_skills_and_smooth():
    seqs = generate_sequences(LocomotionConfig(num_sequences=4, seconds_per_sequence=12.0, seed=1))
    overlaps = 0
    for i, seq in enumerate(seqs):
        validate_sequence(seq, f"seq{i}.npz")  # segments cover every frame
        skills = [TEXT_TO_SKILL[str(t)] for t in seq["seg_text"]]
        for k in range(len(skills) - 1):
            assert seq["seg_start"][k + 1] < seq["seg_end"][k]  # neighbours overlap over the transition
            assert skills[k + 1] in NEIGHBOURS[skills[k]]
            overlaps += 1
        joints = joints_of(seq)
        assert np.linalg.norm(np.diff(joints, axis=0), axis=-1).max() * FPS < 14.0  # no pops (m/s)
        assert pelvis_speed(joints).max() < 4.5
    assert overlaps >= 8


def test_default_dataset_is_balanced_and_clean():
    cfg = LocomotionConfig()
    seqs = generate_sequences(cfg)
    stats = dataset_statistics(seqs)
    assert 40_000 <= stats["frames"] <= 60_000
    assert 0.12 <= stats["transition_fraction"] <= 0.3
    skills = stats["skills"]
    assert set(skills) == set(LOCOMOTION_SKILLS)  # the default: locomotion alone (scene skills are opt-in)
    single_frames = np.array([s["single_label_frames"] for s in skills.values()])
    assert single_frames.min() > 0.5 * single_frames.mean()
    for name, s in skills.items():
        assert s["skate_cm_s"] < 0.5 and s["skate_xy_cm_s"] < 0.1, name
    assert skills["stand"]["speed_m_s"] < 0.05 < skills["walk"]["speed_m_s"] < skills["run"]["speed_m_s"]


def test_generate_dataset_writes_readable_files_and_meta(tmp_path):
    cfg = LocomotionConfig(num_sequences=3, seconds_per_sequence=4.0, seed=2)
    paths = generate_dataset(cfg, tmp_path)
    assert [p.name for p in paths] == ["seq_00000.npz", "seq_00001.npz", "seq_00002.npz"]
    for p in paths:
        read_sequence(p)
    meta = read_meta(tmp_path)
    assert meta["seed"] == 2 and meta["frames"] == 3 * 4 * FPS
    assert meta["config"]["num_sequences"] == 3 and sum(meta["frames_per_text"].values()) >= meta["frames"]
    assert set(meta["frames_per_skill"]) <= set(SKILLS)
    with pytest.raises(DataError, match="already holds 3 .npz files"):
        generate_dataset(cfg, tmp_path)
    assert len(generate_dataset(LocomotionConfig(num_sequences=1, seconds_per_sequence=2.0), tmp_path,
                                overwrite=True)) == 1
    assert len(list(tmp_path.glob("*.npz"))) == 1


def test_steerable_data_options_steer_unpredictably_and_keep_flights_low():
    # steering: random_hold and flights: low (configs/motion/default.yaml, and every model since v2): the data
    # itself meets the targets for heading variety, floor distance and single support (docs/motion_history.md).
    from latentrl.datasets.locomotion import dataset_statistics

    stats = dataset_statistics(generate_sequences(
        LocomotionConfig(num_sequences=24, steering="random_hold", flights="low")))["skills"]
    old = dataset_statistics(generate_sequences(LocomotionConfig(num_sequences=24)))["skills"]
    for skill in ("walk", "run", "hop_left"):
        assert stats[skill]["steer_spread_deg"] > max(40.0, 1.2 * old[skill]["steer_spread_deg"]), skill
    assert stats["hop_left"]["floor_cm"] <= 5.0 and stats["run"]["floor_cm"] <= 3.0
    assert stats["hop_left"]["left_only"] >= 0.55 and stats["hop_left"]["right_only"] == 0.0
    with pytest.raises(ConfigError, match="steering"):
        LocomotionConfig(steering="zigzag").validate()
