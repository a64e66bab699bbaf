"""`latentrl bench motion`'s transition figures: DART's PJ/AUJ and the pops at primitive boundaries."""

import pytest
import torch

from latentrl.app.bench.motion import _data_transitions, skill_switch_seconds, transition_figures
from latentrl.evaluation import metrics as M


def test_transition_figures_of_a_pop_and_without_a_reference():
    j = torch.zeros(2, 60, 22, 3)
    j[:, 30:, :, 1] = 0.02  # a 2 cm jump of the whole body at frame 30
    fig = transition_figures(j, [30], jerk_reference=0.0)
    assert fig["clips"] == 2 and fig["pj"] == pytest.approx(0.04) and fig["auj"] == pytest.approx(0.08)
    assert transition_figures(j, [30], None)["auj"] is None  # no data, no AUJ
    assert transition_figures(j, [3], 0.0) == {"pj": None, "auj": None, "clips": 0}


def test_data_transitions_score_a_seamless_motion_about_one():
    """Hand-made data: a foot planted for 6 frames, then a 4-frame swing, over and over; the pelvis sways.
    The data has no primitives, so its boundary frames are ordinary frames: a pelvis ratio near 1, still feet."""
    t = torch.arange(400, dtype=torch.float32)
    j = torch.zeros(400, 22, 3)
    phase = t % 10
    swing = (phase >= 6).float()
    j[:, 10, 0] = 0.1 * torch.cumsum(swing, 0)  # moves 10 cm a frame in swing, still in stance
    j[:, 10, 2] = 0.05 * swing  # lifted in swing
    j[:, 11] = j[:, 10] + torch.tensor([0.3, 0.0, 0.0])
    j[:, 0, 0] = 0.04 * t
    j[:, 0, 1] = 0.05 * torch.sin(t * 0.7)
    j[:, 0, 2] = 0.9
    seqs = [{"joints": j.numpy(), "seg_start": [0, 200], "seg_end": [200, 400], "seg_text": ["walk", "walk"]}]
    d = _data_transitions(seqs)
    assert d["text_splits"] == 1 and d["jerk_reference"] > 0
    assert d["pelvis_acc_ratio"] == pytest.approx(1.0, abs=0.1)
    assert d["step_boundary_cm"] == 0.0 and d["step_inside_cm"] == 0.0  # planted feet that do not move
    assert d["text_auj"] == pytest.approx(float((M.transition_jerk_curve(j[185:215]) - d["jerk_reference"])
                                                .abs().sum()), rel=1e-5)


def test_skill_switch_reports_dart_transition_jerk(tiny_model):
    sw = skill_switch_seconds(tiny_model, batch=2, jerk_reference=0.05)
    tt = sw["text_transitions"]
    assert tt["clips"] == 2 * 3 and tt["pj"] > 0 and tt["auj"] > 0
