"""SIGTERM (what SLURM, Kubernetes and ``kill`` send on preemption) saves and stops like Ctrl-C, exit 143.

Real subprocesses and real signals; the commands run with SIGINT ignored, as a job started in the background
by a non-interactive shell does (``nohup latentrl ... &``), so only SIGTERM can stop them cleanly.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from latentrl.ppo.checkpoint import iteration_checkpoints, read_checkpoint
from latentrl.safe_io import load_torch
from tests.test_kill_loop import (  # noqa: F401
    MOTION_STEP,
    MTINY,
    TINY,
    motion_file,
    optimize_argv,
    start_lines,
    temporaries,
    wait_for,
)

ENV = {**os.environ, "OMP_NUM_THREADS": "1"}


def _background(argv: list[str], cwd: Path) -> subprocess.Popen:
    """Start ``argv`` as a background job of a non-interactive shell would run: SIGINT ignored."""
    return subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=ENV, cwd=cwd,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))


def _terminate(proc: subprocess.Popen) -> tuple[int, str]:
    """SIGTERM, then a second one while it saves (ignored); the exit status and stderr."""
    proc.send_signal(signal.SIGTERM)
    proc.send_signal(signal.SIGTERM)
    try:
        err = proc.stderr.read()
        return proc.wait(timeout=120), err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


@pytest.mark.slow
def test_sigterm_during_motion_train_saves_a_later_step_and_resume_finishes(tmp_path):
    run = tmp_path / "run"
    argv = [sys.executable, "-m", "latentrl", "motion", "train", str(MTINY), "--run-dir", str(run),
            "--set", "data.locomotion.num_sequences=3", "--set", "vae_train.steps=400",
            "--set", "denoiser_train.steps=8", "--set", "checkpoint_every=100000", "--set", "log_every=1",
            "--no-progress"]
    proc = _background(argv, tmp_path)
    log = run / "train.log"
    assert wait_for(lambda: log.is_file() and len(MOTION_STEP.findall(log.read_text())) >= 2, proc), proc.stderr.read()
    code, err = _terminate(proc)
    assert code == 143, err
    assert "Traceback" not in err and err.rstrip().endswith("latentrl: interrupted by SIGTERM"), err
    assert not temporaries(run)
    state = load_torch(run / "checkpoints" / "state.pt")
    # checkpoint_every is past the stage's end: no periodic checkpoint was due, this one is the SIGTERM's
    assert state["stage"] == "vae" and 0 < state["step"] < 400, (state["stage"], state["step"])
    assert f"saved vae step {state['step']} to " in err and f"--resume {run}" in err, err
    done = subprocess.run([sys.executable, "-m", "latentrl", "motion", "train", "--resume", str(run), "--no-progress"],
                          capture_output=True, text=True, env=ENV, cwd=tmp_path, timeout=600)
    assert done.returncode == 0, done.stderr
    assert (run / "motion_model.pt").is_file()


@pytest.mark.slow
def test_sigterm_during_train_saves_and_the_run_resumes(motion_file, tmp_path):  # noqa: F811
    run = tmp_path / "run"
    argv = [sys.executable, "-m", "latentrl", "train", str(TINY), "--set", f"env.motion={motion_file}",
            "--set", "ppo.checkpoint_every=2", "--total-steps", str(64 * 100_000), "--run-dir", str(run),
            "--no-progress"]
    proc = _background(argv, tmp_path)
    assert wait_for(lambda: len(iteration_checkpoints(run)) >= 1, proc), proc.stderr.read()
    code, err = _terminate(proc)
    assert code == 143, err
    assert "Traceback" not in err and err.rstrip().endswith("latentrl: interrupted by SIGTERM"), err
    assert not temporaries(run)
    newest = max(read_checkpoint(p)["iteration"] for p in iteration_checkpoints(run))  # every one loads
    assert f"interrupted: saved iteration {newest} " in err and f"--resume {run}" in err, err
    resumed = _background([sys.executable, "-m", "latentrl", "train", "--resume", str(run), "--no-progress"], tmp_path)
    try:
        assert wait_for(lambda: len(start_lines(run)) >= 2, resumed), resumed.stderr.read()
        assert start_lines(run)[-1] == (newest, 64 * newest), start_lines(run)
    finally:
        code, err = _terminate(resumed)
    assert code == 143, err


@pytest.mark.slow
def test_sigterm_during_optimize_exits_143_and_the_same_command_finishes(motion_file, tmp_path):  # noqa: F811
    from latentrl.motion.clip import load_motion_npz

    out = tmp_path / "out"
    argv = optimize_argv(tmp_path, motion_file, problems=4)
    proc = _background([*argv, "--steps", "100000"], tmp_path)
    assert wait_for(lambda: (out / ".lock").is_file(), proc), proc.stderr.read()
    code, err = _terminate(proc)
    assert code == 143, err
    assert "Traceback" not in err and err.rstrip().endswith("latentrl: interrupted by SIGTERM"), err
    assert not list(out.rglob(".*.tmp")), "a temporary file was left"
    done = subprocess.run([*argv, "--steps", "3"], capture_output=True, text=True, env=ENV, cwd=tmp_path, timeout=300)
    assert done.returncode == 0, done.stderr
    json.loads((out / "report.json").read_text())
    assert sorted(p.stem for p in (out / "motions").glob("*.npz")) == [f"p{i}" for i in range(4)]
    for motion in (out / "motions").glob("*.npz"):
        load_motion_npz(motion)



@pytest.mark.slow
def test_sigterm_during_eval_keeps_the_report_of_finished_paths_and_the_same_command_finishes(eval_files, tmp_path):
    from latentrl.evaluation.report import load_report

    out = tmp_path / "out"
    suite = tmp_path / "paths.json"
    suite.write_text(json.dumps([{"goal_location": [[0.0, 0.0, 0.0], [0.0, 40.0 + i, 0.0]],
                                  "goal_text": ["walk", "walk"]} for i in range(40)]))
    argv = [sys.executable, "-m", "latentrl", "eval", str(eval_files["policy"]), "--motion",
            str(eval_files["motion"]), "--paths", str(suite), "--episodes", "2", "--max-steps", "6", "--out", str(out),
            "--no-progress"]
    proc = _background(argv, tmp_path)
    assert wait_for(lambda: (out / "report.json").is_file(), proc), proc.stderr.read()  # a path is done
    code, err = _terminate(proc)
    assert code == 143, err
    assert "Traceback" not in err and err.rstrip().endswith("latentrl: interrupted by SIGTERM"), err
    assert not list(out.rglob(".*.tmp*")), "a temporary file was left"
    kept = load_report(out / "report.json")
    assert 1 <= len(kept["suites"]["paths"]["paths"]) < 40
    done = subprocess.run(argv, capture_output=True, text=True, env=ENV, cwd=tmp_path, timeout=600)
    assert done.returncode == 0, done.stderr
    assert len(load_report(out / "report.json")["suites"]["paths"]["paths"]) == 40
