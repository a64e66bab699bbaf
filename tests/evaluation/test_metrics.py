"""Known answers of the evaluation metrics on hand-made motions (metres, z up, 30 fps)."""

import math

import numpy as np
import pytest
import torch

from latentrl.evaluation import metrics as M

FPS = 30.0


def body(frames: int = 31, foot_heights=(0.0, 0.0), height: float = 1.0) -> torch.Tensor:
    """(T, 22, 3): every joint at ``height`` except the two foot joints (10, 11) at ``foot_heights``."""
    j = torch.zeros(frames, 22, 3)
    j[..., 2] = height
    j[:, 10, 2], j[:, 11, 2] = foot_heights
    j[:, 11, 0] = 0.2  # feet side by side
    return j


def slide(joints: torch.Tensor, speed_m_s: float, axis: int = 1) -> torch.Tensor:
    """The whole body translated at ``speed_m_s`` along ``axis``."""
    t = torch.arange(len(joints), dtype=joints.dtype) / FPS
    out = joints.clone()
    out[..., axis] += (speed_m_s * t)[:, None]
    return out


def test_foot_sliding_on_the_floor_skates_at_its_speed():
    # Both feet in contact (weight 1) slide at 0.5 m/s: DART's skate is that speed, in cm/s.
    assert float(M.foot_skate_cm_s(slide(body(), 0.5))) == pytest.approx(50.0, rel=1e-4)


def test_skate_counts_only_feet_in_contact():
    # One foot on the floor, one 10 cm up (weight 0): the mean over the two feet halves the speed.
    assert float(M.foot_skate_cm_s(slide(body(foot_heights=(0.0, 0.10)), 0.5))) == pytest.approx(25.0, rel=1e-4)
    assert float(M.foot_skate_cm_s(slide(body(foot_heights=(0.10, 0.10)), 0.5))) == 0.0


def test_skate_xy_part_separates_sliding_from_lifting():
    # Sliding on the floor: all of DART's skate is horizontal.
    j = slide(body(), 0.5)
    assert float(M.foot_skate_cm_s(j, horizontal=True)) == pytest.approx(float(M.foot_skate_cm_s(j)), rel=1e-5)
    # The left foot rising 1 mm per frame from the floor (inside the 3 cm band), nothing sliding: DART's
    # skate counts the lift (0.1 cm per frame times the contact weight), its xy part is 0.
    lift = body()
    lift[:, 10, 2] = torch.arange(31) * 0.001
    weights = M.foot_skate_weights(lift[:, [10, 11], 2])[:, 0]
    expected = float(weights.mean()) * 0.1 * FPS / 2  # cm per frame times fps, averaged over both feet
    assert float(M.foot_skate_cm_s(lift)) == pytest.approx(expected, rel=1e-4)
    assert float(M.foot_skate_cm_s(lift, horizontal=True)) == 0.0
    assert set(M.episode_metrics(lift)) == set(M.EPISODE_METRICS) - {"pj_seam"}  # 31 frames: no whole clip


def test_skate_weight_is_dart_exponential_ramp():
    # At 1.5 cm (half the 3 cm threshold) the weight is 2 - 2^0.5.
    w = M.foot_skate_weights(torch.full((2, 2), 0.015))
    assert torch.allclose(w, torch.full((1, 2), 2.0 - math.sqrt(2.0)))


def test_standing_still_does_not_skate():
    assert float(M.foot_skate_cm_s(body())) == 0.0


def test_floating_foot_gives_its_height():
    # The lower foot is 5 cm up: DART's floor distance is 5 cm; CLoSD's floating 50 - 5 mm tolerance.
    j = body(foot_heights=(0.05, 0.08))
    assert float(M.foot_floor_distance_cm(j)) == pytest.approx(5.0, rel=1e-5)
    assert float(M.closd_floating_mm(j)) == pytest.approx(45.0, rel=1e-4)
    assert float(M.closd_penetration_mm(j)) == 0.0


def test_penetrating_foot_gives_its_depth():
    j = body(foot_heights=(-0.02, 0.0))
    assert float(M.foot_floor_distance_cm(j)) == pytest.approx(2.0, rel=1e-5)  # |min height|
    assert float(M.closd_penetration_mm(j)) == pytest.approx(15.0, rel=1e-4)
    assert float(M.closd_floating_mm(j)) == 0.0


def test_closd_skating_is_horizontal_displacement_in_contact():
    # Both feet in contact, 0.3 m/s: 10 mm per frame for both feet.
    assert float(M.closd_skating_mm(slide(body(), 0.3, axis=0))) == pytest.approx(10.0, rel=1e-4)
    assert float(M.closd_skating_mm(slide(body(foot_heights=(0.01, 0.01)), 0.3))) == 0.0  # above 5 mm


def test_jerk_of_a_cubic_is_six_times_its_coefficient():
    t = torch.arange(20, dtype=torch.float64) / FPS
    j = body(20).double()
    j[..., 0] += (2.0 * t**3)[:, None]  # x = 2 t^3 -> third derivative 12 m/s^3 for every joint
    assert float(M.jerk(j)) == pytest.approx(12.0, rel=1e-6)
    assert float(M.jerk(slide(body().double(), 1.0))) == pytest.approx(0.0, abs=1e-6)  # constant velocity


def test_episode_metrics_bundle():
    out = M.episode_metrics(slide(body(), 0.5))
    assert set(out) == set(M.EPISODE_METRICS) - {"pj_seam"}  # too short for PJ's 30-frame clips (below)
    assert set(M.episode_metrics(slide(body(66), 0.5))) == set(M.EPISODE_METRICS)
    assert out["skate_cm_s"] == pytest.approx(50.0, rel=1e-4) and out["floor_cm"] == 0.0


def test_final_goal_distance_is_min_over_the_last_eight_frames():
    j = slide(body(40), 3.0)  # pelvis y = 0.1 m per frame
    goal = torch.tensor([0.0, 3.5, 0.0])  # frame 35; the last 8 frames are 32..39
    assert float(M.final_goal_distance_m(j, goal)) == pytest.approx(0.0, abs=1e-5)
    assert float(M.final_goal_distance_m(j[:30], goal)) == pytest.approx(0.6, abs=1e-5)


def test_mean_ci95_known_values():
    out = M.mean_ci95([1.0, 2.0, 3.0, 4.0])
    assert out["mean"] == 2.5
    assert out["ci95"] == pytest.approx(1.96 * math.sqrt(1.25) / 2.0)  # population std, as DART
    assert M.mean_ci95([7.0]) == {"mean": 7.0, "ci95": 0.0}
    assert math.isnan(M.mean_ci95([])["mean"])


def test_dart_aggregation_averages_episode_index_over_paths_first():
    values = np.array([[1.0, 3.0], [3.0, 5.0]])  # 2 paths x 2 episodes; index means 2 and 4
    out = M.dart_mean_ci95(values)
    assert out["mean"] == 3.0 and out["ci95"] == pytest.approx(1.96 * 1.0 / math.sqrt(2))
    with pytest.raises(ValueError, match="paths, episodes"):
        M.dart_mean_ci95([1.0, 2.0])


def test_transition_jerk_curve_is_the_largest_joint_l1_third_difference():
    t = torch.arange(12, dtype=torch.float32)
    j = torch.zeros(12, 22, 3)
    j[:, 5, 0] = 0.002 * t**3  # third difference 0.012 per frame on x
    j[:, 7, 1] = -0.001 * t**3  # a smaller one on another joint
    curve = M.transition_jerk_curve(j)
    assert curve.shape == (9,) and torch.allclose(curve, torch.full((9,), 0.012), atol=1e-5)


def test_peak_jerk_and_area_under_jerk_of_a_pop():
    """A 5 cm jump of the whole body at frame 40: third differences d, -2d, d around it."""
    j = torch.zeros(1, 80, 22, 3)
    j[:, 40:, :, 0] = 0.05
    clips = M.transition_clips(j, [40, 2, 79])  # the two splits too near the ends have no whole clip
    assert clips.shape == (1, 30, 22, 3)
    assert M.peak_jerk(clips) == pytest.approx(0.10)
    assert M.area_under_jerk(clips, reference=0.0) == pytest.approx(0.05 + 0.10 + 0.05)
    assert M.area_under_jerk(clips, reference=0.01) == pytest.approx(0.04 + 0.09 + 0.04 + 24 * 0.01)
    smooth = torch.zeros(1, 80, 22, 3)
    assert M.peak_jerk(M.transition_clips(smooth, [40])) == 0.0


def test_seam_ratios_of_a_rollout_that_pops_at_each_primitive():
    """2 seed frames then 4 primitives of 8: a planted foot creeps 1 cm a frame and jumps 5 cm into each
    primitive; the pelvis accelerates evenly upwards (1 mm/frame^2) and jumps 3 mm sideways at each seam."""
    frames = 2 + 4 * 8
    seam = torch.zeros(frames)
    seam[M.primitive_seams(frames)] = 1.0
    assert M.primitive_seams(frames) == [2, 10, 18, 26]
    j = torch.zeros(frames, 22, 3)
    step = 0.01 + 0.04 * seam  # frame k arrives with this step
    for foot in (10, 11):
        j[:, foot, 0] = torch.cumsum(step, 0)
    t = torch.arange(frames, dtype=torch.float32)
    j[:, 0, 2] = 0.9 + 0.5 * 0.001 * t**2
    j[:, 0, 0] = 0.003 * torch.cumsum(seam, 0)
    r = M.seam_ratios(j)
    assert r["step_boundary_cm"] == pytest.approx(5.0) and r["step_inside_cm"] == pytest.approx(1.0)
    assert r["step_ratio"] == pytest.approx(5.0)
    assert r["pelvis_acc_rest"] == pytest.approx(0.001 * 900, rel=1e-3)
    assert r["pelvis_acc_boundary"] == pytest.approx(math.hypot(0.001, 0.003) * 900, rel=1e-3)
    assert r["pelvis_acc_ratio"] == pytest.approx(math.sqrt(10), rel=1e-3)
    smooth = j.clone()
    smooth[:, 10, 0] = smooth[:, 11, 0] = 0.01 * t
    smooth[:, 0, 0] = 0.0
    r = M.seam_ratios(smooth)
    assert r["step_ratio"] == pytest.approx(1.0) and r["pelvis_acc_ratio"] == pytest.approx(1.0, rel=1e-3)


def test_seam_peak_jerk_is_twice_a_jump_made_at_every_primitive_boundary_and_zero_for_steady_motion():
    """A body gliding at constant speed has no jerk; one that jumps d at the first frame of every primitive has
    a third difference of d, -2d, d around each jump: PJ = 2d (every joint jumps, along x only)."""
    frames = 2 + 8 * 8
    steady = torch.zeros(frames, 22, 3)
    steady[..., 0] = torch.arange(frames, dtype=torch.float32)[:, None] * 0.04
    assert M.seam_peak_jerk(steady) == pytest.approx(0.0, abs=1e-6)
    jumps = torch.zeros(frames, 22, 3)
    for seam in M.primitive_seams(frames):
        jumps[seam:, :, 0] += 0.01
    assert M.seam_peak_jerk(jumps) == pytest.approx(0.02, abs=1e-6)
    assert M.episode_metrics(jumps)["pj_seam"] == pytest.approx(0.02, abs=1e-6)
    assert math.isnan(M.seam_peak_jerk(jumps[:26]))  # no boundary with 15 frames on either side
    assert "pj_seam" not in M.episode_metrics(jumps[:26])
