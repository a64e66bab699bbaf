"""History export: episodes split at resets, the shared motion format, bounded by clearing."""

import numpy as np
import pytest
import torch

from latentrl.render import load_motion_npz, save_motion_npz
from tests.envs.conftest import actions


def recorded_env(make_reach, **kwargs):
    env = make_reach(2, max_episode_steps=2, record_history=True, texts=("walk", "run"), **kwargs)
    env.reset(seed=0)
    return env


def test_episodes_are_split_at_resets(make_reach):
    env = recorded_env(make_reach)
    seed_frames = env.history_world()[0].clone()
    sent = [actions(2, k) * 3 for k in range(3)]
    goals = []
    for act in sent:
        goals.append(env.goal_world[0].clone())
        env.step(act)
    first = env.export_history(0, episode=0)
    assert first["joints"].shape == (2 + 16, 22, 3) and first["joints"].dtype == np.float32
    assert first["fps"] == 30.0 and first["from_reset"] is True
    assert torch.equal(torch.from_numpy(first["joints"][:2]), seed_frames)
    assert first["texts"][2] in env.texts and first["texts"] == ["", ""] + [first["texts"][2]] * 16
    assert first["primitive"].tolist() == [-1, -1] + [0] * 8 + [1] * 8
    np.testing.assert_array_equal(first["actions"], torch.stack(sent[:2])[:, 0].clamp(-4, 4).numpy())
    np.testing.assert_array_equal(first["goals"], torch.stack(goals[:2]).numpy())
    latest = env.export_history(0)  # the running episode: seed + 1 step
    assert latest["joints"].shape == (10, 22, 3) and latest["actions"].shape == (1, 16)
    # the same frames, once placed from the decoded primitive, once from the re-canonicalized history
    np.testing.assert_allclose(latest["joints"][-2:], env.history_world()[0].numpy(), atol=1e-5)
    with pytest.raises(IndexError, match="2 recorded episodes"):
        env.export_history(0, episode=2)


def test_clear_history_keeps_the_current_frames(make_reach):
    env = recorded_env(make_reach)
    env.step(actions(2))
    env.clear_history()
    out = env.export_history(1)
    assert out["from_reset"] is False and out["joints"].shape == (2, 22, 3) and out["actions"].shape == (0, 16)
    np.testing.assert_array_equal(out["joints"], env.history_world()[1].numpy())


def test_features_are_consistent_with_joints_and_save_as_npz(make_reach, tmp_path):
    env = recorded_env(make_reach, record_features=True)
    env.step(actions(2))
    out = env.export_history(1)
    assert out["features"].shape == (10, 276)
    np.testing.assert_allclose(out["features"][:, 144:210].reshape(-1, 22, 3), out["joints"], atol=1e-5)
    path = save_motion_npz(tmp_path / "m.npz", **out)
    back = load_motion_npz(path)
    np.testing.assert_array_equal(back["joints"], out["joints"])
    assert back["goals"].shape == (1, 3)


def test_no_history_unless_requested(make_reach):
    env = make_reach(1)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="record_history=True"):
        env.export_history(0)
