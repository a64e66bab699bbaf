"""`latentrl bench motion`'s scene-skill rows: they run where the model knows the prompts, and only there."""

import copy

import numpy as np
import pytest
import torch

from latentrl.app.bench.motion import (
    NOT_IN_MODEL,
    SKILL_CHECK_NAMES,
    SKILL_PROMPTS,
    prompt_known,
    skill_checks,
    skill_figures,
)
from latentrl.datasets.locomotion import LocomotionConfig, generate_sequences
from latentrl.evaluation import skill_checks as S

ALL_PROMPTS = [p for prompts in SKILL_PROMPTS.values() for p in prompts]


@pytest.fixture(scope="module")
def skilled_model(tiny_model):
    """The tiny model with every skill prompt in its table (random weights: the plumbing, not the skills)."""
    model = copy.deepcopy(tiny_model)
    model.text_encoder = model.text_encoder.extended(ALL_PROMPTS)
    return model


def test_rows_of_a_model_without_the_prompts_say_so_and_count_neither_way(tiny_model):
    assert not any(prompt_known(tiny_model, p) for p in ALL_PROMPTS)  # its table: walk, run, hop on left leg
    rows = skill_figures(tiny_model, batch=2)
    assert set(rows) == set(SKILL_PROMPTS)
    assert all(r["status"] == NOT_IN_MODEL and "ok" not in r for r in rows.values())
    assert skill_checks(rows) == {}


def test_the_shipped_default_model_lacks_the_skill_prompts():
    from latentrl.motion.checkpoint import load_motion_model

    model = load_motion_model("default")
    assert prompt_known(model, "walk") and prompt_known(model, "hop on left leg")
    rows = skill_figures(model, batch=1)  # no prompt known: nothing is rolled out
    assert all(r["status"] == NOT_IN_MODEL for r in rows.values())


def test_rows_run_on_a_model_that_knows_the_prompts(skilled_model):
    snap, lock = skilled_model.floor_snap, skilled_model.foot_lock
    rows = skill_figures(skilled_model, batch=3, reach_samples=4)
    assert (skilled_model.floor_snap, skilled_model.foot_lock) == (snap, lock)  # stairs put them back
    assert all("status" not in r and isinstance(r["ok"], bool) for r in rows.values())
    assert np.isfinite(rows["crouch"]["depth_m"]) and 0.0 <= rows["sit"]["seated"] <= 1.0
    assert rows["sit"]["seat_heights_m"] == pytest.approx([0.2, 0.4, 0.6])
    assert rows["reach"]["targets"] == 2 * 4 * 2 and rows["reach"]["samples"] == 4
    assert all(np.isfinite(rows["stairs"][k]["penetration_m"]) for k in ("up", "down"))
    assert 0.0 <= rows["wave"]["waving"] <= 1.0
    checks = skill_checks(rows)
    assert set(checks) == set(SKILL_CHECK_NAMES.values())
    assert all(checks[SKILL_CHECK_NAMES[n]] == rows[n]["ok"] for n in rows)


def test_reach_counts_the_best_of_its_noises(skilled_model):
    rows = skill_figures(skilled_model, batch=1, reach_samples=6)["reach"]
    g = torch.Generator().manual_seed(0)
    state = skilled_model.initial_state(6, g, seed_index=torch.zeros(6, dtype=torch.long))
    j = skilled_model.rollout("reach with the left hand", 8, batch=6, generator=g, state=state).joints_world
    target = S.reach_target(j[0, 1], 0, "forward", 0.7)  # the first target: left hand, forward, 0.7 arm
    each = S.reach_check(j, target.expand(6, 3), 0)["distance_m"]
    assert rows["best_distance_m"][0] == pytest.approx(float(each.min()))
    assert float(each.max()) > float(each.min())  # the noises differ; the best one counts


def test_the_checks_pass_the_data_they_are_built_from():
    """The crouch and wave checks the rows use, on generated data (what a model that learnt the skills makes)."""
    from latentrl.datasets.locomotion.config import TEXT_TO_SKILL

    seqs = generate_sequences(LocomotionConfig(num_sequences=4, seconds_per_sequence=4.0, seed=0,
                                               skills=("stand", "crouch", "wave")))
    found = {"crouch": [], "wave": []}
    for seq in seqs:
        joints = torch.from_numpy(seq["joints"].astype(np.float64))
        standing = float(seq["rest_joints"][0, 2])
        for a, b, text in zip(seq["seg_start"], seq["seg_end"], seq["seg_text"]):
            clip, skill = joints[int(a):int(b)], TEXT_TO_SKILL[str(text)]
            if skill == "crouch" and b - a >= 30:
                found["crouch"].append(bool(S.crouch_depth(clip, standing) >= S.CROUCH_MIN_DROP_M))
            if skill == "wave" and b - a >= 60:
                r = max((S.wave_check(clip, hand) for hand in (0, 1)), key=lambda x: float(x["raised"]))
                found["wave"].append(bool(r["raised"] >= S.WAVE_MIN_RAISED
                                          and S.WAVE_SWING_HZ[0] <= r["swings_hz"] <= S.WAVE_SWING_HZ[1]))
    assert len(found["crouch"]) >= 2 and len(found["wave"]) >= 2
    assert all(found["crouch"]) and all(found["wave"])
