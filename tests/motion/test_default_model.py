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
    # What a reach policy works with: with only the noise differing, headings must spread. Measured over
    # 60 s: v1 13.6 (walk) and 10.8 (run) degrees, v2 30.6 and 28.5, v5 (the default) 42.4 and 47.1.
    from latentrl.app.bench.motion import steering_spread_deg

    assert steering_spread_deg(model, "walk", batch=64) > 35.0
    assert steering_spread_deg(model, "run", batch=64) > 30.0


def test_ten_seconds_stay_on_the_floor_and_hops_keep_to_one_foot(model):
    # The rollout's floor snap keeps every prompt on the floor (the model alone sank hops by 0.5 m in
    # 60 s); hopping on the left leg keeps the right foot off the floor.
    g = torch.Generator().manual_seed(0)
    for text in ("walk", "hop on left leg", "jump forward"):
        roll = model.rollout(text, num_steps=38, batch=4, generator=g)
        lowest = roll.joints_world[:, 2:, :, 2].amin(dim=-1)
        assert float(lowest.min()) > -0.01, text  # never under the floor
        pelvis = roll.joints_world[:, 2:, 0, 2]
        # neither sunk nor floating: the data's pelvis range +-10 cm is 0.50-1.19 m; v2's jump crouches
        # to ~0.45 m (docs/benchmarks.md, a target it misses), so the jump gets a looser floor
        assert float(pelvis.min()) > (0.4 if text == "jump forward" else 0.5), text
        assert float(pelvis.max()) < 1.3, text
        if text == "hop on left leg":
            shares = M.foot_contact_shares(roll.joints_world[:, 2:])
            assert float(shares["left_only"].mean()) > 0.2 > 0.05 > float(shares["right_only"].mean())


def test_switching_text_from_walk_to_run_shows_within_a_second(model):
    from latentrl.app.bench.motion import skill_switch_seconds

    switch = skill_switch_seconds(model, batch=4)
    to_run = switch["switches"][0]
    assert to_run["to"] == "run" and to_run["within_1s"] >= 0.75
    assert switch["deepest_below_floor_cm"] <= 1.0


def test_the_default_is_v5_and_the_only_model_shipped(model):
    # "default" is v5 since 2026-11-26 (configs/motion/default.yaml: the wider VAE with the planted-foot loss) and
    # "default-v5" names the same file; the models before it left the package (zoo/README.md) and their names
    # say which file to restore instead of loading another model.
    from latentrl.errors import CheckpointError
    from latentrl.motion.checkpoint import EMBEDDED_MODELS, RETIRED_MODELS, default_model_path

    assert default_model_path("default") == default_model_path("default-v5")
    assert set(EMBEDDED_MODELS.values()) == {"default_motion.pt"}
    assert sorted(p.name for p in default_model_path().parent.glob("*.pt")) == ["default_motion.pt"]
    assert model.info["config"]["vae_train"]["plant_weight"] == 100.0
    assert model.info["config"]["model"]["vae"]["h_dim"] == 256
    for name, (file, _) in RETIRED_MODELS.items():
        with pytest.raises(CheckpointError, match=file):
            load_motion_model(name)


def test_hopping_keeps_to_the_named_leg(model):
    # docs/benchmarks.md "v5": the named foot alone in 0.95 (left) and 0.90 (right) of the frames over 60 s
    # (v2, the default before it: 0.63 and 0.53, its right hop often starting on the left leg). Issue 13's
    # target is 0.6; these floors catch a regression.
    def shares(text):
        roll = model.rollout(text, num_steps=30, batch=4, generator=torch.Generator().manual_seed(0))
        return M.foot_contact_shares(roll.joints_world[:, 2:])

    left, right = shares("hop on left leg"), shares("hop on right leg")
    assert float(left["left_only"].mean()) > 0.6 and float(left["right_only"].max()) < 0.05
    assert float(right["right_only"].mean()) > 0.6 and float(right["left_only"].max()) < 0.05


def test_v5_steers_walk_far_and_hops_low_on_one_foot(model):
    """``default-v5`` (the default since 2026-11-26, configs/motion/default.yaml): v4's recipe on a wider VAE with
    the planted-foot loss.

    docs/benchmarks.md measures over 60 s: walk steer 42.4 degrees (v4: 30.9), hop on left leg floor distance
    1.06 cm (v4: 3.57) and left foot alone 0.95 (v4: 0.67). These floors, above v4's figures, catch a regression.
    """
    from latentrl.app.bench.motion import steering_spread_deg

    assert model.latent_shape == (1, 32) and model.info["config"]["vae_train"]["plant_weight"] == 100.0
    walk = steering_spread_deg(model, "walk", batch=64)
    assert walk >= 35.0, walk
    roll = model.rollout("hop on left leg", num_steps=30, batch=4, generator=torch.Generator().manual_seed(0))
    floor = float(M.foot_floor_distance_cm(roll.joints_world).mean())
    alone = float(M.foot_contact_shares(roll.joints_world[:, 2:])["left_only"].mean())
    assert floor < 3.0, floor
    assert alone > 0.8, alone
