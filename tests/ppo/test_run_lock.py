"""One writer per run directory, and Ctrl-C saves before it stops.

A real ``latentrl train`` process holds its run directory; a second writer (``--resume`` of the same
folder, in this process) is refused at once with exit 2, naming the holder's PID. SIGINT to the
first process then makes it save the iteration it is in and exit 130; ``--resume`` continues there.
"""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from latentrl.app.cli import main
from latentrl.errors import ConfigError
from latentrl.motion import save_motion_model
from latentrl.ppo.checkpoint import iteration_checkpoints, read_checkpoint
from latentrl.runlock import LOCK_FILE, RunLock
from tests.helpers import make_tiny_model

TINY = Path(__file__).resolve().parents[2] / "configs" / "tiny.yaml"


def test_a_second_lock_on_one_folder_is_refused_naming_the_pid(tmp_path):
    with RunLock(tmp_path / "run"):
        with pytest.raises(ConfigError, match=rf"in use by another latentrl process \(PID {os.getpid()}\)"):
            RunLock(tmp_path / "run").acquire()
    with RunLock(tmp_path / "run"):  # released: the next writer gets it; the stale file blocks nothing
        pass


def wait_until(condition, proc: subprocess.Popen, what: str, timeout: float = 180.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert proc.poll() is None, f"the training process ended before {what}"
        assert time.monotonic() < deadline, f"no {what} after {timeout} s"
        time.sleep(0.05)


def test_two_concurrent_writers_never_mix_and_ctrl_c_saves(tmp_path, capsys):
    motion = save_motion_model(make_tiny_model(), tmp_path / "tiny.pt")
    run = tmp_path / "run"
    argv = [sys.executable, "-m", "latentrl.app.cli", "train", str(TINY), "--set", f"env.motion={motion}",
            "--set", "ppo.checkpoint_every=0", "--total-steps", str(64 * 100_000), "--run-dir", str(run),
            "--no-progress"]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    with open(tmp_path / "first.err", "w") as err:
        first = subprocess.Popen(argv, stdout=err, stderr=subprocess.STDOUT, env=env, cwd=tmp_path)
    try:
        log = run / "train.log"
        wait_until(lambda: log.is_file() and "start at iteration" in log.read_text(), first, "training start")
        assert (run / LOCK_FILE).read_text().strip() == str(first.pid)

        assert main(["train", "--resume", str(run), "--no-progress"]) == 2  # the second writer
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"in use by another latentrl process (PID {first.pid})" in err
        assert not iteration_checkpoints(run)  # it wrote nothing

        first.send_signal(signal.SIGINT)
        assert first.wait(timeout=180) == 130
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()
    text = (tmp_path / "first.err").read_text()
    assert "interrupted: saved iteration" in text, text[-2000:]
    saved = iteration_checkpoints(run)
    assert len(saved) == 1 and read_checkpoint(saved[0])["iteration"] >= 1  # checkpoint_every=0: Ctrl-C wrote it
