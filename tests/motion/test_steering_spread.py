"""The steering diagnostic of `latentrl bench motion`: how far the action noise can turn a prompt."""

import math

import torch

from latentrl.app.bench.motion import steering_spread_deg
from latentrl.motion.rollout import MotionModel


def test_spread_is_finite_nonnegative_and_reproducible(tiny_model):
    a = steering_spread_deg(tiny_model, "walk", batch=16, steps=2, seed=3)
    b = steering_spread_deg(tiny_model, "walk", batch=16, steps=2, seed=3)
    assert math.isfinite(a) and a >= 0.0
    assert a == b


def test_noise_that_cannot_reach_the_motion_gives_zero_spread(tiny_model, monkeypatch):
    # A denoiser that ignores its input makes every sequence identical: nothing to steer with.
    original = MotionModel.sample_primitive

    def ignore_noise(self, history, text, noise, *args, **kwargs):
        return original(self, history, text, torch.zeros_like(noise), *args, **kwargs)

    monkeypatch.setattr(MotionModel, "sample_primitive", ignore_noise)
    assert steering_spread_deg(tiny_model, "walk", batch=16, steps=2) < 1e-3
