"""Terrain-aware floor snap: a step's tread carries the body, walls do not lift it, flat stays bit-identical."""

import pytest
import torch

from latentrl.envs.reach import ReachLocationEnv
from latentrl.motion import load_motion_model
from latentrl.motion.canonical import WorldTransform, features_to_world
from latentrl.motion.representation import joints_of
from latentrl.motion.rollout import FLOOR_SNAP_M, MAX_STEP_UP_M, follow_steps, ground_under, ramp_snap
from latentrl.scenes import Box, Scene, SceneBatch, Stairs

STEP = Scene((Box((0.5, 0.0), (1.0, 2.0, 0.2)),))  # a 0.2 m step over 0 <= x <= 1
FLAT = Scene(())


class Slope:
    """A hand-made terrain (no scene): z = 0.1 x, to show any ``height(xy)`` will do."""

    def height(self, xy: torch.Tensor) -> torch.Tensor:
        return 0.1 * xy[..., 0]


def primitive(feet_x: tuple[float, float], feet_z: tuple[float, float]) -> torch.Tensor:
    """(1, 8, 22, 3) a body whose feet (joints 10, 11) stand at ``feet_x``/``feet_z``, every other joint above."""
    joints = torch.zeros(1, 8, 22, 3)
    joints[..., 0] = -0.2  # the body over the floor beside the step
    joints[..., 2] = torch.linspace(0.6, 1.6, 22)
    for j, x, z in zip((10, 11), feet_x, feet_z):
        joints[..., j, 0], joints[..., j, 2] = x, z
    return joints


def snap(model, joints, terrain, airborne=False):
    ground = None if terrain is None else ground_under(joints, terrain, torch.zeros(1))
    return model._snap_to_floor(joints, WorldTransform.identity(1), torch.tensor([airborne]), ground)


@pytest.mark.parametrize("left_z, shift", [(0.23, -0.03), (0.12, 0.08), (0.20, 0.0)])
def test_a_foot_over_a_step_lands_on_its_tread(tiny_model, left_z, shift):
    """Known answer: the left foot over the 0.2 m tread, the right one 0.3 m up over the floor beside it."""
    joints = primitive((0.5, -0.5), (left_z, 0.30))
    out, world, airborne = snap(tiny_model, joints, SceneBatch.from_scenes([STEP]))
    torch.testing.assert_close(out[0, :, 10, 2], torch.full((8,), 0.2))  # the foot on the tread
    torch.testing.assert_close(world.translation[0, 2], torch.tensor(shift))
    assert not airborne.item()
    flat, _, _ = snap(tiny_model, joints, None)
    assert flat[0, :, 10, 2].max() <= 0.15 + 1e-6  # the flat snap leaves the foot at least 5 cm inside the step


def test_a_foot_high_over_the_tread_is_in_the_air(tiny_model):
    joints = primitive((0.5, -0.5), (0.2 + FLOOR_SNAP_M + 0.05, 0.60))
    out, _, airborne = snap(tiny_model, joints, SceneBatch.from_scenes([STEP]))
    assert airborne.item() and torch.equal(out, joints)  # a hop's flight over the step keeps its height


def test_an_obstacle_higher_than_a_step_does_not_lift_the_body(tiny_model):
    """A foot walking into a 1 m box reads the box's top; the snap keeps the body on the floor instead."""
    box = SceneBatch.from_scenes([Scene((Box((0.5, 0.0), (1.0, 2.0, 1.0)),))])
    joints = primitive((0.5, -0.5), (0.10, 0.0))
    ground = ground_under(joints, box, torch.zeros(1))
    assert torch.isinf(ground[0, 0, 10]) and ground[0, 0, 11] == 0.0
    out, world, _ = snap(tiny_model, joints, box)
    assert torch.equal(out, joints) and world.translation[0, 2] == 0.0  # right foot on the floor: no shift
    assert MAX_STEP_UP_M < 1.0


def test_any_height_function_is_a_terrain(tiny_model):
    joints = primitive((2.0, 1.0), (0.25, 0.40))  # slope 0.2 and 0.1 under the feet: left 5 cm up, right 30 cm
    out, _, _ = snap(tiny_model, joints, Slope())
    torch.testing.assert_close(out[0, :, 10, 2], torch.full((8,), 0.2))


def test_the_ramped_snap_keeps_frames_above_the_tread():
    """Each frame goes down at most until its lowest joint touches the ground under it, here the tread."""
    joints = primitive((0.5, -0.5), (0.2, 0.5))
    joints[:, :3, 10, 2] = 0.21  # the first frames 1 cm over the tread after a 8 cm lift
    ground = ground_under(joints, SceneBatch.from_scenes([STEP]), torch.zeros(1))
    out, _ = ramp_snap(torch.zeros(1, 8, 276), joints, torch.tensor([0.08]), ground)
    assert (out[0, :, 10, 2] >= 0.2 - 1e-7).all()
    torch.testing.assert_close(out[0, :3, 10, 2], torch.full((3,), 0.2))


def test_a_step_down_lands_the_primitive_end_on_the_lower_ground():
    """Known answer: the left foot stands on the 0.2 m tread, then lifts; the right one stepped off over the floor.

    Snapped as a whole, the right foot would hover 0.2 m over the floor; following the step, each frame after
    the left foot leaves goes down (i + 1) / 8 of it, so the last frame stands on the floor and the placement
    moves down 0.2 m (the features follow, relative to it)."""
    joints = primitive((0.5, -0.5), (0.2, 0.2))
    joints[:, 4:, 10, 2] = 0.5  # the left foot lifts off the tread
    future = torch.zeros(1, 8, 276)
    out, feats, drop = follow_steps(future, joints, torch.zeros(1), SceneBatch.from_scenes([STEP]),
                                    torch.tensor([0.2]), torch.tensor([False]), FLOOR_SNAP_M)
    torch.testing.assert_close(drop, torch.tensor([-0.2]))
    right = torch.tensor([0.2, 0.2, 0.2, 0.2, 0.075, 0.05, 0.025, 0.0])
    torch.testing.assert_close(out[0, :, 11, 2], right)
    assert torch.equal(out[0, :4], joints[0, :4])  # the left foot still on the tread: not moved
    torch.testing.assert_close(feats[0, :, 2], right)  # the pelvis translation's z, relative to the moved placement


def test_a_step_up_lifts_the_frames_before_the_landing_gradually(tiny_model):
    """Known answer: the right foot lands on the tread at frame 4; the snap lifted the primitive 0.2 m as a whole,
    so the left foot (on the floor) floated 0.2 m in frames 0-3; now frame i keeps (i + 1) / 8 of the lift."""
    joints = primitive((-0.5, -0.3), (0.0, 0.1))
    joints[:, 4:, 11, 0], joints[:, 4:, 11, 2] = 0.5, 0.0  # the right foot lands 0.2 m inside the tread
    snapped, world, _ = snap(tiny_model, joints, SceneBatch.from_scenes([STEP]))
    lift = world.translation[:, 2]
    torch.testing.assert_close(lift, torch.tensor([0.2]))
    out, _, drop = follow_steps(torch.zeros(1, 8, 276), snapped, lift, SceneBatch.from_scenes([STEP]),
                                torch.zeros(1), torch.tensor([False]), FLOOR_SNAP_M)
    torch.testing.assert_close(out[0, :4, 10, 2], torch.tensor([0.025, 0.05, 0.075, 0.1]))
    assert torch.equal(out[0, 4:], snapped[0, 4:]) and drop.item() == 0.0


def test_a_frame_with_a_joint_inside_an_obstacle_is_not_lowered():
    """The step down of the first test, with a hand inside a 1 m box in frame 5: that frame keeps its height."""
    scene = SceneBatch.from_scenes([Scene((*STEP.objects, Box((-1.5, 0.0), (0.4, 0.4, 1.0))))])
    joints = primitive((0.5, -0.5), (0.2, 0.2))
    joints[:, 4:, 10, 2] = 0.5
    joints[:, 5, 20, :2] = torch.tensor([-1.5, 0.0])  # a hand 0.6-1.6 m up, inside the box top
    joints[:, 5, 20, 2] = 0.9
    out, _, drop = follow_steps(torch.zeros(1, 8, 276), joints, torch.zeros(1), scene, torch.tensor([0.2]),
                                torch.tensor([False]), FLOOR_SNAP_M)
    assert torch.equal(out[0, 5], joints[0, 5]) and drop.item() == pytest.approx(-0.2)
    assert out[0, 6, 11, 2].item() == pytest.approx(0.025)


@pytest.mark.parametrize("lock", [False, True])
def test_rollouts_down_stairs_keep_features_and_placement_in_step(tiny_model, lock):
    """On stairs, the returned features placed by the returned placement are the returned joints, the next
    state starts at the last frame, and no foot ends a step below the tread under it."""
    stairs = SceneBatch.from_scenes([Scene((Stairs((0.0, 1.0), -90.0, 6.0, 0.06, 0.1, 20),))] * 6)
    tiny_model.foot_lock = lock
    try:
        g = torch.Generator().manual_seed(0)
        state = tiny_model.initial_state(6, generator=g)
        start = state.world.apply(joints_of(state.history))
        up = stairs.height(start[:, -1, :1, :2])[:, 0] - start[..., 2].flatten(1).amin(dim=1)  # onto the tread
        state = state._replace(world=WorldTransform(state.world.rotation, state.world.translation
                                                    + torch.nn.functional.pad(up[:, None], (2, 0))))
        text = torch.zeros(6, tiny_model.text_dim)
        drops = 0
        for _ in range(12):
            before = state.world.translation[:, 2]
            out = tiny_model.rollout_step(state, text, torch.randn(6, *tiny_model.latent_shape, generator=g),
                                          terrain=stairs)
            placed = joints_of(features_to_world(out.future, out.placement, tiny_model.pelvis_delta))
            torch.testing.assert_close(placed, out.joints_world, atol=1e-4, rtol=0)
            if not lock:  # the lock places the next history one frame's correction away (docs/motion.md)
                nxt = out.state.world.apply(joints_of(out.state.history))[:, -1]
                torch.testing.assert_close(nxt, out.joints_world[:, -1], atol=1e-4, rtol=0)
            drops += int((out.state.world.translation[:, 2] < before - 0.05).sum())
            state = out.state
        assert drops > 0  # the test walks down stairs
    finally:
        tiny_model.foot_lock = False


@pytest.fixture(scope="module", params=["default", "parity"])
def model(request, parity_dir_or_none):
    if request.param == "default":
        return load_motion_model("default")
    if parity_dir_or_none is None:
        pytest.skip("DART parity data not found")
    return load_motion_model(parity_dir_or_none / "mld_denoiser/mld_parity_A/checkpoint_1.pt")


@pytest.fixture(scope="module")
def parity_dir_or_none():
    from tests.conftest import PARITY

    return PARITY if (PARITY / "expected.pt").is_file() else None


@pytest.mark.parametrize("ramp", [False, True])
def test_flat_placement_is_bit_identical(model, ramp):
    """``terrain=None`` is today's snap (recomputed here by hand), and a flat scene's floor gives the same bits."""
    model.floor_snap_ramp = ramp
    try:
        g = torch.Generator().manual_seed(3)
        state = model.initial_state(3, generator=g)
        text = torch.zeros(3, model.text_dim)
        flat = SceneBatch.from_scenes([FLAT])
        for _ in range(4):
            noise = torch.randn(3, *model.latent_shape, generator=g)
            out = model.rollout_step(state, text, noise)
            scened = model.rollout_step(state, text, noise, terrain=flat)
            for a, b in zip((out.joints_world, out.future, out.placement.translation, out.state.world.translation,
                             out.state.airborne), (scened.joints_world, scened.future, scened.placement.translation,
                                                   scened.state.world.translation, scened.state.airborne)):
                assert torch.equal(a, b)
            if not ramp:  # the snap before terrain existed: lowest joint to z = 0, flights kept (capped), by hand
                raw = state.world.apply(joints_of(model.sample_primitive(state.history, text, noise).future))
                lowest = raw[..., 2].flatten(1).min(dim=1).values
                land = (lowest <= FLOOR_SNAP_M) | state.airborne_flags()
                shift = torch.where(land, torch.zeros_like(lowest), lowest.clamp(max=0.15)) - lowest
                zero = torch.zeros_like(shift)
                assert torch.equal(out.joints_world, raw + torch.stack((zero, zero, shift), -1)[:, None, None, :])
            state = out.state
    finally:
        model.floor_snap_ramp = False


def test_an_env_on_a_platform_stands_on_it(tiny_model):
    """The env passes its scene: on a 0.2 m platform under the whole walk, the motion is the flat env's, 0.2 m up."""
    platform = Scene((Box((0.0, 0.0), (40.0, 40.0, 0.2)),))
    env = ReachLocationEnv(2, motion=tiny_model, scene=platform)
    flat = ReachLocationEnv(2, motion=tiny_model)
    env.reset(seed=1)
    flat.reset(seed=1)
    for step in range(4):  # no episode ends in these steps (a reset starts on z = 0)
        a = torch.randn(2, 16, generator=torch.Generator().manual_seed(step))
        done = env.step(a)[2:4]
        flat.step(a)
        assert not (done[0] | done[1]).any()
        moved = env.history_world() - flat.history_world()
        torch.testing.assert_close(moved[..., 2], torch.full_like(moved[..., 2], 0.2), atol=1e-5, rtol=0)
        torch.testing.assert_close(moved[..., :2], torch.zeros_like(moved[..., :2]), atol=1e-5, rtol=0)


def test_metrics_measure_feet_against_the_tread():
    """Known answer: feet standing still on a 0.2 m step are on the floor, not 20 cm above it."""
    from latentrl.evaluation import metrics as M

    joints = primitive((0.4, 0.6), (0.2, 0.2))[0]  # (8, 22, 3) both feet on the tread, the body above
    joints[..., 0] = torch.where(joints[..., 2] > 0.5, 0.5, joints[..., 0])  # the whole body over the step
    step = SceneBatch.from_scenes([STEP])
    on = M.episode_metrics(joints, 30.0, 0.0, step)
    flat = M.episode_metrics(joints, 30.0, 0.0)
    assert on["floor_cm"] < 1e-4 and on["floating_mm"] == 0.0 and on["penetration_mm"] == 0.0
    assert abs(flat["floor_cm"] - 20.0) < 1e-4 and flat["floating_mm"] > 190.0
    assert M.episode_metrics(joints, 30.0, 0.0, SceneBatch.from_scenes([FLAT])) == flat  # a flat scene: same
    wall = SceneBatch.from_scenes([Scene((Box((0.5, 0.0), (1.0, 2.0, 1.0)),))])  # too high to stand on
    assert M.episode_metrics(joints, 30.0, 0.0, wall) == flat
