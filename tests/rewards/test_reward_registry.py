"""One reward-term registry: every term's kernel, default weight and inputs in ``REWARD_TERMS``."""

from __future__ import annotations

import pytest
import torch

from latentrl.rewards import DART_TERMS, DEFAULT_WEIGHTS, REWARD_TERMS, TERM_NAMES, RewardComposer, RewardInputs
from latentrl.rewards.compose import RewardConfig, reward_term


def test_the_names_and_default_weights_come_from_the_registry():
    assert TERM_NAMES == tuple(REWARD_TERMS)
    assert DEFAULT_WEIGHTS == {name: term.weight for name, term in REWARD_TERMS.items()}
    assert TERM_NAMES[: len(DART_TERMS)] == DART_TERMS
    assert REWARD_TERMS["heading"].inputs == ("command",) and REWARD_TERMS["dist"].inputs == ()


def _inputs(n: int = 2, **extra) -> RewardInputs:
    joints = torch.zeros(n, 10, 22, 3)
    joints[:, 2:, 0, 1] = torch.linspace(0.1, 0.8, 8)  # the pelvis moves 0.8 m along +y
    return RewardInputs(joints, torch.tensor([[0.0, 5.0, 0.0]] * n), torch.zeros(n, dtype=torch.bool),
                        torch.ones(n), **extra)


@pytest.fixture
def lift():
    """A term registered from outside the package: the pelvis's forward displacement, needing the actions."""

    @reward_term("lift", 2.0, inputs=("actions",))
    def _lift(x: RewardInputs, cfg: RewardConfig) -> torch.Tensor:
        before, after = x.pelvis_before_after()
        return after[:, 1] - before[:, 1]

    yield
    del REWARD_TERMS["lift"]


def test_a_registered_term_is_weighted_reported_and_checked(lift):
    composer = RewardComposer(terms=("dist", "lift"))
    assert composer.weights == {"dist": 1.0, "lift": 2.0}
    total, values = composer(_inputs(actions=torch.zeros(2, 4)))
    assert torch.allclose(values["lift"], torch.full((2,), 0.8))
    assert torch.allclose(total, values["dist"] + 2.0 * values["lift"])
    assert RewardComposer(RewardConfig(weights={"lift": 0.5}), terms=("lift",)).weights == {"lift": 0.5}
    with pytest.raises(ValueError, match="'lift' needs RewardInputs.actions"):
        composer(_inputs())
