import pytest
import torch

from latentrl.motion.representation import SLICES, joints_of


def test_sample_shapes_and_dtypes(tiny_model):
    b = 3
    hist = tiny_model.seed_history.expand(b, -1, -1)
    text = tiny_model.encode_text(["walk", "run", "walk"])
    noise = torch.randn(b, 1, 16)
    out = tiny_model.sample_primitive(hist, text, noise)
    assert out.latent.shape == (b, 1, 16) and out.future.shape == (b, 8, 276)
    assert out.future.dtype == torch.float32 and torch.isfinite(out.future).all()


def test_deterministic_for_given_noise(tiny_model):
    hist = tiny_model.seed_history.expand(2, -1, -1)
    text = tiny_model.encode_text(["walk", "run"])
    noise = torch.randn(2, 1, 16, generator=torch.Generator().manual_seed(4))
    a = tiny_model.sample_primitive(hist, text, noise)
    b = tiny_model.sample_primitive(hist, text, noise)
    assert torch.equal(a.future, b.future)


def test_batch_rows_are_independent(tiny_model):
    hist = tiny_model.seed_history.expand(4, -1, -1)
    text = tiny_model.encode_text(["walk", "run", "hop on left leg", "walk"])
    noise = torch.randn(4, 1, 16, generator=torch.Generator().manual_seed(5))
    full = tiny_model.sample_primitive(hist, text, noise)
    one = tiny_model.sample_primitive(hist[2:3], text[2:3], noise[2:3])
    torch.testing.assert_close(full.future[2:3], one.future, atol=1e-5, rtol=1e-5)


def test_rollout_step_recanonicalizes_and_tracks_world(tiny_model):
    state = tiny_model.initial_state(2, seed_index=torch.tensor([0, 0]))
    # lowest seed joint is on the floor in world coordinates
    seed_world = state.world.apply(joints_of(state.history))
    assert seed_world[..., 2].amin().abs() < 1e-5
    text = tiny_model.encode_text(["walk", "walk"])
    step = tiny_model.rollout_step(state, text, torch.randn(2, 1, 16))
    assert step.joints_world.shape == (2, 8, 22, 3)
    # new history: pelvis at canonical origin, same world joints as the last two future frames
    torch.testing.assert_close(joints_of(step.state.history)[:, 0, 0], torch.zeros(2, 3), atol=1e-5, rtol=0)
    torch.testing.assert_close(
        step.state.world.apply(joints_of(step.state.history)), step.joints_world[:, -2:], atol=1e-5, rtol=0
    )


def test_rollout_length_and_reproducibility(tiny_model):
    g1, g2 = torch.Generator().manual_seed(9), torch.Generator().manual_seed(9)
    a = tiny_model.rollout(["walk", "run", "walk"], num_steps=3, batch=2, generator=g1)
    b = tiny_model.rollout(["walk", "run", "walk"], num_steps=3, batch=2, generator=g2)
    assert a.joints_world.shape == (2, 2 + 8 * 3, 22, 3)
    assert torch.equal(a.joints_world, b.joints_world)


def test_bad_shapes_are_clear_errors(tiny_model):
    hist = tiny_model.seed_history
    text = tiny_model.encode_text(["walk"])
    with pytest.raises(ValueError, match=r"noise must be \(1, 1, 16\)"):
        tiny_model.sample_primitive(hist, text, torch.randn(1, 16))
    with pytest.raises(ValueError, match="text_embedding must be"):
        tiny_model.sample_primitive(hist, torch.zeros(1, 7), torch.randn(1, 1, 16))


def test_pelvis_delta_from_seed_matches(tiny_model):
    seed = tiny_model.seed_history[0, 0]
    d = seed[SLICES["joints"]][:3] - seed[SLICES["transl"]]
    torch.testing.assert_close(d, tiny_model.pelvis_delta, atol=1e-5, rtol=0)


def test_floor_snap_lifts_sinking_lowers_hovering_and_keeps_flight(tiny_model):
    from latentrl.motion.canonical import WorldTransform
    from latentrl.motion.rollout import FLIGHT_CAP_M

    world = WorldTransform.identity(4)
    joints = torch.zeros(4, 8, 22, 3)
    joints[..., 2] = torch.linspace(0.0, 1.0, 22)  # lowest joint at 0, pelvis-ish joints above
    lows = torch.tensor([-0.20, 0.03, 0.10, 0.60])  # sunk, within the band, a hop's flight, flying
    joints[..., 2] += lows[:, None, None]
    snapped, new_world, airborne = tiny_model._snap_to_floor(joints, world, torch.zeros(4, dtype=torch.bool))
    expected = torch.tensor([0.0, 0.0, 0.10, FLIGHT_CAP_M])  # flight kept, but capped
    assert torch.allclose(snapped[..., 2].amin(dim=(1, 2)), expected, atol=1e-6)
    assert torch.allclose(new_world.translation[:, 2], expected - lows, atol=1e-6)
    assert torch.equal(snapped[..., :2], joints[..., :2]) and torch.equal(new_world.rotation, world.rotation)
    assert airborne.tolist() == [False, False, True, True]


def test_floor_snap_lands_a_second_airborne_primitive(tiny_model):
    from latentrl.motion.canonical import WorldTransform

    joints = torch.zeros(2, 8, 22, 3)
    joints[..., 2] = torch.linspace(0.0, 1.0, 22) + 0.10  # both 10 cm up
    before = torch.tensor([False, True])  # the second was airborne one primitive ago already
    snapped, _, airborne = tiny_model._snap_to_floor(joints, WorldTransform.identity(2), before)
    assert torch.allclose(snapped[..., 2].amin(dim=(1, 2)), torch.tensor([0.10, 0.0]), atol=1e-6)
    assert airborne.tolist() == [True, False]


def test_rollout_state_carries_airborne_flags(tiny_model):
    state = tiny_model.initial_state(3, generator=torch.Generator().manual_seed(0))
    assert state.airborne.tolist() == [False] * 3  # a start state is on the floor
    assert state._replace(airborne=None).airborne_flags().tolist() == [False] * 3  # a hand-made one reads so too
    out = tiny_model.rollout_step(state, tiny_model.encode_text(["walk"] * 3), torch.randn(3, 1, 16))
    assert out.state.airborne is not None and out.state.airborne.shape == (3,)
    lowest = out.joints_world[..., 2].flatten(1).amin(dim=1)
    assert torch.equal(out.state.airborne, lowest > 1e-6)  # landed primitives sit exactly on the floor


def test_floor_snap_keeps_long_rollouts_on_the_floor_and_can_be_turned_off(tiny_model):
    g = torch.Generator().manual_seed(0)
    roll = tiny_model.rollout("walk", num_steps=6, batch=4, generator=g)
    lowest = roll.joints_world[:, 2:, :, 2].reshape(4, 6, 8 * 22).amin(dim=-1)
    assert (lowest >= -1e-5).all()  # never below the floor
    tiny_model.floor_snap = None
    try:
        free = tiny_model.rollout("walk", num_steps=6, batch=4, generator=torch.Generator().manual_seed(0))
    finally:
        tiny_model.floor_snap = 0.05
    assert torch.allclose(free.joints_world[..., :2], roll.joints_world[..., :2], atol=1e-5)


def test_v_prediction_reads_back_the_clean_latent():
    """Known answer: for x_t = q_sample(x0, t, eps) the true v = sqrt(acp) eps - sqrt(1 - acp) x0 gives x0 back.

    Checks that the denoiser's schedule buffers line up with the diffusion's steps (the model sees the
    original step index).
    """
    from latentrl.motion.denoiser import DenoiserConfig, build_denoiser
    from latentrl.motion.diffusion import DiffusionConfig, GaussianDiffusion

    diffusion = GaussianDiffusion(DiffusionConfig(diffusion_steps=10))
    den = build_denoiser(DenoiserConfig(h_dim=16, ff_size=32, num_layers=1, clip_dim=8, noise_shape=(1, 4),
                                        prediction="v"))
    g = torch.Generator().manual_seed(0)
    x0, eps = torch.randn(10, 1, 4, generator=g), torch.randn(10, 1, 4, generator=g)
    t = torch.arange(10)
    with pytest.raises(RuntimeError, match="attach_schedule"):
        den.x0_from_output(x0, t, x0)
    den.attach_schedule(diffusion.base_alphas_cumprod)
    x_t = diffusion.q_sample(x0, t, eps)
    acp = torch.as_tensor(diffusion.alphas_cumprod, dtype=torch.float32).reshape(-1, 1, 1)
    v = acp.sqrt() * eps - (1 - acp).sqrt() * x0
    assert torch.allclose(den.x0_from_output(x_t, t, v), x0, atol=1e-5)
    # one step index for the whole batch (what the sampler passes) reads the same row
    assert torch.allclose(den.x0_from_output(x_t[3:4], torch.tensor(3), v[3:4]), x0[3:4], atol=1e-5)
    with pytest.raises(ValueError, match="prediction must be one of"):
        build_denoiser(DenoiserConfig(prediction="eps"))


def test_ramped_floor_snap_spreads_the_shift_over_the_primitive(tiny_model):
    """Known answer: frame i of 8 keeps (i + 1)/8 of the snap's lift; the last frame and the next state are
    the plain snap's, and the world features stay in step with the joints."""
    _check_ramped_snap(tiny_model)


def test_ramped_floor_snap_on_a_dart_format_model(parity_dir):
    """The same on a model in DART's own checkpoint format (the parity model, untrained), given a seed."""
    from latentrl.motion import load_motion_model
    from tests.helpers import seed_history

    model = load_motion_model(parity_dir / "mld_denoiser/mld_parity_A/checkpoint_1.pt", seed_history=seed_history())
    _check_ramped_snap(model)


def _check_ramped_snap(model) -> None:
    from latentrl.motion.canonical import features_to_world
    from latentrl.motion.representation import joints_of

    state = model.initial_state(3, generator=torch.Generator().manual_seed(0))
    state = state._replace(world=state.world._replace(translation=state.world.translation + torch.tensor(
        [0.0, 0.0, 0.04])))  # 4 cm up: the snap lowers the primitive
    emb = torch.zeros(3, model.text_dim)
    emb[:, 0] = 1.0
    noise = torch.randn(3, *model.latent_shape, generator=torch.Generator().manual_seed(1))
    plain = model.rollout_step(state, emb, noise)
    model.floor_snap_ramp = True
    try:
        ramped = model.rollout_step(state, emb, noise)
    finally:
        model.floor_snap_ramp = False
    lift = plain.placement.translation[:, 2] - state.world.translation[:, 2]
    assert (lift.abs() > 1e-3).all()
    frac = torch.arange(1, 9) / 8.0
    want = plain.joints_world.clone()
    want[..., 2] += (lift[:, None] * (frac - 1.0))[..., None]
    torch.testing.assert_close(ramped.joints_world, want, atol=1e-5, rtol=0)
    torch.testing.assert_close(ramped.state.history, plain.state.history)
    torch.testing.assert_close(ramped.state.world.translation, plain.state.world.translation)
    world = features_to_world(ramped.future, ramped.placement, model.pelvis_delta)
    torch.testing.assert_close(joints_of(world), ramped.joints_world, atol=1e-5, rtol=0)
    before = features_to_world(plain.future, plain.placement, model.pelvis_delta)
    added = lift[:, None] / 8.0  # each step within the primitive takes 1/8 of the lift (the deltas in step)
    torch.testing.assert_close(world[:, :-1, 212:276:3] - before[:, :-1, 212:276:3],
                               added[..., None].expand(3, 7, 22), atol=1e-5, rtol=0)


def test_ramped_snap_never_puts_a_lifted_primitive_below_the_floor():
    """Known answer: a primitive sunk 8 cm and lifted; the ramp would leave frame i 8 (7 - i)/8 cm under its
    snapped height, but each frame goes down only until its lowest joint touches the floor."""
    from latentrl.motion.rollout import ramp_snap

    lowest = torch.tensor([0.05, 0.0, 0.03, 0.0, 0.0, 0.0, 0.01, 0.0])
    joints = torch.zeros(1, 8, 22, 3)
    joints[..., 2] = lowest[None, :, None] + torch.linspace(0.0, 1.0, 22)
    out, future = ramp_snap(torch.zeros(1, 8, 276), joints, torch.tensor([0.08]))
    want = torch.tensor([-0.05, 0.0, -0.03, 0.0, 0.0, 0.0, -0.01, 0.0])
    torch.testing.assert_close(out[0, :, 0, 2] - joints[0, :, 0, 2], want)
    assert (out[..., 2] >= -1e-7).all()
    torch.testing.assert_close(future[0, :, 2], want)  # transl z moves with the joints
