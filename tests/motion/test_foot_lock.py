"""The foot lock (``MotionModel.foot_lock``, :func:`latentrl.motion.rollout.lock_feet`): known answers on a
hand-made primitive, and a rollout whose outputs stay consistent while the model's input is untouched."""

import math

import pytest
import torch

from latentrl.motion.canonical import WorldTransform, features_to_world
from latentrl.motion.contacts import foot_positions, weighted_foot_slide
from latentrl.motion.representation import FEATURE_DIM, SLICES, joints_of
from latentrl.motion.rollout import lock_feet
from latentrl.motion.skeleton import FOOT_JOINTS

LEFT, RIGHT = FOOT_JOINTS


def primitive(left_z: float, right_z: float, speed: float = 0.01):
    """(1, 8, 276) canonical features: every joint 1 m up, the left foot at ``left_z`` sliding +x by ``speed``
    per frame, the right foot still at ``right_z``; placed by a 90-degree turn and a shift."""
    joints = torch.zeros(1, 8, 22, 3)
    joints[..., 2] = 1.0
    frames = torch.arange(8, dtype=torch.float32)
    joints[0, :, LEFT] = torch.stack((speed * frames, torch.zeros(8), torch.full((8,), left_z)), dim=-1)
    joints[0, :, RIGHT] = torch.tensor([0.0, 0.3, right_z])
    future = torch.zeros(1, 8, FEATURE_DIM)
    future[..., SLICES["joints"]] = joints.flatten(-2)
    future[..., SLICES["transl"]] = joints[:, :, 0]
    c, s = math.cos(math.pi / 2), math.sin(math.pi / 2)
    turn = torch.tensor([[[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]])
    placement = WorldTransform(turn, torch.tensor([[1.0, 2.0, 0.0]]))
    world = placement.apply(joints_of(future))
    before = placement.apply(torch.stack((joints[0, 0, LEFT] - torch.tensor([speed, 0, 0]), joints[0, 0, RIGHT]))[None])
    return future, world, placement, before


def test_a_planted_sliding_foot_stays_where_it_was():
    future, world, placement, before = primitive(left_z=0.0, right_z=0.2)
    locked, feats, shift = lock_feet(future, world, placement, before)
    left = locked[0, :, LEFT]
    assert torch.allclose(left, before[0, 0].expand(8, 3), atol=1e-6)  # the slide is gone, frame by frame
    # the whole body moved back by the slide (x in the canonical frame = y in the world after the turn)
    assert torch.allclose(shift, torch.tensor([[0.0, -0.08, 0.0]]), atol=1e-6)
    assert torch.allclose(locked - world, (locked - world)[:, :, :1].expand_as(world), atol=1e-6)  # rigid
    assert torch.allclose(locked[..., 2], world[..., 2])  # heights untouched
    # the returned features describe the shifted joints, deltas included
    assert torch.allclose(joints_of(features_to_world(feats, placement, torch.zeros(3))), locked, atol=1e-5)
    delta = feats[0, :, SLICES["transl_delta"]]
    # the (still) pelvis now moves back 1 cm a frame in the canonical x; the last delta points past the primitive
    assert torch.allclose(delta[:-1], torch.tensor([-0.01, 0.0, 0.0]).expand(7, 3), atol=1e-6)
    assert torch.allclose(delta[-1], torch.zeros(3), atol=1e-6)
    feet = torch.cat((before[:, None], foot_positions(locked)), dim=1)
    assert weighted_foot_slide(feet).max() < 1e-6  # DART's skate weighting: nothing left


def test_feet_in_the_air_are_left_alone_and_a_touching_foot_is_corrected_in_proportion():
    future, world, placement, before = primitive(left_z=0.2, right_z=0.2)
    locked, feats, shift = lock_feet(future, world, placement, before)
    assert torch.equal(locked, world) and torch.equal(feats, future) and torch.equal(shift, torch.zeros(1, 3))
    weight = 2.0 - 2.0 ** (0.02 / 0.03)  # DART's ramp at 2 cm, below the lock's minimum summed weight of 0.5
    future, world, placement, before = primitive(left_z=0.02, right_z=0.2)
    _, _, shift = lock_feet(future, world, placement, before)
    assert shift[0, 1].item() == pytest.approx(-0.08 * weight / 0.5, abs=1e-6)
    # with a lower minimum weight the same touching foot is pinned fully
    locked, _, shift = lock_feet(future, world, placement, before, min_weight=0.05)
    assert weight > 0.05 and shift[0, 1].item() == pytest.approx(-0.08, abs=1e-6)
    assert torch.allclose(locked[0, :, LEFT, :2], before[0, 0, :2].expand(8, 2), atol=1e-6)


def test_rollout_with_the_lock_keeps_the_model_input_and_slides_less():
    """On the shipped default model, whose walking feet slide (docs/benchmarks.md)."""
    from latentrl.motion import load_motion_model

    model = load_motion_model("default")
    state = model.initial_state(4, generator=torch.Generator().manual_seed(0))
    text = model.encode_text(["walk"] * 4)
    free_state, locked_state = state, state
    free_joints, locked_joints = [], []
    for step in range(6):
        noise = torch.randn(4, *model.latent_shape, generator=torch.Generator().manual_seed(step))
        free = model.rollout_step(free_state, text, noise)
        model.foot_lock = True
        try:
            locked = model.rollout_step(locked_state, text, noise)
        finally:
            model.foot_lock = False
        assert torch.equal(locked.state.history, free.state.history)  # the model never sees the lock
        assert torch.allclose(locked.state.world.rotation, free.state.world.rotation, atol=1e-6)
        world = features_to_world(locked.future, locked.placement, model.pelvis_delta)
        assert torch.allclose(joints_of(world), locked.joints_world, atol=1e-4)
        free_state, locked_state = free.state, locked.state
        free_joints.append(free.joints_world)
        locked_joints.append(locked.joints_world)
    free_j, locked_j = torch.cat(free_joints, 1), torch.cat(locked_joints, 1)
    assert torch.allclose(free_j[..., 2], locked_j[..., 2], atol=1e-5)  # heights are the floor snap's alone
    def slide(joints):
        return weighted_foot_slide(foot_positions(joints), horizontal=True).sum()

    assert slide(locked_j) < 0.5 * slide(free_j), (slide(locked_j), slide(free_j))


def test_a_foot_planted_on_a_tread_is_locked_against_the_terrain_under_it():
    from latentrl.scenes import Box, Scene, SceneBatch

    tread = SceneBatch.from_scenes([Scene((Box((1.0, 2.0), (4.0, 4.0, 0.2)),))])  # under the whole primitive
    future, world, placement, before = primitive(left_z=0.2, right_z=0.4)
    untouched, _, shift = lock_feet(future, world, placement, before)  # measured from z = 0: in the air
    assert torch.equal(untouched, world) and torch.equal(shift, torch.zeros(1, 3))
    locked, _, shift = lock_feet(future, world, placement, before, terrain=tread)
    assert torch.allclose(locked[0, :, LEFT], before[0, 0].expand(8, 3), atol=1e-6)  # planted on the tread
    assert torch.allclose(shift, torch.tensor([[0.0, -0.08, 0.0]]), atol=1e-6)
    far = SceneBatch.from_scenes([Scene((Box((50.0, 50.0), (1.0, 1.0, 0.2)),))])  # nothing underfoot: z = 0
    future, world, placement, before = primitive(left_z=0.0, right_z=0.2)
    assert all(torch.equal(a, b) for a, b in zip(lock_feet(future, world, placement, before, terrain=far),
                                                   lock_feet(future, world, placement, before)))
