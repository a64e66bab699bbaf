"""Checks before writing: devices, unwritable folders, full disks, and cleanup of what a failed command created."""

import os
import shutil
from pathlib import Path

import pytest
import torch

from latentrl import preflight
from latentrl.app.cli import main
from latentrl.errors import ConfigError, DataError, NonFiniteError
from latentrl.motion import save_motion_model
from latentrl.preflight import NewOutput, check_device, check_free_space, check_writable
from tests.helpers import make_tiny_model

ROOT = Path(__file__).resolve().parents[1]
TINY = ROOT / "configs" / "tiny.yaml"
IS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0



@pytest.fixture(scope="module")
def motion_file(tmp_path_factory):
    return save_motion_model(make_tiny_model(), tmp_path_factory.mktemp("motion") / "tiny.pt")


def tree(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


@pytest.mark.parametrize(("device", "message"), [
    ("tpu", "unknown device 'tpu'"),
    ("cuda:x", "unknown device 'cuda:x'"),
    ("", "unknown device ''"),
    ("meta", "device type 'meta' is not supported"),
])
def test_devices_that_do_not_parse_or_are_unsupported(device, message):
    with pytest.raises(ConfigError, match=f"^--device: {message}"):
        check_device(device)


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has CUDA")
def test_cuda_absent_is_a_clear_message():
    for device in ("cuda", "cuda:0", "cuda:7"):
        with pytest.raises(ConfigError, match=f"ppo.device: '{device}' requested but CUDA is not available"):
            check_device(device, "ppo.device")
    assert check_device("cpu").type == "cpu"


@pytest.mark.skipif(torch.backends.mps.is_available(), reason="this machine has MPS")
def test_mps_absent_is_a_clear_message():
    with pytest.raises(ConfigError, match="'mps' requested but MPS is not available"):
        check_device("mps")


def test_check_writable_probes_without_creating(tmp_path):
    target = tmp_path / "a" / "b"
    check_writable(target)
    assert not (tmp_path / "a").exists() and tree(tmp_path) == set()
    (tmp_path / "file").write_text("x")
    with pytest.raises(ConfigError, match="exists and is not a directory"):
        check_writable(tmp_path / "file")
    with pytest.raises(ConfigError, match="is a file, not a directory"):
        check_writable(tmp_path / "file" / "run")


def test_unwritable_folder_is_refused(tmp_path, monkeypatch):
    def refuse(*args, **kwargs):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(preflight.tempfile, "mkstemp", refuse)
    with pytest.raises(ConfigError, match=r"run directory .*run is not writable \(Permission denied in .*\)"):
        check_writable(tmp_path / "run", "run directory")


@pytest.mark.skipif(IS_ROOT, reason="root ignores permission bits (the monkeypatched probe covers this)")
def test_read_only_folder_is_refused(tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        with pytest.raises(ConfigError, match="is not writable"):
            check_writable(folder / "run")
    finally:
        folder.chmod(0o755)


def test_full_disk_is_refused(tmp_path, monkeypatch):
    usage = shutil.disk_usage(tmp_path)
    monkeypatch.setattr(preflight.shutil, "disk_usage", lambda p: usage._replace(free=5 << 20))
    with pytest.raises(ConfigError, match=r"only 5 MiB free on its disk, this run needs about 64 MiB"):
        check_free_space(tmp_path / "run", 64 << 20, "run directory")
    check_free_space(tmp_path / "run", 1 << 20)


def test_new_output_removes_only_what_it_created(tmp_path):
    keep = tmp_path / "mine"
    keep.mkdir()
    (keep / "old.txt").write_text("x")
    with pytest.raises(DataError):
        with NewOutput(keep / "a" / "b"):
            (keep / "a" / "b").mkdir(parents=True)
            (keep / "a" / "b" / "partial.npz").write_text("x")
            raise DataError("bad input")
    assert tree(tmp_path) == {"mine", "mine/old.txt"}
    with pytest.raises(DataError):
        with NewOutput(keep):  # existed before: never removed
            raise DataError("bad input")
    assert keep.is_dir()
    with pytest.raises(NonFiniteError):  # a training fault: its logs stay
        with NewOutput(tmp_path / "run"):
            (tmp_path / "run").mkdir()
            raise NonFiniteError("nan")
    assert (tmp_path / "run").is_dir()
    with pytest.raises(DataError):
        with NewOutput(tmp_path / "kept") as out:
            (tmp_path / "kept").mkdir()
            out.keep()
            raise DataError("after the command produced something")
    assert (tmp_path / "kept").is_dir()


def test_train_refuses_full_disk_and_unwritable_dir_before_writing(motion_file, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    usage = shutil.disk_usage(tmp_path)
    args = ["train", str(TINY), "--set", f"env.motion={motion_file}", "--run-dir", "runs/r", "--no-progress"]
    with monkeypatch.context() as m:
        m.setattr(preflight.shutil, "disk_usage", lambda p: usage._replace(free=1 << 20))
        assert main(args) == 2
    err = capsys.readouterr().err
    assert err.startswith("latentrl: error: run directory runs/r: only 1 MiB free") and err.count("\n") == 1
    assert tree(tmp_path) == set()
    def read_only(*args, **kwargs):
        raise OSError(30, "Read-only file system")

    with monkeypatch.context() as m:
        m.setattr(preflight.tempfile, "mkstemp", read_only)
        assert main(args) == 2
    assert "run directory runs/r is not writable (Read-only file system" in capsys.readouterr().err
    assert tree(tmp_path) == set()


def test_fresh_run_refuses_a_folder_that_holds_a_run(motion_file, tmp_path, capsys):
    run = tmp_path / "run"
    (run / "checkpoints").mkdir(parents=True)
    (run / "checkpoints" / "iter_3.pt").write_bytes(b"x")
    code = main(["train", str(TINY), "--set", f"env.motion={motion_file}", "--run-dir", str(run), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 2 and f"--run-dir {run} already holds a training run; continue it with --resume" in err
    assert tree(run) == {"checkpoints", "checkpoints/iter_3.pt"}


def test_disk_full_during_a_run_is_one_line_exit_1_keeping_the_previous_checkpoint(motion_file, tmp_path, monkeypatch,
                                                                                     capsys):
    from latentrl import safe_io

    real_fsync, calls = safe_io.os.fsync, []

    def fsync(fd):
        calls.append(fd)
        if len(calls) == 3:  # config.yaml, iter_1.pt, then the write of iter_2.pt fails
            raise OSError(28, "No space left on device")
        real_fsync(fd)

    monkeypatch.setattr(safe_io.os, "fsync", fsync)
    run = tmp_path / "run"
    code = main(["train", str(TINY), "--set", f"env.motion={motion_file}", "--total-steps", "192", "--run-dir",
                 str(run), "--no-progress"])
    err = capsys.readouterr().err
    assert code == 1 and err.startswith("latentrl: error: No space left on device") and err.count("\n") == 1
    assert sorted(p.name for p in (run / "checkpoints").iterdir()) == ["iter_1.pt"]  # no temporary file left
    assert not (run / "final.pt").exists()
