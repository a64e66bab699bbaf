"""``MotionModel.pack_for_cpu``: oneDNN-prepacked linear weights give the unpacked sampler's results."""

import pytest
import torch
from torch import nn

from latentrl.errors import LatentRLError
from latentrl.motion.packed import PackedLinear
from tests.helpers import make_tiny_model


def _sample(model, batch: int = 3):
    g = torch.Generator().manual_seed(0)
    hist = torch.randn(batch, 2, 276, generator=g) * 0.1
    text = torch.randn(batch, model.text_dim, generator=g)
    noise = torch.randn(batch, *model.latent_shape, generator=g)
    with torch.no_grad():
        return model.sample_primitive(hist, text, noise, guidance_scale=5.0).future


def test_packed_model_samples_like_the_unpacked_one_and_keeps_its_state_dict():
    plain, packed = make_tiny_model(), make_tiny_model()
    packed.load_state_dict(plain.state_dict())
    state = {k: v.clone() for k, v in packed.state_dict().items()}
    linears = sum(type(m) is nn.Linear for m in packed.modules())
    attention = sum(hasattr(m, "pack_keys") for m in packed.modules())
    count = packed.pack_for_cpu()
    assert count == linears + 3 * attention > 0
    assert not any(type(m) is nn.Linear for m in packed.modules())
    assert any(isinstance(m, PackedLinear) for m in packed.modules())
    assert packed.pack_for_cpu() == 0  # layers already packed are left alone
    after = packed.state_dict()
    assert after.keys() == state.keys() and all(torch.equal(after[k], state[k]) for k in state)
    for batch in (1, 3):  # the layout is chosen for 10 rows; other row counts still compute the same thing
        torch.testing.assert_close(_sample(packed, batch), _sample(plain, batch), atol=1e-5, rtol=1e-5)


def test_packed_sampler_traces_as_one_graph():
    """The packed op is a torch.library op: fullgraph tracing keeps it as one opaque call."""
    model = make_tiny_model()
    model.pack_for_cpu()
    model.prepare_compile()
    g = torch.Generator().manual_seed(0)
    hist, text = torch.randn(2, 2, 276, generator=g) * 0.1, torch.randn(2, model.text_dim, generator=g)
    noise = torch.randn(2, *model.latent_shape, generator=g)
    torch._dynamo.reset()
    fn = torch.compile(lambda h, t, n: model.sample_primitive(h, t, n, guidance_scale=5.0).future,
                       fullgraph=True, backend="eager")
    with torch.no_grad():
        torch.testing.assert_close(fn(hist, text, noise), model.sample_primitive(hist, text, noise, 5.0).future)


def test_packing_refuses_weights_that_are_not_cpu_float32_and_autocast():
    model = make_tiny_model().to(torch.float64)
    with pytest.raises(LatentRLError, match=r"packing is for CPU float32 weights, found torch.float64 on cpu"):
        model.pack_for_cpu()
    model = make_tiny_model()
    model.amp_dtype = torch.bfloat16
    with pytest.raises(LatentRLError, match=r"samples under autocast \(torch.bfloat16\)"):
        model.pack_for_cpu()


def test_a_packed_model_cast_afterwards_falls_back_to_plain_linears():
    """Inputs that are not CPU float32 (here float64 after packing) take F.linear, not the oneDNN op."""
    plain, packed = make_tiny_model(), make_tiny_model()
    packed.load_state_dict(plain.state_dict())
    packed.pack_for_cpu()
    plain, packed = plain.double(), packed.double()
    g = torch.Generator().manual_seed(0)
    hist = torch.randn(2, 2, 276, generator=g, dtype=torch.float64) * 0.1
    text = torch.randn(2, plain.text_dim, generator=g, dtype=torch.float64)
    noise = torch.randn(2, *plain.latent_shape, generator=g, dtype=torch.float64)
    with torch.no_grad():
        a = plain.sample_primitive(hist, text, noise, guidance_scale=5.0).future
        b = packed.sample_primitive(hist, text, noise, guidance_scale=5.0).future
    torch.testing.assert_close(a, b)


def test_an_input_that_needs_a_gradient_takes_the_differentiable_linear():
    """The packed op has no backward: a gradient through a packed layer must still be the true one."""
    layer = nn.Linear(16, 24)
    packed = nn.Linear(16, 24)
    packed.load_state_dict(layer.state_dict())
    from latentrl.motion.packed import pack_linears

    assert pack_linears(packed.requires_grad_(False)) == 1
    x = torch.randn(2, 5, 16, requires_grad=True)
    x2 = x.detach().clone().requires_grad_(True)
    layer(x).square().sum().backward()
    packed(x2).square().sum().backward()
    assert torch.allclose(x.grad, x2.grad, atol=1e-5)
    with torch.no_grad():
        assert torch.allclose(layer(x), packed(x), atol=1e-5)
    trainable = nn.Linear(16, 24)  # packed while its weight still needs a gradient: the weight must get one
    pack_linears(trainable)
    trainable(x.detach()).sum().backward()
    assert trainable.weight.grad is not None and trainable.weight.grad.abs().sum() > 0


def test_cpu_autocast_switched_on_after_packing_takes_the_plain_linear():
    from latentrl.motion.packed import pack_linears

    packed = nn.Linear(16, 24).requires_grad_(False)
    pack_linears(packed)
    with torch.no_grad(), torch.autocast("cpu", dtype=torch.bfloat16):
        assert packed(torch.randn(3, 16)).dtype == torch.bfloat16
