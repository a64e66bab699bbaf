"""No write lands in a file through a symbolic link: locks and logs are refused, atomic writes replace the link.

Files written in place (a run folder's ``.lock``, ``train.log``) are opened with ``O_NOFOLLOW``: a
link there is refused with one line and exit 2, and the file it points to keeps its bytes. Files written
atomically (checkpoints, reports, motions) go to a fresh temporary file that is renamed over the final
name, which replaces a link at that name instead of following it. ``eval`` and ``optimize`` hold the run
lock on their ``--out`` folder: a second one into the same folder is refused, naming the folder and the PID.
"""

import os
from pathlib import Path

import pytest
import torch

from latentrl.app.cli import main
from latentrl.errors import ConfigError
from latentrl.motion import save_motion_model
from latentrl.ppo.progress import LOG_FILE, RunProgress
from latentrl.runlock import LOCK_FILE, RunLock
from latentrl.safe_io import atomic_write_bytes, atomic_write_text, open_no_follow, save_torch_atomic
from tests.helpers import make_tiny_model

TINY = Path(__file__).resolve().parents[1] / "configs" / "tiny.yaml"
MOTION_TINY = Path(__file__).resolve().parents[1] / "configs" / "motion" / "tiny.yaml"
SECRET = "precious bytes\n"

pytestmark = pytest.mark.skipif(not hasattr(os, "symlink") or os.name == "nt", reason="POSIX links and flock")


def victim(tmp_path: Path) -> Path:
    """A file outside the run folder that a link points to; its bytes must never change."""
    path = tmp_path / "elsewhere" / "victim.txt"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(SECRET)
    return path


def linked(folder: Path, name: str, target: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / name).symlink_to(target)
    return folder / name


# --------------------------------------------------------------------------- the helper
def test_open_no_follow_refuses_a_link_a_hard_link_and_a_fifo(tmp_path):
    target = victim(tmp_path)
    flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT
    with pytest.raises(ConfigError, match=r"link\.log: the training log is a symbolic link \(to .*victim\.txt\); "
                                          r"refused to write through it"):
        open_no_follow(linked(tmp_path / "run", "link.log", target), flags, "training log")
    dangling = linked(tmp_path / "run", "dangling.log", tmp_path / "not-there.txt")
    with pytest.raises(ConfigError, match="is a symbolic link"):  # O_CREAT through a dangling link creates nothing
        open_no_follow(dangling, flags, "training log")
    assert not (tmp_path / "not-there.txt").exists()
    os.link(target, tmp_path / "run" / "hard.log")
    with pytest.raises(ConfigError, match="has 2 hard links"):
        open_no_follow(tmp_path / "run" / "hard.log", flags, "training log")
    os.mkfifo(tmp_path / "run" / "fifo.log")
    with pytest.raises(ConfigError, match="is not a regular file"):  # fails at once, no reader needed
        open_no_follow(tmp_path / "run" / "fifo.log", flags, "training log")
    assert target.read_text() == SECRET
    fd = open_no_follow(tmp_path / "run" / "plain.log", flags, "training log")
    os.write(fd, b"ok\n")
    os.close(fd)
    assert (tmp_path / "run" / "plain.log").read_text() == "ok\n"


# --------------------------------------------------------------------------- the run lock and train.log
def test_a_linked_lock_file_is_refused_and_its_target_kept(tmp_path):
    target = victim(tmp_path)
    linked(tmp_path / "run", LOCK_FILE, target)
    with pytest.raises(ConfigError, match=r"\.lock: the lock file is a symbolic link"):
        RunLock(tmp_path / "run").acquire()
    assert target.read_text() == SECRET


def test_a_linked_train_log_is_refused_before_the_first_line(tmp_path):
    target = victim(tmp_path)
    linked(tmp_path / "run", LOG_FILE, target)
    with pytest.raises(ConfigError, match=r"train\.log: the training log is a symbolic link"):
        RunProgress(tmp_path / "run", total_steps=10, enabled=False)
    assert target.read_text() == SECRET
    (tmp_path / "plain").mkdir()
    plain = RunProgress(tmp_path / "plain", total_steps=10, enabled=False)
    plain.write("first line")
    (tmp_path / "plain" / LOG_FILE).unlink()
    (tmp_path / "plain" / LOG_FILE).symlink_to(target)  # a link put there during the run
    with pytest.raises(ConfigError, match="is a symbolic link"):
        plain.write("second line")
    plain.close()
    assert target.read_text() == SECRET


@pytest.fixture(scope="module")
def tiny_motion(tmp_path_factory):
    return save_motion_model(make_tiny_model(), tmp_path_factory.mktemp("motion") / "tiny.pt")


def train_argv(run: Path, motion: Path) -> list[str]:
    return ["train", str(TINY), "--set", f"env.motion={motion}", "--run-dir", str(run), "--no-progress"]


@pytest.mark.parametrize("name, what", [(LOCK_FILE, "lock file"), (LOG_FILE, "training log")])
def test_train_refuses_a_run_folder_with_a_linked_lock_or_log(name, what, tmp_path, tiny_motion, capsys):
    target = victim(tmp_path)
    run = tmp_path / "run"
    linked(run, name, target)
    assert main(train_argv(run, tiny_motion)) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{name}: the {what} is a symbolic link" in err, err
    assert target.read_text() == SECRET
    assert (run / name).is_symlink()  # left as it was: the user decides what it should be


def test_resume_refuses_a_linked_lock_in_a_finished_run(tmp_path, tiny_motion, capsys):
    run = tmp_path / "run"
    assert main(train_argv(run, tiny_motion)) == 0
    capsys.readouterr()
    target = victim(tmp_path)
    (run / LOCK_FILE).unlink()
    (run / LOCK_FILE).symlink_to(target)
    assert main(["train", "--resume", str(run), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and ".lock: the lock file is a symbolic link" in err, err
    assert target.read_text() == SECRET
    log_before = (run / LOG_FILE).read_text()
    (run / LOCK_FILE).unlink()
    (run / LOG_FILE).unlink()
    (run / LOG_FILE).symlink_to(target)
    assert main(["train", "--resume", str(run), "--total-steps", "192", "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "train.log: the training log is a symbolic link" in err, err
    assert target.read_text() == SECRET and log_before


@pytest.mark.parametrize("name, what", [(LOCK_FILE, "lock file"), (LOG_FILE, "training log")])
def test_motion_train_refuses_a_linked_lock_or_log(name, what, tmp_path, capsys):
    target = victim(tmp_path)
    run = tmp_path / "run"
    linked(run, name, target)
    assert main(["motion", "train", str(MOTION_TINY), "--run-dir", str(run), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{name}: the {what} is a symbolic link" in err, err
    assert target.read_text() == SECRET


# --------------------------------------------------------------------------- atomic writes
def test_atomic_writes_replace_a_link_at_the_final_name_instead_of_following_it(tmp_path):
    """Reports, checkpoints and motions: the link is replaced by the new file; the file it named is untouched."""
    target = victim(tmp_path)
    out = tmp_path / "out"
    for name, write in (("report.json", lambda p: atomic_write_text(p, "{}\n")),
                        ("motion.npz", lambda p: atomic_write_bytes(p, b"new bytes")),
                        ("final.pt", lambda p: save_torch_atomic({"w": torch.ones(2)}, p))):
        path = linked(out, name, target)
        write(path)
        assert not path.is_symlink() and path.is_file(), name
        assert target.read_text() == SECRET, name
    assert torch.load(out / "final.pt", weights_only=True)["w"].tolist() == [1.0, 1.0]
    assert sorted(p.name for p in out.iterdir()) == ["final.pt", "motion.npz", "report.json"]  # no temporaries
    from latentrl.datasets.motion_text import META_FILE, write_meta

    linked(out, f"{META_FILE}.tmp", target)  # the fixed temporary name a dataset's meta.json once went through
    write_meta(out, {"name": "tiny"})
    assert target.read_text() == SECRET and (out / META_FILE).read_text().startswith("{")


def test_plots_and_gifs_never_write_through_a_link_at_their_final_or_temporary_name(tmp_path):
    """matplotlib and Pillow open files by name: they write a fresh, randomly named temporary file."""
    from latentrl.evaluation.plots import save_paths_png
    from latentrl.render import render_gif
    from tests.helpers import walking_clip

    target = victim(tmp_path)
    out = tmp_path / "eval"
    for name in ("paths.png", "ep.gif"):  # the final names, and the fixed temporary names used before
        linked(out, name, target)
        linked(out, f".{name}.tmp{Path(name).suffix}", target)
    save_paths_png(out / "paths.png", [])
    render_gif(out / "ep.gif", walking_clip(6)["joints"].numpy(), stride=3)
    assert target.read_text() == SECRET
    assert (out / "paths.png").read_bytes()[:4] == b"\x89PNG" and (out / "ep.gif").read_bytes()[:3] == b"GIF"
    assert not any(p.name.endswith((".tmp.png", ".tmp.gif")) and not p.is_symlink() for p in out.iterdir())


# --------------------------------------------------------------------------- one eval or optimize per --out folder
@pytest.fixture(scope="module")
def near_paths(tmp_path_factory) -> Path:
    """A one-path suite for the tiny policy of ``eval_files`` (tests/conftest.py)."""
    from tests.evaluation.conftest import NEAR, write_paths

    return write_paths(tmp_path_factory.mktemp("near"), [NEAR], "near.json")


def refused_while_held(out: Path, argv: list[str], capsys) -> None:
    """Run ``argv`` while this process holds ``out``'s lock: exit 2, one line naming the folder and our PID."""
    out.mkdir()
    (out / "report.json").write_text("the first writer's report\n")
    with RunLock(out):  # the first eval or optimize, still writing
        assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    assert f"--out folder {out} is in use by another latentrl process (PID {os.getpid()})" in err, err
    assert (out / "report.json").read_text() == "the first writer's report\n"  # nothing of the second one
    assert sorted(p.name for p in out.iterdir()) == [LOCK_FILE, "report.json"]


def test_a_second_eval_into_the_same_out_folder_is_refused(eval_files, near_paths, tmp_path, capsys):
    out = tmp_path / "out"
    argv = ["eval", str(eval_files["policy"]), "--motion", str(eval_files["motion"]), "--paths",
            str(near_paths), "--episodes", "1", "--max-steps", "2", "--device", "cpu", "--render", "0",
            "--out", str(out)]
    refused_while_held(out, argv, capsys)
    assert main(argv) == 0  # once the holder is gone, the folder is free again
    assert (out / "report.json").read_text().startswith("{")


def test_a_second_optimize_into_the_same_out_folder_is_refused(eval_files, tmp_path, capsys):
    import json

    suite = tmp_path / "suite.json"
    suite.write_text(json.dumps({"format": "latentrl.constraints/1", "problems": [
        {"name": "p", "start": {"seed": 0}, "text": "walk", "primitives": 2,
         "constraints": [{"type": "joint", "frame": 3, "joint": "pelvis", "position": [0, 0, 1]}]}]}))
    out = tmp_path / "out"
    argv = ["optimize", str(suite), "--motion", str(eval_files["motion"]), "--steps", "1", "--out", str(out),
            "--no-progress"]
    refused_while_held(out, argv, capsys)
    assert main(argv) == 0
    assert (out / "report.json").read_text().startswith("{")


def test_an_interrupt_during_the_temporary_files_creation_waits_until_cleanup_can_see_it():
    """SIGTERM arriving while ``mkstemp`` creates the file is held back, then raised where the file is removed:
    sent to the main thread, to the process, and to another thread (Python runs the handler in the main thread
    whichever thread the OS picked; a process-directed SIGTERM taken by a torch or tqdm thread left an
    interrupted evaluation's temporary report behind)."""
    import os
    import signal
    import threading

    from latentrl import safe_io

    seen = []

    def record(*_) -> None:
        seen.append("term")

    previous = signal.signal(signal.SIGTERM, record)

    def bytecodes() -> None:  # where a tripped handler would run
        for _ in range(10_000):
            pass

    try:
        with safe_io._signals_held():
            signal.pthread_kill(threading.main_thread().ident, signal.SIGTERM)
            bytecodes()
            os.kill(os.getpid(), signal.SIGTERM)
            bytecodes()
            other = threading.Thread(target=lambda: signal.pthread_kill(threading.get_ident(), signal.SIGTERM))
            other.start()
            other.join()
            bytecodes()
            assert seen == []  # held back inside
        assert seen == ["term"] * 3  # delivered once the block ends
        assert signal.getsignal(signal.SIGTERM) is record  # the caller's handler is back in place
    finally:
        signal.signal(signal.SIGTERM, previous)
