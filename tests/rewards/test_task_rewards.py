"""The Joystick and TimedPath terms on hand-made pelvis motions with known answers, and per-task composition."""

import math

import pytest
import torch

from latentrl.errors import ConfigError
from latentrl.rewards import DART_TERMS, DEFAULT_WEIGHTS, TERM_NAMES, RewardComposer, RewardConfig, RewardInputs, terms
from tests.rewards.test_reward_compose import gliding_body

STEP_S = 8 / 30


def pelvis_move(direction_deg: float, speed: float) -> tuple[torch.Tensor, torch.Tensor]:
    """(1, 3) pelvis before and after one step moving at ``speed`` m/s toward ``direction_deg`` (from +x)."""
    a = math.radians(direction_deg)
    before = torch.tensor([[1.0, 2.0, 0.9]])
    after = before + torch.tensor([[math.cos(a), math.sin(a), 0.0]]) * speed * STEP_S
    return before, after


def heading(deg: float) -> torch.Tensor:
    return torch.tensor([[math.cos(math.radians(deg)), math.sin(math.radians(deg))]])


def test_heading_is_max_along_the_command_half_at_90_degrees_and_zero_opposite():
    for off, expected in ((0.0, 1.0), (90.0, 0.5), (-90.0, 0.5), (180.0, 0.0), (60.0, 0.75)):
        before, after = pelvis_move(30.0 + off, 1.2)
        torch.testing.assert_close(terms.heading_tracking(before, after, heading(30.0)), torch.tensor([expected]))
    before, _ = pelvis_move(0.0, 0.0)
    torch.testing.assert_close(terms.heading_tracking(before, before, heading(0.0)), torch.tensor([0.5]))


def test_speed_is_zero_at_the_commanded_speed_whatever_the_direction():
    for direction in (0.0, 90.0, 200.0):
        before, after = pelvis_move(direction, 1.2)
        torch.testing.assert_close(terms.speed_tracking(before, after, torch.tensor([1.2]), STEP_S),
                                   torch.tensor([0.0]), atol=1e-5, rtol=0)
    before, after = pelvis_move(0.0, 0.7)
    torch.testing.assert_close(terms.speed_tracking(before, after, torch.tensor([1.2]), STEP_S), torch.tensor([-0.5]))


def test_pace_counts_only_the_speed_toward_the_goal():
    before, after = pelvis_move(90.0, 1.5)
    goal = before + torch.tensor([[0.0, 4.0, 0.0]])  # straight ahead (+y)
    target = torch.tensor([1.5])
    torch.testing.assert_close(terms.pace_tracking(before, after, goal, target, STEP_S), torch.tensor([0.0]),
                               atol=1e-5, rtol=0)
    side = before + torch.tensor([[4.0, 0.0, 0.0]])  # the goal at 90 degrees: no progress toward it
    torch.testing.assert_close(terms.pace_tracking(before, after, side, target, STEP_S), torch.tensor([-1.5]))
    torch.testing.assert_close(terms.pace_tracking(before, after, goal, torch.tensor([1.0]), STEP_S),
                               torch.tensor([-0.5]))  # 0.5 m/s too fast


def test_timing_bonus_falls_linearly_to_zero_at_the_tolerance():
    reached = torch.tensor([True, True, True, True, False])
    error = torch.tensor([0.0, 0.25, -0.5, 2.0, 0.0])
    torch.testing.assert_close(terms.arrival_timing(reached, error, 1.0), torch.tensor([1.0, 0.75, 0.5, 0.0, 0.0]))


def test_joystick_terms_in_the_composer_on_a_gliding_body():
    body = gliding_body(0.04)  # 4 cm per frame along +y = 1.2 m/s
    command = torch.tensor([[0.0, 1.0, 1.2]])
    x = RewardInputs(body, torch.zeros(1, 3), torch.tensor([False]), torch.ones(1), command=command)
    comp = RewardComposer(terms=("heading", "speed", "skate"))
    total, values = comp(x)
    assert list(values) == ["heading", "speed", "skate"]
    torch.testing.assert_close(values["heading"], torch.tensor([1.0]))
    torch.testing.assert_close(values["speed"], torch.tensor([0.0]), atol=1e-5, rtol=0)
    torch.testing.assert_close(total, values["heading"] + values["speed"] + 100 * values["skate"])
    side = RewardInputs(body, torch.zeros(1, 3), torch.tensor([False]), torch.ones(1),
                        command=torch.tensor([[1.0, 0.0, 1.2]]))  # commanded +x: the body moves 90 degrees off
    torch.testing.assert_close(comp(side)[1]["heading"], torch.tensor([0.5]))


def test_a_term_without_its_task_input_names_what_is_missing():
    x = RewardInputs(gliding_body(0.01), torch.zeros(1, 3), torch.tensor([False]), torch.ones(1))
    with pytest.raises(ValueError, match="'speed' needs RewardInputs.command"):
        RewardComposer(terms=("speed",))(x)


def test_task_term_sets_and_overrides():
    assert TERM_NAMES[: len(DART_TERMS)] == DART_TERMS and tuple(DEFAULT_WEIGHTS) == TERM_NAMES
    assert tuple(RewardComposer().weights) == DART_TERMS
    comp = RewardComposer(RewardConfig(timing_tolerance=2.0), {"timing": 3.0}, terms=("dist", "timing"))
    assert comp.weights == {"dist": 1.0, "timing": 3.0} and comp.config.timing_tolerance == 2.0
    with pytest.raises(ConfigError, match="the task has no reward term 'dist'"):
        RewardComposer(weights={"dist": 1.0}, terms=("heading", "speed"))
    with pytest.raises(ConfigError, match="timing_tolerance"):
        RewardComposer(RewardConfig(timing_tolerance=0.0))


def test_noise_prior_is_free_inside_the_prior_and_grows_outside():
    from latentrl.rewards.terms import noise_prior

    a = torch.stack((torch.zeros(32), torch.ones(32), torch.full((32,), 2.0), torch.full((32,), -4.0)))
    assert torch.allclose(noise_prior(a), torch.tensor([0.0, 0.0, -3.0, -15.0]))
    draws = torch.randn(4096, 32, generator=torch.Generator().manual_seed(0))
    assert float(noise_prior(draws).mean()) > -0.15  # a typical N(0, I) draw costs (almost) nothing


def test_every_task_reports_prior_and_weights_it_into_the_reward():
    from latentrl.rewards.compose import RewardComposer, RewardInputs

    joints = torch.zeros(2, 10, 22, 3)
    joints[..., 2] = 0.9
    x = RewardInputs(joints, torch.zeros(2, 3), torch.zeros(2, dtype=torch.bool), torch.ones(2),
                     actions=torch.stack((torch.zeros(32), torch.full((32,), 3.0))))
    off = RewardComposer(terms=("dist", "prior"))
    on = RewardComposer(weights={"prior": 0.5}, terms=("dist", "prior"))
    total_off, values = off(x)
    total_on, _ = on(x)
    assert torch.allclose(values["prior"], torch.tensor([0.0, -8.0]))
    assert torch.allclose(total_on - total_off, torch.tensor([0.0, -4.0]))
