import math

import pytest
import torch

from latentrl.motion.canonical import WorldTransform, canonicalize, features_to_world, world_to_canonical
from latentrl.motion.representation import FEATURE_DIM, SLICES, compute_features, split_frames
from latentrl.motion.rotations import rotation_6d_to_matrix
from tests.helpers import PELVIS_DELTA, walking_clip


def world_features(yaw=0.7, seed=0):
    clip = walking_clip(11, speed=1.3, yaw=yaw, seed=seed)
    return compute_features(clip["transl"], clip["rotations"], clip["joints"])[None]  # (1, 10, 276)


def test_feature_layout():
    assert SLICES["transl"] == slice(0, 3) and SLICES["joints_delta"] == slice(210, 276)
    assert sum(s.stop - s.start for s in SLICES.values()) == FEATURE_DIM


def test_pelvis_at_origin_and_hips_on_x():
    canon, _, _ = canonicalize(world_features(), PELVIS_DELTA)
    f = split_frames(canon)
    torch.testing.assert_close(f.joints[:, 0, 0], torch.zeros(1, 3), atol=1e-6, rtol=0)
    hips = f.joints[:, 0, 2] - f.joints[:, 0, 1]
    assert hips[0, 0] > 0 and abs(hips[0, 1]) < 1e-6
    # pelvis = transl + pelvis_delta still holds after the transform
    torch.testing.assert_close(f.joints[..., 0, :], f.transl + PELVIS_DELTA, atol=1e-5, rtol=0)


def test_forward_motion_maps_to_plus_y():
    """A body walking along its facing direction walks along +y in its canonical frame."""
    canon, _, _ = canonicalize(world_features(yaw=2.0), PELVIS_DELTA)
    f = split_frames(canon)
    step = f.joints[0, -1, 0] - f.joints[0, 0, 0]
    assert step[1] > 0.3 and abs(step[0]) < 0.05


@pytest.mark.parametrize("yaw", [0.0, 1.0, -2.5, math.pi])
def test_round_trip_world_canonical_world(yaw):
    feats = world_features(yaw=yaw, seed=3)
    canon, world = world_to_canonical(feats, PELVIS_DELTA)
    back = features_to_world(canon, world, PELVIS_DELTA)
    torch.testing.assert_close(back, feats, atol=1e-5, rtol=0)


def test_deltas_stay_consistent_and_orientation_delta_conjugated():
    canon, _, _ = canonicalize(world_features(seed=5), PELVIS_DELTA)
    f = split_frames(canon[0])
    torch.testing.assert_close(f.joints[1:] - f.joints[:-1], f.joints_delta[:-1], atol=1e-5, rtol=0)
    torch.testing.assert_close(f.transl[1:] - f.transl[:-1], f.transl_delta[:-1], atol=1e-5, rtol=0)
    g = rotation_6d_to_matrix(f.poses_6d[:, 0])
    delta = rotation_6d_to_matrix(f.global_orient_delta_6d)
    torch.testing.assert_close(delta[:-1] @ g[:-1], g[1:], atol=1e-5, rtol=0)


def test_world_transform_compose_matches_sequential_canonicalization():
    """Re-canonicalizing a later window and composing transforms recovers world joints."""
    feats = world_features(seed=7)
    canon, world = world_to_canonical(feats, PELVIS_DELTA)
    later, r, t = canonicalize(canon[:, 5:], PELVIS_DELTA)
    world2 = world.compose(r, t)
    joints_world = world2.apply(split_frames(later).joints)
    torch.testing.assert_close(joints_world, split_frames(feats).joints[:, 5:], atol=1e-5, rtol=0)


def test_world_transform_inverse():
    w = WorldTransform(torch.linalg.qr(torch.randn(2, 3, 3))[0], torch.randn(2, 3))
    p = torch.randn(2, 5, 3)
    torch.testing.assert_close(w.inverse_apply(w.apply(p)), p, atol=1e-5, rtol=0)
