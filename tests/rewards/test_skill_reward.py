"""The ``skill`` term on hand-made steps with known answers: it is 0 exactly where the evaluation's rule passes."""

import pytest
import torch

from latentrl.errors import ConfigError
from latentrl.motion.skeleton import FOOT_JOINTS, PELVIS
from latentrl.rewards import RewardComposer, RewardConfig, RewardInputs, terms
from latentrl.rewards.skills import SKILLS, matches, skill_code, skill_of

STEP_S = 8 / 30
RUN, WALK, HOP_LEFT, HOP_RIGHT = (SKILLS.index(s) + 1 for s in SKILLS)


def step(speed: float, left_down: int, right_down: int, n_frames: int = 8) -> tuple:
    """Pelvis before/after a step at ``speed`` m/s along x, and feet heights with the left foot on the floor in
    the first ``left_down`` frames and the right foot in the last ``right_down`` frames (else 20 cm up)."""
    before = torch.tensor([[0.0, 0.0, 0.9]])
    after = before + torch.tensor([[speed * STEP_S, 0.0, 0.0]])
    height = torch.full((1, n_frames, 2), 0.2)
    height[0, :left_down, 0] = 0.0
    height[0, n_frames - right_down:, 1] = 0.0
    return before, after, height


def fidelity(code: int, speed: float, left_down: int = 4, right_down: int = 4) -> float:
    before, after, height = step(speed, left_down, right_down)
    return float(terms.skill_fidelity(before, after, height, torch.tensor([code]), STEP_S))


def test_prompts_map_to_families_and_codes():
    assert [skill_of(t) for t in ("walk", "run forward", "hop on left leg", "hop on right leg", "wave")] == [
        "walk", "run", "hop_left", "hop_right", None]
    assert [skill_code(t) for t in ("run", "walk", "hop on left leg", "hop on right leg", "jump")] == [1, 2, 3, 4, 0]
    assert RewardComposer.skill_codes(["walk", "dance"]).tolist() == [2, 0]


@pytest.mark.parametrize("speed, expected", [(1.2, 0.0), (0.2, -0.3), (2.6, -0.6), (0.5, 0.0)])
def test_walk_pays_the_speed_outside_the_walk_band(speed, expected):
    assert fidelity(WALK, speed) == pytest.approx(expected, abs=1e-5)


@pytest.mark.parametrize("speed, expected", [(3.1, 0.0), (2.0, 0.0), (1.2, -0.8)])
def test_run_pays_the_speed_below_the_run_threshold(speed, expected):
    assert fidelity(RUN, speed) == pytest.approx(expected, abs=1e-5)


def test_hop_pays_for_too_little_stance_and_for_the_other_foot():
    # left foot alone in all 8 frames: a clean left hop
    assert fidelity(HOP_LEFT, 0.8, left_down=8, right_down=0) == 0.0
    # stepping: left alone 4/8, right alone 4/8 -> other foot 0.5 - 0.1
    assert fidelity(HOP_LEFT, 0.8, left_down=4, right_down=4) == pytest.approx(-0.4)
    # flight most of the step: left alone 2/8 -> stance 0.4 - 0.25
    assert fidelity(HOP_LEFT, 0.8, left_down=2, right_down=0) == pytest.approx(-0.15)
    # mirrored: the same clean left hop is all wrong for "hop on right leg"
    assert fidelity(HOP_RIGHT, 0.8, left_down=8, right_down=0) == pytest.approx(-(0.4 + 0.9))
    # texts the rule does not judge pay nothing, whatever the motion
    assert fidelity(0, 9.0, left_down=4, right_down=4) == 0.0


@pytest.mark.parametrize("code, speed, left_down, right_down", [
    (WALK, 1.0, 4, 4), (WALK, 2.4, 4, 4), (RUN, 1.5, 3, 3), (RUN, 3.0, 3, 3),
    (HOP_LEFT, 0.6, 8, 0), (HOP_LEFT, 0.6, 3, 0), (HOP_LEFT, 0.6, 5, 2), (HOP_RIGHT, 0.6, 0, 6),
])
def test_the_term_is_zero_exactly_where_the_judge_passes(code, speed, left_down, right_down):
    _, _, height = step(speed, left_down, right_down)
    down = height[0] <= 0.05
    left_only = float((down[:, 0] & ~down[:, 1]).float().mean())
    right_only = float((down[:, 1] & ~down[:, 0]).float().mean())
    passes = matches(SKILLS[code - 1], speed, left_only, right_only)
    assert (fidelity(code, speed, left_down, right_down) == 0.0) == passes


def alternating_step(texts: list[str], speed: float) -> RewardInputs:
    """One env per text, its pelvis moving at ``speed`` m/s along x over 2 history + 8 new frames, the left foot
    down in new frames 0-3 and the right in 4-7 (else 20 cm up)."""
    n = len(texts)
    joints = torch.zeros(n, 10, 22, 3)
    joints[:, :, PELVIS, 0] = torch.linspace(0, speed * 9 / 30, 10)
    joints[:, :, PELVIS, 2] = 0.9
    joints[:, :, list(FOOT_JOINTS), 2] = 0.2
    joints[:, 2:6, FOOT_JOINTS[0], 2] = 0.0
    joints[:, 6:, FOOT_JOINTS[1], 2] = 0.0
    return RewardInputs(joints, torch.zeros(n, 3), torch.zeros(n, dtype=torch.bool), torch.ones(n),
                        skill=RewardComposer.skill_codes(texts))


def test_composer_reads_the_feet_of_the_new_frames_and_weights_the_term():
    """Two envs stepping at 1.2 m/s with alternating feet: fine for "walk", a miss for "hop on left leg"."""
    x = alternating_step(["walk", "hop on left leg"], 1.2)
    total_off, values = RewardComposer(terms=("dist", "skill"))(x)
    total_on, _ = RewardComposer(weights={"skill": 2.0}, terms=("dist", "skill"))(x)
    assert torch.allclose(values["skill"], torch.tensor([0.0, -0.4]))
    assert torch.allclose(total_on - total_off, torch.tensor([0.0, -0.8]))


def test_skill_scale_multiplies_the_term_of_one_family_only():
    """``skill_scale: {hop_left: 10}`` makes the hop's miss 10x dearer and leaves walk, run and unjudged texts."""
    x = alternating_step(["walk", "run", "hop on left leg", "wave"], 0.2)  # 0.2 m/s: too slow to walk or run
    _, plain = RewardComposer(terms=("skill",))(x)
    _, scaled = RewardComposer(RewardConfig(skill_scale={"hop_left": 10}), terms=("skill",))(x)
    assert torch.allclose(plain["skill"], torch.tensor([-0.3, -1.8, -0.4, 0.0]), atol=1e-5)
    assert torch.allclose(scaled["skill"], torch.tensor([-0.3, -1.8, -4.0, 0.0]), atol=1e-5)


@pytest.mark.parametrize("scale, match", [({"hop_leftt": 2.0}, "did you mean 'hop_left'"),
                                          ({"run": -1.0}, "skill_scale.run"), ({"walk": float("nan")}, "finite")])
def test_skill_scale_rejects_unknown_families_and_bad_numbers(scale, match):
    with pytest.raises(ConfigError, match=match):
        RewardComposer(RewardConfig(skill_scale=scale), terms=("skill",))


def test_skill_term_without_skill_codes_names_what_is_missing():
    x = RewardInputs(torch.zeros(1, 10, 22, 3), torch.zeros(1, 3), torch.zeros(1, dtype=torch.bool), torch.ones(1))
    with pytest.raises(ValueError, match="RewardInputs.skill"):
        RewardComposer(terms=("skill",))(x)
