"""DART's noise descent (latentrl.optim.descent): kept minimum, per-env unit gradient, bound, env axis."""

import pytest
import torch

from latentrl.optim.descent import descend


def test_each_env_keeps_its_lowest_loss_and_walks_toward_its_minimum():
    target = torch.tensor([[[0.5, -0.3]], [[-1.0, 2.0]]])  # (N, 1, D)
    seen = []

    def loss_of(z):
        loss = (z - target).flatten(1).square().sum(dim=1)
        seen.append(loss.detach())
        return loss

    kept, kept_loss = descend(torch.zeros(2, 1, 2), loss_of, steps=30, lr=0.2, bound=4.0)
    assert len(seen) == 31
    assert torch.equal(kept_loss, torch.stack(seen).min(dim=0).values)  # the least of every step's loss
    assert torch.allclose((kept - target).flatten(1).square().sum(dim=1), kept_loss)
    assert (kept_loss < 0.05 * seen[0]).all()


def test_a_loss_scaled_by_a_thousand_takes_the_same_steps():
    """DART's unit gradient: a far goal and a near one move at the same pace (Adam's own scaling aside)."""
    target = torch.tensor([[[0.7, 0.2]]])
    runs = []
    for scale in (1.0, 1000.0):
        trace = []

        def loss_of(z, s=scale, t=trace):
            t.append(z.detach().clone())
            return s * (z - target).flatten(1).square().sum(dim=1)

        descend(torch.zeros(1, 1, 2), loss_of, steps=5, lr=0.1, bound=4.0)
        runs.append(torch.stack(trace))
    assert torch.allclose(runs[0], runs[1], atol=1e-6)


def test_plans_share_one_unit_gradient_over_their_primitives_and_stay_in_the_bound():
    """env_dim 1: (S, N, 1, D) plans; each env's gradient over all its primitives has norm 1 before Adam."""
    target = torch.full((3, 2, 1, 4), 9.0)  # beyond the bound

    def loss_of(z):
        return (z - target).square().sum(dim=(0, 2, 3))

    kept, _ = descend(torch.zeros(3, 2, 1, 4), loss_of, steps=200, lr=1.0, bound=2.0, env_dim=1)
    assert kept.shape == (3, 2, 1, 4) and float(kept.max()) == pytest.approx(2.0)


def test_an_env_whose_loss_is_never_finite_keeps_its_start():
    start = torch.tensor([[[0.3]], [[0.1]]])

    def loss_of(z):
        loss = z.flatten(1).square().sum(dim=1)
        return torch.stack((loss[0], loss[1] * float("nan")))

    kept, kept_loss = descend(start, loss_of, steps=3, lr=0.1, bound=4.0)
    assert float(kept[1]) == pytest.approx(0.1) and torch.isinf(kept_loss[1])
    assert float(kept[0].abs()) < 0.3


def test_an_env_axis_other_than_0_or_1_is_refused():
    with pytest.raises(ValueError, match="env_dim must be 0 or 1, got 2"):
        descend(torch.zeros(1, 1, 2), lambda z: z.sum(dim=(1, 2)), steps=1, lr=0.1, bound=1.0, env_dim=2)
