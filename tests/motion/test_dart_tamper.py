"""Tampered DART layouts (args.yaml, mean/std pickle, text table): one line, exit 2, never a traceback.

Uses the DART parity layout in LATENTRL_SHARED (skips without it); each case edits a copy.
"""

import pickle
import re
import shutil

import numpy as np
import pytest
import yaml

from latentrl.app.cli import main
from latentrl.motion.checkpoint import load_motion_model

DEN = "mld_denoiser/mld_parity_A"
VAE = "mvae/mvae_parity_A"
MS = "data/seq_data_zero_male/mean_std_h2_f8.pkl"


def edit_args(root, folder: str, old: str, new: str) -> None:
    path = root / folder / "args.yaml"
    inner = yaml.safe_load(path.read_text())
    assert old in inner, old
    path.write_text(yaml.safe_dump(inner.replace(old, new, 1)))


def write_pickle(path, obj) -> None:
    path.write_bytes(pickle.dumps(obj))


CASES = [
    ("args-random-bytes", lambda r: (r / DEN / "args.yaml").write_bytes(bytes(range(256)) * 4),
     r"args\.yaml: not a text DART args file"),
    ("num-layers-abc", lambda r: edit_args(r, DEN, "num_layers: 2", "num_layers: abc"),
     r"field 'num_layers': expected an integer in \[1, 16384\], got 'abc'"),
    ("diffusion-steps-0", lambda r: edit_args(r, DEN, "diffusion_steps: 10", "diffusion_steps: 0"),
     r"field 'diffusion_steps': expected an integer in \[1, 16384\], got '0'"),
    ("noise-schedule-banana", lambda r: edit_args(r, DEN, "noise_schedule: cosine", "noise_schedule: banana"),
     r"cannot build a motion model from this DART checkpoint .*banana"),
    ("data-dir-list", lambda r: edit_args(r, VAE, "data_dir: ./data/seq_data_zero_male", "data_dir: [1, 2]"),
     r"cannot build a motion model from this DART checkpoint"),
    ("inner-python-tag", lambda r: edit_args(r, DEN, "h_dim: 64", "h_dim: !!python/object/apply:os.system ['true']"),
     r"field 'h_dim': expected an integer"),
    ("h-dim-huge", lambda r: edit_args(r, DEN, "h_dim: 64", "h_dim: 4000000"),
     r"field 'h_dim': expected an integer in \[1, 16384\], got '4000000'"),
    ("mean-std-strings", lambda r: write_pickle(r / MS, (np.array(["a"] * 276), np.array(["b"] * 276))),
     r"mean_std_h2_f8\.pkl: mean: expected real numbers"),
    ("mean-std-zero-std", lambda r: write_pickle(r / MS, (np.zeros(276, np.float32), np.zeros(276, np.float32))),
     r"mean_std_h2_f8\.pkl: mean/std must be finite and std strictly positive"),
    ("text-table-string", lambda r: write_pickle(r / "data/seq_data_zero_male/train_text_embedding_dict.pkl",
                                                 {"walk": "not a vector"}),
     r"prompt 'walk': expected real numbers"),
]


@pytest.fixture
def dart_root(parity_dir, tmp_path):
    root = tmp_path / "dart"
    shutil.copytree(parity_dir, root)
    for p in root.rglob("*"):
        p.chmod(0o755 if p.is_dir() else 0o644)
    return root


@pytest.mark.parametrize(("tamper", "pattern"), [pytest.param(t, p, id=i) for i, t, p in CASES])
def test_tampered_dart_layout_is_one_line_exit_2(tamper, pattern, dart_root, capsys):
    tamper(dart_root)
    code = main(["motion", "info", "--motion", str(dart_root / DEN / "checkpoint_1.pt")])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
    assert re.search(pattern, err), f"{pattern!r} not in {err!r}"


def test_identity_hash_covers_the_normalizer(dart_root):
    before = load_motion_model(dart_root / DEN / "checkpoint_1.pt").info["sha256"]
    with open(dart_root / MS, "rb") as f:
        mean, std = pickle.load(f)  # noqa: S301 - our own test file
    write_pickle(dart_root / MS, (np.asarray(mean) + 1, np.asarray(std) * 10))
    after = load_motion_model(dart_root / DEN / "checkpoint_1.pt").info["sha256"]
    assert before != after
