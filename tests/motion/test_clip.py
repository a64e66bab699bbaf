"""MotionClip: the one motion type and its .npz (contacts, rest offsets, old files without them)."""

from __future__ import annotations

import numpy as np
import pytest

from latentrl.errors import DataError
from latentrl.motion.clip import MotionClip, load_motion_npz, primitive_layout
from latentrl.motion.skeleton import FOOT_JOINTS, PARENTS, rest_offsets

LEFT, RIGHT = FOOT_JOINTS


def walking(frames: int = 18) -> np.ndarray:
    rng = np.random.default_rng(0)
    joints = rng.normal(scale=0.1, size=(frames, 22, 3)).astype(np.float32)
    joints[:, :, 2] += 1.0
    joints[:, LEFT, 2] = 0.01  # planted
    joints[:, RIGHT, 2] = np.where(np.arange(frames) % 2 == 0, 0.0, 0.2)  # every other frame up
    return joints


def test_round_trip_with_contacts_and_rest_offsets(tmp_path):
    joints = walking()
    clip = MotionClip(joints, texts=[""] * 2 + ["walk"] * 16, actions=np.ones((2, 16)), goals=np.zeros((2, 3)),
                      primitive=primitive_layout(2), meta={"seed": 3, "success": True})
    assert clip.contacts[:, 0].all() and clip.contacts[:, 1].tolist() == [i % 2 == 0 for i in range(18)]
    path = clip.save(tmp_path / "m.npz")
    with np.load(path, allow_pickle=False) as z:
        assert z["contacts"].dtype == bool and z["contacts"].shape == (18, 2)
        assert z["parents"].tolist() == list(PARENTS)
        np.testing.assert_allclose(z["rest_offsets"], rest_offsets(joints), atol=1e-6)
    back = MotionClip.load(path)
    np.testing.assert_array_equal(back.joints, joints)
    np.testing.assert_array_equal(back.contacts, clip.contacts)
    assert back.texts == clip.texts and back.fps == 30.0 and back.primitive.tolist() == primitive_layout(2).tolist()
    assert back.meta == {"seed": 3, "success": True}
    cut = back.cut(1)
    assert cut.frames == 10 and len(cut.actions) == 1 and cut.contacts.shape == (10, 2)


def test_old_files_without_the_new_keys_still_load(tmp_path):
    joints = walking()
    np.savez(tmp_path / "old.npz", joints=joints)  # a file from before fps/texts/contacts were written
    clip = MotionClip.load(tmp_path / "old.npz")
    assert clip.fps == 30.0 and clip.texts == [""] * 18 and clip.contacts.shape == (18, 2)
    assert load_motion_npz(tmp_path / "old.npz")["contacts"].shape == (18, 2)


def test_malformed_clip_is_one_line_error(tmp_path):
    with pytest.raises(DataError, match="texts has 1 entries for 18 frames"):
        MotionClip(walking(), texts=["walk"])
    np.savez(tmp_path / "bad.npz", joints=np.zeros((4, 21, 3)))
    with pytest.raises(DataError, match="must be"):
        MotionClip.load(tmp_path / "bad.npz")
