import os
import pickle
import shutil

import pytest
import torch

from latentrl.errors import CheckpointError
from latentrl.motion import load_motion_model, save_motion_model
from latentrl.motion.checkpoint import load_normalizer
from latentrl.motion.representation import FEATURE_ORDER, SLICES


def test_latentrl_format_round_trip(tiny_model, tmp_path):
    path = save_motion_model(tiny_model, tmp_path / "m.pt", meta={"note": "test"})
    loaded = load_motion_model(path)
    assert loaded.info["note"] == "test" and len(loaded.info["sha256"]) == 64
    hist = tiny_model.seed_history
    text = tiny_model.encode_text(["walk"])
    noise = torch.randn(1, 1, 16)
    torch.testing.assert_close(
        loaded.sample_primitive(hist, loaded.encode_text(["walk"]), noise).future,
        tiny_model.sample_primitive(hist, text, noise).future,
    )
    assert torch.equal(loaded.pelvis_delta, tiny_model.pelvis_delta)
    # a folder holding motion_model.pt works too
    (tmp_path / "dir").mkdir()
    shutil.copy(path, tmp_path / "dir" / "motion_model.pt")
    assert load_motion_model(tmp_path / "dir").latent_shape == (1, 16)


def test_save_is_atomic_no_temp_left(tiny_model, tmp_path):
    save_motion_model(tiny_model, tmp_path / "m.pt")
    assert sorted(os.listdir(tmp_path)) == ["m.pt"]


def test_missing_and_unknown_files(tmp_path):
    with pytest.raises(CheckpointError, match="motion model not found"):
        load_motion_model(tmp_path / "nope.pt")
    torch.save({"hello": torch.ones(1)}, tmp_path / "x.pt")
    with pytest.raises(CheckpointError, match="unknown motion-model format"):
        load_motion_model(tmp_path / "x.pt")


def test_truncated_file_is_clear_error(tiny_model, tmp_path):
    path = save_motion_model(tiny_model, tmp_path / "m.pt")
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(CheckpointError, match="corrupt or truncated"):
        load_motion_model(path)


def test_nan_weights_rejected(tiny_model, tmp_path):
    from latentrl.motion.checkpoint import motion_model_state

    state = motion_model_state(tiny_model)
    state["vae_state"]["final_layer.weight"][0, 0] = float("nan")
    torch.save(state, tmp_path / "m.pt")
    with pytest.raises(CheckpointError, match="'final_layer.weight' contains NaN"):
        load_motion_model(tmp_path / "m.pt")


def test_shape_mismatch_names_key(tiny_model, tmp_path):
    from latentrl.motion.checkpoint import motion_model_state

    state = motion_model_state(tiny_model)
    state["vae_state"]["final_layer.bias"] = torch.zeros(5)
    torch.save(state, tmp_path / "m.pt")
    with pytest.raises(CheckpointError, match=r"shape mismatch at 'final_layer.bias': file has \(5,\)"):
        load_motion_model(tmp_path / "m.pt")


@pytest.fixture
def dart_copy(parity_dir, tmp_path):
    root = tmp_path / "dart"
    shutil.copytree(parity_dir, root, ignore=shutil.ignore_patterns("*.pt"))
    for rel in ("mld_denoiser/mld_parity_A/checkpoint_1.pt", "mvae/mvae_parity_A/checkpoint_1.pt"):
        shutil.copy(parity_dir / rel, root / rel)
    for p in root.rglob("*"):
        p.chmod(0o755 if p.is_dir() else 0o644)
    return root


def test_dart_paths_resolve_from_any_working_directory(dart_copy, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    model = load_motion_model(dart_copy / "mld_denoiser/mld_parity_A/checkpoint_1.pt")
    assert model.info["format"] == "dart" and model.latent_shape == (1, 32)


def test_dart_missing_vae_names_searched_places(dart_copy):
    shutil.rmtree(dart_copy / "mvae")
    with pytest.raises(
        CheckpointError,
        match=r"VAE checkpoint './mvae/mvae_parity_A/checkpoint_1.pt' named by .* "
        r"not found \(searched: ",
    ):
        load_motion_model(dart_copy / "mld_denoiser/mld_parity_A/checkpoint_1.pt")


def test_dart_overrides_and_text_table(dart_copy, tmp_path):
    ms = dart_copy / "data/seq_data_zero_male/mean_std_h2_f8.pkl"
    moved = tmp_path / "stats.pkl"
    shutil.move(ms, moved)
    with pytest.raises(CheckpointError, match="mean/std file"):
        load_motion_model(dart_copy / "mld_denoiser/mld_parity_A/checkpoint_1.pt")
    table = {"walk": torch.randn(512), "run": torch.randn(512)}
    with open(tmp_path / "table.pkl", "wb") as f:
        pickle.dump(table, f)
    model = load_motion_model(
        dart_copy / "mld_denoiser/mld_parity_A/checkpoint_1.pt", mean_std=moved, text_table=tmp_path / "table.pkl"
    )
    torch.testing.assert_close(model.encode_text(["run"])[0], table["run"])


def test_dart_seed_history_gives_pelvis_delta(dart_copy, tiny_model):
    import numpy as np

    np.savez(dart_copy / "seed_history.npz", seed_history=tiny_model.seed_history.numpy())
    model = load_motion_model(dart_copy / "mld_denoiser/mld_parity_A/checkpoint_1.pt")
    torch.testing.assert_close(model.pelvis_delta, tiny_model.pelvis_delta, atol=1e-5, rtol=0)


def test_legacy_mean_std_dict(tmp_path):
    stats = {}
    for k in FEATURE_ORDER:
        n = SLICES[k].stop - SLICES[k].start
        stats[k] = {"mean": torch.full((n,), float(SLICES[k].start)), "std": torch.ones(n)}
    with open(tmp_path / "mean_std.pkl", "wb") as f:
        pickle.dump(stats, f)
    norm = load_normalizer(tmp_path / "mean_std.pkl")
    assert norm.mean[SLICES["joints"]].eq(144).all() and norm.mean.shape == (276,)


def test_malicious_pickle_does_not_execute(tmp_path):
    marker = tmp_path / "pwned"

    class Evil:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    with open(tmp_path / "mean_std.pkl", "wb") as f:
        pickle.dump(Evil(), f)
    with pytest.raises(CheckpointError, match="refused to unpickle"):
        load_normalizer(tmp_path / "mean_std.pkl")
    assert not marker.exists()


def test_malicious_checkpoint_does_not_execute(tmp_path):
    marker = tmp_path / "pwned"

    class Evil:
        def __reduce__(self):
            return (os.system, (f"touch {marker}",))

    torch.save({"format": "latentrl.motion_model", "x": Evil()}, tmp_path / "m.pt")
    with pytest.raises(CheckpointError, match="refused to load"):
        load_motion_model(tmp_path / "m.pt")
    assert not marker.exists()
