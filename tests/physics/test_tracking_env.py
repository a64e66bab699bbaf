"""Stage 2: the learned tracker's env (shapes, reference state init, early termination, reward), its training
command (checkpoint, resume), ``physics track --tracker`` and one-line refusals of bad config fields."""

import json

import numpy as np
import pytest
import torch

pytest.importorskip("mujoco")

from latentrl.app.cli import main  # noqa: E402
from latentrl.physics.humanoid import build_humanoid  # noqa: E402
from latentrl.physics.reference import build_reference  # noqa: E402
from latentrl.physics.tracking_env import OBS_DIM, REWARD_WEIGHTS, Character, Motion, TrackingEnv  # noqa: E402


@pytest.fixture(scope="module")
def humanoid():
    return build_humanoid(1.72)


@pytest.fixture(scope="module")
def sway(humanoid):
    """A 2 s reference of the rest pose whose pelvis sways 3 cm sideways (no motion model needed)."""
    frames = 60
    joints = np.tile(humanoid.rest_joints, (frames, 1, 1))
    joints[:, :, 0] += 0.03 * np.sin(np.linspace(0, 2 * np.pi, frames))[:, None]
    return Motion.of(build_reference(joints, None, 30.0, humanoid), humanoid)


def test_env_shapes_and_finite_values(humanoid, sway):
    env = TrackingEnv(humanoid, [sway], 3, episode_frames=20)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (3, OBS_DIM) and obs.dtype == torch.float32 and torch.isfinite(obs).all()
    gen = torch.Generator().manual_seed(0)
    for _ in range(5):
        obs, reward, terminated, truncated, infos = env.step(torch.rand(3, 63, generator=gen) * 2 - 1)
        assert obs.shape == (3, OBS_DIM) and torch.isfinite(obs).all()
        assert reward.shape == (3,) and ((reward >= 0) & (reward <= 1)).all()
        assert terminated.shape == truncated.shape == (3,)
        assert set(infos) >= {f"reward/{k}" for k in REWARD_WEIGHTS}
    assert env.total_steps == 15


def test_reset_starts_at_a_random_frame_in_the_reference_pose(humanoid, sway):
    env = TrackingEnv(humanoid, [sway], 8)
    env.reset(seed=1)
    starts = {c.t for c in env.chars}
    assert len(starts) > 1  # random start frames
    for c in env.chars:
        sim = c.sim.data.xpos[c.sim.body_index]
        assert np.abs(sim - sway.kinematic[c.t]).max() < 1e-3  # the reference pose at that frame, within 1 mm


def test_reward_is_one_per_term_on_the_reference(humanoid, sway):
    char = Character(humanoid, 2.0, 0.5)
    char.reset_to(sway, 30)
    terms = char.rewards()
    assert set(terms) == set(REWARD_WEIGHTS)
    assert all(v > 0.999 for v in terms.values()), terms
    assert abs(sum(REWARD_WEIGHTS.values()) - 1.0) < 1e-9  # so the reward's maximum is 1


def test_early_termination_fires_on_a_dropped_body(humanoid, sway):
    env = TrackingEnv(humanoid, [sway], 2, terminate_distance=0.3)
    env.reset(seed=0)
    c = env.chars[1]
    c.sim.data.qpos[2] = 0.15  # the body lies on the floor: pelvis 15 cm up, turned 90 degrees about x
    c.sim.data.qpos[3:7] = [np.cos(np.pi / 4), np.sin(np.pi / 4), 0.0, 0.0]
    c.sim.mj.mj_forward(c.sim.model, c.sim.data)
    _, _, terminated, truncated, infos = env.step(torch.zeros(2, 63))
    assert terminated.tolist() == [False, True] and not truncated[1]
    assert infos["_final_obs"].tolist() == [False, True] and infos["_episode"][1]
    assert env.chars[1].error() < 1e-3  # restarted on the reference


def test_assist_anneals_linearly(humanoid, sway):
    env = TrackingEnv(humanoid, [sway], 1, assist_anneal_steps=100, assist_final=0.2)
    assert env.assist_scale == 1.0
    env.total_steps = 50
    assert env.assist_scale == pytest.approx(0.6)
    env.total_steps = 1000
    assert env.assist_scale == pytest.approx(0.2)


def tiny_config(tmp_path, motion, **tracking):
    tracking = {"num_envs": 2, **tracking}
    lines = ["tracking:", f"  motion_files: ['{motion}']", f"  eval_files: ['{motion}']"]
    lines += [f"  {k}: {v}" for k, v in tracking.items()]
    lines += ["ppo:", "  total_steps: 32", "  num_steps: 8", "  num_minibatches: 2", "  update_epochs: 1",
              "  eval_every: 1", "  checkpoint_every: 1", "policy:", "  architecture: mlp", "  mlp_hidden: [16]"]
    path = tmp_path / "tracker.yaml"
    path.write_text("\n".join(lines) + "\n")
    return path


def test_two_iterations_write_a_checkpoint_and_resume(sampled_walk, tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["physics", "train-tracker", str(tiny_config(tmp_path, sampled_walk)), "--run-dir", str(run)]) == 0
    assert (run / "final.pt").is_file() and list((run / "checkpoints").glob("*.pt"))
    rows = [json.loads(x) for x in (run / "eval.jsonl").read_text().splitlines()]
    assert [r["iteration"] for r in rows] == [1, 2]
    assert {"success", "mpjpe_mm", "assist_percent_body_weight", "train_assist_scale"} <= set(rows[0])
    assert main(["physics", "train-tracker", "--resume", str(run), "--total-steps", "64"]) == 0
    assert "trained 4 iterations (64 env steps)" in capsys.readouterr().out
    rows = [json.loads(x) for x in (run / "eval.jsonl").read_text().splitlines()]
    assert [r["iteration"] for r in rows] == [1, 2, 3, 4]
    assert rows[-1]["train_assist_scale"] < rows[1]["train_assist_scale"]  # the schedule went on from step 32
    # the learned tracker executes a motion through physics track
    out = tmp_path / "tracked"
    code = main(["physics", "track", str(sampled_walk), "--out", str(out), "--tracker", str(run / "final.pt")])
    assert code in (0, 4)  # 4: the (barely trained) tracker fell; outputs are written either way
    report = json.loads((out / "report.json").read_text())
    assert report["tracker"] == str(run / "final.pt") and report["tracking"]["mpjpe_mm"] > 0
    assert "--tracker" in report["command"]


@pytest.mark.parametrize("field,value,expected", [
    ("num_envs", 0, "tracking.num_envs: must lie in [1, 1024]"),
    ("terminate_distance", -1, "tracking.terminate_distance"),
    ("assist_final", 2, "tracking.assist_final"),
    ("no_such_field", 1, "no_such_field"),
])
def test_bad_config_field_is_a_one_line_error(tmp_path, capsys, field, value, expected):
    cfg = tiny_config(tmp_path, tmp_path / "unused.npz", **{field: value})
    assert main(["physics", "train-tracker", str(cfg), "--run-dir", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and expected in err and str(cfg) in err


def test_tracker_that_is_not_a_tracker_checkpoint_is_refused(sampled_walk, tmp_path, capsys):
    bogus = tmp_path / "x.pt"
    bogus.write_bytes(b"not a checkpoint")
    code = main(["physics", "track", str(sampled_walk), "--out", str(tmp_path / "o"), "--tracker", str(bogus)])
    assert code == 2 and len(capsys.readouterr().err.strip().splitlines()) == 1
