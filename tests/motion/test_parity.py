"""Parity with outputs computed by DART's own code (shared/reference/dart_parity_A)."""

import pytest
import torch

from latentrl.motion import load_motion_model
from latentrl.motion.diffusion import DiffusionConfig, GaussianDiffusion

TOL = dict(atol=1e-5, rtol=1e-5)


@pytest.fixture(scope="module")
def parity(parity_dir):
    model = load_motion_model(parity_dir / "mld_denoiser/mld_parity_A/checkpoint_1.pt")
    inputs = torch.load(parity_dir / "inputs.pt", weights_only=True)
    expected = torch.load(parity_dir / "expected.pt", weights_only=True)
    return model, inputs, expected


def test_loads_with_dart_hyperparameters(parity):
    model, _, expected = parity
    assert model.latent_shape == (1, 32)
    assert model.text_dim == 512
    assert model.vae.config.num_layers == 3 and model.denoiser.config.num_layers == 2
    assert model.vae.latent_std.item() == pytest.approx(expected["meta"]["latent_std"])
    assert model.rescale_latent


def test_normalization(parity):
    model, inputs, expected = parity
    got = model.normalizer.normalize(inputs["history_motion"])
    torch.testing.assert_close(got, expected["history_normalized"], **TOL)


@pytest.mark.parametrize("name", ["diffusion_ddim10", "diffusion_ddpm"])
def test_diffusion_tables(parity, name):
    _, _, expected = parity
    diff = GaussianDiffusion(DiffusionConfig(respacing="ddim10" if "ddim" in name else ""))
    tables = diff.tables()
    for key, value in expected[name].items():
        if key == "num_timesteps":
            assert diff.num_timesteps == value
        else:
            torch.testing.assert_close(torch.as_tensor(tables[key]).to(value.dtype), value, atol=0, rtol=0)


@pytest.mark.parametrize("t", [9, 5, 0])
@pytest.mark.parametrize("cond", ["cond", "uncond"])
def test_denoiser_single_pass(parity, t, cond):
    model, inputs, expected = parity
    text = inputs["text_embedding"] if cond == "cond" else torch.zeros_like(inputs["text_embedding"])
    with torch.no_grad():
        out = model.denoiser(inputs["x_T"], torch.full((4,), t), expected["history_normalized"], text)
    torch.testing.assert_close(out, expected["unit"][f"denoiser_t{t}_{cond}"], **TOL)


@pytest.mark.parametrize("scaled", [True, False])
def test_vae_decode(parity, scaled):
    model, inputs, expected = parity
    with torch.no_grad():
        out = model.vae.decode(inputs["x_T"], expected["history_normalized"], 8, scale_latent=scaled)
    key = "vae_decode_xT_scaled" if scaled else "vae_decode_xT_unscaled"
    torch.testing.assert_close(out, expected["unit"][key], **TOL)


def test_vae_encode(parity):
    model, _, expected = parity
    with torch.no_grad():
        mu, std = model.vae.encode(expected["ddim_cfg5"]["future_normalized"], expected["history_normalized"])
    torch.testing.assert_close(mu.permute(1, 0, 2), expected["unit"]["vae_encode_mu"], **TOL)
    torch.testing.assert_close(std.permute(1, 0, 2), expected["unit"]["vae_encode_std"], **TOL)


CASES = {
    "ddim_cfg5": dict(guidance_scale=5.0),
    "ddim_cfg1": dict(guidance_scale=1.0),
    "ddpm_cfg5": dict(guidance_scale=5.0, sampler="ddpm"),
}


@pytest.mark.parametrize("case", list(CASES))
def test_sampling(parity, case):
    model, inputs, expected = parity
    exp = expected[case]
    kwargs = dict(CASES[case])
    if case.startswith("ddpm"):
        kwargs["step_noise"] = exp["step_noises"]
    trace = []
    out = model.sample_primitive(
        inputs["history_motion"], inputs["text_embedding"], inputs["x_T"], trace=trace, **kwargs
    )
    torch.testing.assert_close(out.latent, exp["x0"], **TOL)
    torch.testing.assert_close(out.future_normalized, exp["future_normalized"], **TOL)
    torch.testing.assert_close(out.future, exp["future_unnormalized"], **TOL)
    assert [t for t, _, _ in trace] == exp["steps_t"].tolist()
    torch.testing.assert_close(torch.stack([x for _, x, _ in trace]), exp["steps_sample"], **TOL)
    torch.testing.assert_close(torch.stack([x0 for _, _, x0 in trace]), exp["steps_pred_xstart"], **TOL)


def test_guidance_scale_one_equals_no_wrapper(parity):
    model, inputs, expected = parity
    out = model.sample_primitive(inputs["history_motion"], inputs["text_embedding"], inputs["x_T"], guidance_scale=1.0)
    torch.testing.assert_close(out.latent, expected["ddim_nowrapper"]["x0"], **TOL)


def test_per_sample_guidance_scale(parity):
    """A (B,) guidance tensor equals running each row with its own float scale."""
    model, inputs, _ = parity
    scales = torch.tensor([5.0, 1.0, 3.0, 2.0])
    out = model.sample_primitive(
        inputs["history_motion"], inputs["text_embedding"], inputs["x_T"], guidance_scale=scales
    )
    for i, s in enumerate(scales.tolist()):
        row = model.sample_primitive(
            inputs["history_motion"][i : i + 1],
            inputs["text_embedding"][i : i + 1],
            inputs["x_T"][i : i + 1],
            guidance_scale=s if s != 1.0 else 1.0 + 0.0,
        )
        torch.testing.assert_close(out.latent[i : i + 1], row.latent, **TOL)


def test_cfg_is_one_batched_pass(parity, monkeypatch):
    """Guidance runs one denoiser call of batch 2B per step, not two calls."""
    model, inputs, _ = parity
    calls = []
    original = model.denoiser.denoise

    def spy(x, t, cond):
        calls.append(x.shape[0])
        return original(x, t, cond)

    monkeypatch.setattr(model.denoiser, "denoise", spy)
    model.sample_primitive(inputs["history_motion"], inputs["text_embedding"], inputs["x_T"], guidance_scale=5.0)
    assert calls == [8] * 10


def test_zero_text_row_ignores_guidance(parity):
    model, inputs, _ = parity
    zero = inputs["zero_text_row"]
    a = model.sample_primitive(inputs["history_motion"], inputs["text_embedding"], inputs["x_T"], guidance_scale=5.0)
    b = model.sample_primitive(inputs["history_motion"], inputs["text_embedding"], inputs["x_T"], guidance_scale=1.0)
    torch.testing.assert_close(a.latent[zero], b.latent[zero], **TOL)
