"""Files from strangers never execute code: policy checkpoints (eval, --resume), torch files, DART's pickles and
tyro-tagged args.yaml, config YAML and numpy archives. Every payload would create a marker file if it ran."""

import os
import pickle
from pathlib import Path

import numpy as np
import pytest
import torch

from latentrl.app.cli import main
from latentrl.errors import CheckpointError, DataError
from latentrl.motion import save_motion_model
from latentrl.motion.checkpoint import load_motion_model
from latentrl.safe_io import load_pickle, load_torch, load_tyro_yaml

ROOT = Path(__file__).resolve().parents[1]
TINY = ROOT / "configs" / "tiny.yaml"


class Payload:
    """Unpickling calls ``func(*args)``: what an attacker's file does."""

    def __init__(self, func, *args):
        self.func, self.args = func, args

    def __reduce__(self):
        return self.func, self.args


def payloads(marker: Path) -> list[Payload]:
    return [Payload(os.system, f"touch {marker}"),
            Payload(exec, f"open({str(marker)!r}, 'w').write('pwned')"),
            Payload(eval, f"__import__('pathlib').Path({str(marker)!r}).touch()")]


@pytest.fixture(scope="module")
def motion_file(tmp_path_factory):
    from tests.helpers import make_tiny_model

    return save_motion_model(make_tiny_model(), tmp_path_factory.mktemp("motion") / "tiny.pt")



def test_malicious_policy_checkpoint_given_to_eval_does_not_run(motion_file, tmp_path, capsys):
    marker = tmp_path / "pwned"
    for i, payload in enumerate(payloads(marker)):
        policy = tmp_path / f"final{i}.pt"
        torch.save({"format": "latentrl.ppo/1", "policy": payload}, policy)
        code = main(["eval", str(policy), "--motion", str(motion_file), "--paths", "dart_demo_walk", "--device", "cpu"])
        err = capsys.readouterr().err
        assert code == 2 and "refused to load" in err and err.count("\n") == 1
        assert not marker.exists() and not (tmp_path / f"eval-final{i}").exists()


def test_malicious_checkpoint_in_a_run_is_skipped_on_resume(motion_file, tmp_path, capsys):
    run, marker = tmp_path / "run", tmp_path / "pwned"
    args = ["train", str(TINY), "--set", f"env.motion={motion_file}", "--total-steps", "192", "--run-dir", str(run),
            "--no-progress"]
    assert main(args) == 0
    torch.save({"format": "latentrl.ppo/1", "iteration": 99, "x": payloads(marker)[0]}, run / "final.pt")
    torch.save({"format": "latentrl.ppo/1", "iteration": 98, "x": payloads(marker)[1]},
               run / "checkpoints" / "iter_98.pt")
    with pytest.warns(UserWarning, match="skipping unusable checkpoint: .*refused to load"):
        assert main(["train", "--resume", str(run), "--no-progress"]) == 0
    assert not marker.exists()
    assert "start at iteration 2, 128 env steps" in (run / "train.log").read_text()  # iter_2.pt: the newest good one
    assert torch.load(run / "final.pt", weights_only=True)["env_steps"] == 192


def test_torch_loads_use_weights_only(tmp_path):
    marker = tmp_path / "pwned"
    for payload in payloads(marker):
        torch.save({"weights": torch.zeros(2), "x": payload}, tmp_path / "m.pt")
        with pytest.raises(CheckpointError, match="refused to load"):
            load_torch(tmp_path / "m.pt")
        with pytest.raises(CheckpointError, match="refused to load"):
            load_motion_model(tmp_path / "m.pt")
    assert not marker.exists()


def test_dart_pickles_go_through_the_restricted_unpickler(tmp_path):
    marker = tmp_path / "pwned"
    for protocol in (2, pickle.HIGHEST_PROTOCOL):
        for payload in payloads(marker):
            table = tmp_path / "train_text_embedding_dict.pkl"
            table.write_bytes(pickle.dumps({"walk": np.zeros(4, np.float32), "evil": payload}, protocol=protocol))
            with pytest.raises(CheckpointError, match="refused to unpickle: global '.*' is not allowed"):
                load_pickle(table, what="text-embedding table")
    assert not marker.exists()
    # what DART's files really hold still loads: numpy arrays, tensors and plain containers
    good = tmp_path / "mean_std.pkl"
    good.write_bytes(pickle.dumps((np.arange(3.0), torch.ones(2), {"a": [1, (2, 3)]}), protocol=2))
    mean, std, extra = load_pickle(good)
    assert mean.tolist() == [0.0, 1.0, 2.0] and std.tolist() == [1.0, 1.0] and extra == {"a": [1, (2, 3)]}


def test_tyro_args_yaml_is_parsed_without_constructing_objects(tmp_path):
    marker = tmp_path / "pwned"
    inner = (f"denoiser_args: !dataclass:DenoiserArgs\n"
             f"  mvae_path: !!python/object/apply:pathlib.PosixPath [mvae, exp, checkpoint.pt]\n"
             f"  evil: !!python/object/apply:os.system [touch {marker}]\n"
             f"  evil2: !!python/object/new:subprocess.Popen [[touch, {marker}]]\n"
             f"  shape: !!python/tuple [1, 128]\n")
    args = tmp_path / "args.yaml"
    import yaml

    args.write_text(yaml.safe_dump(inner))  # DART stores tyro's YAML as one YAML string
    data = load_tyro_yaml(args)
    den = data["denoiser_args"]
    assert den["mvae_path"] == "mvae/exp/checkpoint.pt" and den["shape"] == [1, 128]
    assert den["evil"] == [f"touch {marker}"] and den["evil2"] == [["touch", str(marker)]]  # plain data only
    assert not marker.exists()


def test_config_yaml_with_python_tags_is_refused(tmp_path, capsys):
    marker = tmp_path / "pwned"
    cfg = tmp_path / "evil.yaml"
    cfg.write_text(f"env: !!python/object/apply:os.system [touch {marker}]\n")
    assert main(["train", str(cfg), "--run-dir", str(tmp_path / "run")]) == 2
    assert "evil.yaml: invalid YAML: could not determine a constructor" in capsys.readouterr().err
    assert not marker.exists() and not (tmp_path / "run").exists()


def test_numpy_archives_with_pickled_objects_are_refused(tmp_path, motion_file, capsys):
    marker = tmp_path / "pwned"
    obj = np.empty(1, dtype=object)
    obj[0] = payloads(marker)[0]
    np.savez(tmp_path / "seed.npz", seed_history=obj)
    with pytest.raises(CheckpointError, match="seed.npz: not a readable seed-history .npz"):
        load_motion_model(motion_file, seed_history=tmp_path / "seed.npz")
    np.savez(tmp_path / "motion.npz", joints=np.zeros((4, 22, 3)), texts=obj)
    from latentrl.render import load_motion_npz

    with pytest.raises(DataError, match="motion.npz: not a readable motion .npz"):
        load_motion_npz(tmp_path / "motion.npz")
    assert main(["motion", "export-bvh", str(tmp_path / "motion.npz")]) == 2
    assert "not a readable motion .npz" in capsys.readouterr().err
    assert not marker.exists() and not (tmp_path / "motion.bvh").exists()
