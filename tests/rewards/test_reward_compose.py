"""The composer: names, weights, thresholds and the weighted sum, on a hand-made body motion."""

import math

import pytest
import torch

from latentrl.errors import ConfigError
from latentrl.rewards import DART_TERMS, DEFAULT_WEIGHTS, TERM_NAMES, RewardComposer, RewardConfig, RewardInputs
from tests.helpers import rest_joints


def gliding_body(speed_per_frame: float, frames: int = 10, lift: float = 0.0) -> torch.Tensor:
    """(1, frames, 22, 3): the rest body translated along +y, feet ``lift`` metres above z = 0."""
    rest = rest_joints()
    rest = rest - torch.tensor([0.0, 0.0, float(rest[:, 2].min())]) + torch.tensor([0.0, 0.0, lift])
    shift = torch.zeros(frames, 1, 3)
    shift[:, 0, 1] = speed_per_frame * torch.arange(frames)
    return (rest[None] + shift)[None]


def inputs(joints: torch.Tensor, goal=(0.0, 5.0, 0.0), reached=False, scale=1.0) -> RewardInputs:
    n = joints.shape[0]
    return RewardInputs(joints, torch.tensor([goal]).expand(n, 3), torch.tensor([reached] * n), torch.full((n,), scale))


def test_defaults_are_darts_readme_weights():
    comp = RewardComposer()
    assert comp.weights == {
        "dist": 1.0,
        "success": 1.0,
        "foot_floor": 100.0,
        "skate": 100.0,
        "orient": 0.1,
        "rotation": 10.0,
        "jerk": 0.0,
    }
    assert tuple(comp.weights) == DART_TERMS == TERM_NAMES[:7] and tuple(DEFAULT_WEIGHTS) == TERM_NAMES


def test_gliding_body_toward_goal_known_terms():
    # the whole body (feet on the floor) glides 2 cm per frame toward a goal straight ahead
    total, terms = RewardComposer()(inputs(gliding_body(0.02)))
    assert set(terms) == set(DART_TERMS)
    torch.testing.assert_close(terms["dist"], torch.tensor([0.02 * 8]))  # last history frame -> last new frame
    torch.testing.assert_close(terms["orient"], torch.tensor([1.0]))
    torch.testing.assert_close(terms["rotation"], torch.tensor([0.0]))
    torch.testing.assert_close(terms["jerk"], torch.tensor([0.0]), atol=1e-6, rtol=0)
    # toe joints sit 5 mm below the ankle offset in the helper skeleton: the lowest joint is a toe, on the floor
    torch.testing.assert_close(terms["foot_floor"], torch.tensor([0.0]))
    torch.testing.assert_close(terms["skate"], torch.tensor([-0.02]))  # both feet in contact slide 2 cm per frame
    expected = 0.16 + 0.1 * 1.0 + 100 * -0.02
    torch.testing.assert_close(total, torch.tensor([expected]))


def test_floating_body_is_penalised_and_hop_run_scaling_applies():
    lifted = inputs(gliding_body(0.0, lift=0.13))
    _, terms = RewardComposer()(lifted)
    torch.testing.assert_close(terms["foot_floor"], torch.tensor([-0.10]))
    assert terms["skate"].item() == 0.0
    _, scaled = RewardComposer()(inputs(gliding_body(0.0, lift=0.13), scale=0.1))
    torch.testing.assert_close(scaled["foot_floor"], torch.tensor([-0.01]))


def test_success_and_weights_override():
    comp = RewardComposer(weights={"success": 10.0, "skate": 0.0, "dist": 0.0, "orient": 0.0})
    total, terms = comp(inputs(gliding_body(0.02), reached=True))
    assert terms["success"].item() == 1.0
    torch.testing.assert_close(total, torch.tensor([10.0]))
    # overrides merge over the config's weights, which merge over the defaults
    comp = RewardComposer(RewardConfig(weights={"jerk": 2.0}), weights={"dist": 3.0})
    assert comp.weights["jerk"] == 2.0 and comp.weights["dist"] == 3.0 and comp.weights["skate"] == 100.0


def test_total_is_the_weighted_sum_of_reported_terms():
    joints = gliding_body(0.03) + 0.01 * torch.randn(1, 10, 22, 3, generator=torch.Generator().manual_seed(0))
    comp = RewardComposer(weights={"jerk": 0.5})
    total, terms = comp(inputs(joints.expand(3, -1, -1, -1).clone()))
    manual = sum(comp.weights[k] * v for k, v in terms.items())
    torch.testing.assert_close(total, manual)
    assert total.shape == (3,) and total.dtype == torch.float32


def test_floor_scales_follow_darts_substring_rule():
    scales = RewardComposer().floor_scales(["walk", "run", "hop on left leg", "Hop and RUN"])
    torch.testing.assert_close(scales, torch.tensor([1.0, 0.1, 0.1, 0.01]))


def test_unknown_term_is_an_error_with_a_suggestion():
    with pytest.raises(ConfigError, match=r"weights: unknown reward term 'skat' \(did you mean 'skate'\?\)"):
        RewardComposer(weights={"skat": 1.0})


@pytest.mark.parametrize(
    "field,value", [("contact_threshold", -0.01), ("floor_scale", -1.0), ("contact_threshold", math.nan)]
)
def test_negative_or_nan_thresholds_are_errors(field, value):
    with pytest.raises(ConfigError, match=field):
        RewardComposer(RewardConfig(**{field: value}))


def test_non_finite_weight_is_an_error():
    with pytest.raises(ConfigError, match=r"weights.dist: must be a finite number"):
        RewardComposer(weights={"dist": math.inf})
