"""An unpacked DART download drives train -> eval -> render -> export with one flag (issue 16, part 1).

The DART-format parity folder (random weights, DART's layout and file formats) stands in for the
release. It has no CLIP table, so the copy gets one, as a real download has
(``data/seq_data_zero_male/train_text_embedding_dict.pkl``), and no ``seed_history.npz``, so the
episodes start from the mean pose of its normalizer.
"""

from __future__ import annotations

import pickle
import shutil

import numpy as np
import pytest
import torch

from latentrl.app.cli import main
from latentrl.errors import CheckpointError
from latentrl.motion.representation import SLICES, joints_of


@pytest.fixture()
def download(parity_dir, tmp_path):
    root = tmp_path / "DART"
    for part in ("mld_denoiser", "mvae", "data"):
        shutil.copytree(parity_dir / part, root / part)
    for path in root.rglob("*"):
        path.chmod(0o755 if path.is_dir() else 0o644)
    rng = np.random.default_rng(0)
    table = {text: rng.standard_normal(512).astype(np.float32) for text in ("walk", "run", "hop on left leg")}
    with open(root / "data" / "seq_data_zero_male" / "train_text_embedding_dict.pkl", "wb") as f:
        pickle.dump(table, f)
    return root / "mld_denoiser" / "mld_parity_A" / "checkpoint_1.pt"


def test_mean_pose_seed_is_a_still_canonical_pose(download):
    from latentrl.motion import load_motion_model

    model = load_motion_model(download)
    assert model.info["seed"] == "mean-pose"
    seed = model.seed_history
    assert seed.shape == (1, 2, 276)
    joints = joints_of(seed)[0]
    assert torch.allclose(joints[0, 0], torch.zeros(3), atol=1e-5)  # pelvis at the canonical origin
    assert abs(float(joints[0, 2, 1] - joints[0, 1, 1])) < 1e-5  # hips along x
    assert float(seed[..., SLICES["transl_delta"]].abs().max()) < 1e-6
    assert float(seed[..., SLICES["joints_delta"]].abs().max()) < 1e-6
    assert torch.allclose(seed[0, 0], seed[0, 1])
    state = model.initial_state(2)
    assert float(state.world.apply(joints_of(state.history))[..., 2].amin()) == pytest.approx(0.0, abs=1e-5)


def test_seed_history_file_formats(download, tmp_path):
    from latentrl.motion import load_motion_model
    from latentrl.motion.seed import load_seed_file

    model = load_motion_model(download)
    canon = model.seed_history.numpy()
    np.savez(tmp_path / "seed.npz", history=canon)
    assert np.allclose(load_seed_file(tmp_path / "seed.npz").numpy(), canon)
    world = canon[0].copy()
    world[:, SLICES["transl"]] += 2.0
    world[:, SLICES["joints"]] += np.tile([2.0, 2.0, 2.0], 22)  # a motion file: world features
    np.savez(tmp_path / "motion.npz", features=world, fps=30.0)
    assert np.allclose(load_seed_file(tmp_path / "motion.npz").numpy(), canon, atol=1e-5)
    np.savez(tmp_path / "bad.npz", history=np.zeros((1, 3, 276), np.float32))
    with pytest.raises(CheckpointError, match=r"must be \(K, 2, 276\)"):
        load_seed_file(tmp_path / "bad.npz")
    seeded = load_motion_model(download, seed_history=tmp_path / "motion.npz")
    assert seeded.info["seed"].endswith("motion.npz")


def test_train_eval_render_export_on_a_dart_download(download, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    run = tmp_path / "run"
    sets = [f"env.motion={download}", "env.num_envs=4", "ppo.num_steps=4", "ppo.num_minibatches=1",
            "ppo.update_epochs=1", "ppo.eval_every=0", "ppo.checkpoint_every=0", "policy.latent_dim=32", "threads=1"]
    argv = ["train", "configs/reach_walk.yaml", "--total-steps", "32", "--run-dir", str(run), "--no-progress"]
    assert main(argv + [x for s in sets for x in ("--set", s)]) == 0
    assert "trained 2 iterations" in capsys.readouterr().out
    out = tmp_path / "eval"
    assert main(["eval", str(run / "final.pt"), "--motion", str(download), "--paths", "dart_demo_walk",
                 "--episodes", "1", "--max-steps", "3", "--out", str(out), "--render", "gif"]) == 0
    assert (out / "report.md").is_file() and (out / "paths.png").is_file()
    assert list((out / "renders").glob("*.gif")) and list((out / "renders").glob("*.bvh"))
    motion = sorted((out / "motions").glob("*.npz"))[0]
    assert main(["motion", "export-bvh", str(motion), "--out", str(tmp_path / "walk.bvh")]) == 0
    assert (tmp_path / "walk.bvh").read_text().startswith("HIERARCHY")
