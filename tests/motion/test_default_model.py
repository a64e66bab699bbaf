"""The embedded default motion model: loads offline, knows its prompts, rolls out stably."""

import pytest
import torch

from latentrl.errors import TextError
from latentrl.evaluation import metrics as M
from latentrl.motion import load_motion_model
from latentrl.motion.text import sentence_encoder_available


@pytest.fixture(scope="module")
def model():
    return load_motion_model("default")


def test_default_model_is_complete(model):
    assert model.latent_shape == (1, 32) and model.text_dim == 384
    assert model.seed_history is not None and model.pelvis_delta is not None
    assert {"walk", "run", "hop on left leg", "hop on right leg", "stand still", "turn left"} <= set(
        model.text_encoder.prompts)
    assert model.info["format"] == "latentrl.motion_model" and model.info["config"]["seed"] == 0


def test_unseen_prompt_needs_the_text_extra(model):
    if sentence_encoder_available():
        assert model.encode_text(["amble along slowly"]).shape == (1, 384)
    else:
        with pytest.raises(TextError, match=r"latentrl\[text\]"):
            model.encode_text(["amble along slowly"])


def test_text_controls_speed_and_standing(model):
    g = torch.Generator().manual_seed(0)
    speeds = {}
    for text in ("walk", "run", "stand still"):
        roll = model.rollout(text, num_steps=12, batch=4, generator=g)
        assert torch.isfinite(roll.joints_world).all()
        speeds[text] = float(M.pelvis_speed_m_s(roll.joints_world[:, 10:]).mean())
    assert speeds["run"] > speeds["walk"] > speeds["stand still"]
    assert speeds["stand still"] < 0.1


def test_the_noise_steers_walking_and_running(model):
    # What a reach policy works with: with only the noise differing, headings must spread.
    # The first release measured 11 (walk) and 5 (run) degrees; the shipped model 13.6 and 10.8.
    from latentrl.app.bench.motion import steering_spread_deg

    assert steering_spread_deg(model, "walk", batch=64) > 10.0
    assert steering_spread_deg(model, "run", batch=64) > 8.0
