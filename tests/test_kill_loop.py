"""SIGKILL a real ``latentrl train`` at random moments, checkpoint writes included, and resume it each time.

After every kill: every checkpoint file on disk loads (a write is never visible half-done), and the next
``--resume`` starts exactly at the newest of them, so env-step counters never go backwards; the run then
finishes. CI runs ``KILLS_CI`` kills; ``pytest --kills N`` runs N per command (the full loop: 50,
docs/robustness.md). ``motion train``, ``eval`` and ``optimize`` get the same treatment, and the SB3 trainer two
real Ctrl-Cs.
"""

import json
import os
import random
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from latentrl.motion import save_motion_model
from latentrl.ppo.checkpoint import FINAL, iteration_checkpoints, read_checkpoint
from tests.helpers import make_tiny_model

ROOT = Path(__file__).resolve().parents[1]
TINY = ROOT / "configs" / "tiny.yaml"
KILLS_CI = 5
START = re.compile(r"trainer: start at iteration (\d+), (\d+) env steps")
MODES = ("write", "random", "launch")
"""How a cycle picks its moment: at the next temporary checkpoint file seen after a random delay (inside
``save_torch_atomic``), at a random delay after training started, or at a random delay after the launch."""


def start_lines(run: Path) -> list[tuple[int, int]]:
    log = run / "train.log"
    return [tuple(map(int, m.groups())) for m in START.finditer(log.read_text())] if log.is_file() else []


def temporaries(run: Path) -> list[Path]:
    return [p for d in (run, run / "checkpoints") if d.is_dir() for p in d.glob(".*.tmp")]


def newest_complete(run: Path) -> int:
    """Env steps of the newest checkpoint on disk; every visible checkpoint must load (none is half-written)."""
    files = [p for p in [run / FINAL] if p.is_file()] + iteration_checkpoints(run)
    return max((read_checkpoint(p)["env_steps"] for p in files), default=0)


def wait_for(condition, proc: subprocess.Popen, timeout: float = 120.0) -> bool:
    """Poll ``condition`` every 0.5 ms until it holds (True) or the process exits (False)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        if proc.poll() is not None:
            return False
        time.sleep(0.0005)
    raise AssertionError("the training process made no progress")


@pytest.fixture(scope="module")
def motion_file(tmp_path_factory):
    return save_motion_model(make_tiny_model(), tmp_path_factory.mktemp("motion") / "tiny.pt")


@pytest.mark.slow
def test_sigkill_at_random_moments_always_resumes_from_the_newest_complete_checkpoint(motion_file, tmp_path,
                                                                                     kill_count):
    kills = kill_count or KILLS_CI
    rng = random.Random(7)
    run, logs = tmp_path / "run", tmp_path / "logs"
    logs.mkdir()
    iterations = 8 * kills + 10  # more than the kills can finish: the last resume always has work left
    fresh = [sys.executable, "-m", "latentrl.app.cli", "train", str(TINY), "--set", f"env.motion={motion_file}",
             "--set", "policy.latent_dim=256", "--total-steps", str(64 * iterations), "--run-dir", str(run),
             "--no-progress"]
    resume = [sys.executable, "-m", "latentrl.app.cli", "train", "--resume", str(run), "--no-progress"]
    env = {**os.environ, "OMP_NUM_THREADS": "1", "PYTHONWARNINGS": "always"}
    expected, report = 0, {"kills": 0, "during_write": 0, "before_training": 0, "modes": {}}

    def launch(i: int) -> subprocess.Popen:
        argv = resume if (run / "config.yaml").is_file() else fresh
        with open(logs / f"{i}.out", "w") as out, open(logs / f"{i}.err", "w") as err:
            return subprocess.Popen(argv, stdout=out, stderr=err, env=env, cwd=tmp_path)

    for i in range(kills):
        mode = MODES[i % len(MODES)]
        seen = len(start_lines(run))
        proc = launch(i)
        if mode == "launch":
            time.sleep(rng.uniform(0.5, 4.0))
        elif wait_for(lambda: len(start_lines(run)) > seen, proc):  # noqa: B023 - evaluated inside this iteration
            time.sleep(rng.uniform(0.0, 0.8 if mode == "random" else 0.3))
            if mode == "write":
                wait_for(lambda: bool(temporaries(run)), proc)
        assert proc.poll() is None, f"cycle {i}: the run ended before its kill: {(logs / f'{i}.err').read_text()}"
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        report["kills"] += 1
        report["modes"][mode] = report["modes"].get(mode, 0) + 1
        report["during_write"] += bool(temporaries(run))
        new = start_lines(run)[seen:]
        report["before_training"] += not new
        if new:  # this process resumed exactly where the previous kill left the newest complete checkpoint
            assert new == [(expected // 64, expected)], f"cycle {i}: started at {new}, newest checkpoint {expected}"
        newest = newest_complete(run)
        assert newest >= expected, f"cycle {i}: env steps went back from {expected} to {newest}"
        expected = newest

    final = launch(kills)
    assert final.wait(timeout=600) == 0, (logs / f"{kills}.err").read_text()
    assert start_lines(run)[-1] == (expected // 64, expected), (start_lines(run), expected)
    steps = [s for _, s in start_lines(run)]
    assert steps == sorted(steps), f"a resume went backwards: {steps}"
    assert read_checkpoint(run / FINAL)["env_steps"] == 64 * iterations
    assert not temporaries(run), "the last resume left temporary files"
    for i in range(kills + 1):
        assert "skipping unusable checkpoint" not in (logs / f"{i}.err").read_text(), f"run {i} met a corrupt file"
    print(json.dumps(report))
    if kills >= 4:
        assert report["during_write"] >= 1, f"no kill landed inside a checkpoint write: {report}"


MOTION_KILLS_CI = 2
MTINY = ROOT / "configs" / "motion" / "tiny.yaml"
MOTION_STEP = re.compile(r"^(vae|denoiser) step (\d+):", re.M)
STAGES = ("vae", "denoiser")


def motion_progress(run: Path) -> tuple[int, int]:
    """(stage index, steps done) of the run's ``state.pt``; it must load whenever it exists."""
    from latentrl.safe_io import load_torch

    state_file = run / "checkpoints" / "state.pt"
    if not state_file.is_file():
        return (0, 0)
    state = load_torch(state_file)
    return (STAGES.index(state["stage"]), state["step"])


@pytest.mark.slow
def test_sigkill_motion_training_resumes_from_its_last_state(tmp_path, kill_count):
    kills = kill_count or MOTION_KILLS_CI
    steps = 4 * kills + 6  # per stage
    rng = random.Random(11)
    run, logs = tmp_path / "run", tmp_path / "logs"
    logs.mkdir()
    fresh = [sys.executable, "-m", "latentrl.app.cli", "motion", "train", str(MTINY), "--run-dir", str(run),
             "--set", "data.locomotion.num_sequences=3", "--set", f"vae_train.steps={steps}",
             "--set", f"denoiser_train.steps={steps}", "--set", "checkpoint_every=1", "--set", "log_every=1",
             "--no-progress"]
    resume = [sys.executable, "-m", "latentrl.app.cli", "motion", "train", "--resume", str(run), "--no-progress"]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    progress, during_write = (0, 0), 0

    def logged() -> list[tuple[int, int]]:
        log = run / "train.log"
        text = log.read_text() if log.is_file() else ""
        return [(STAGES.index(s), int(n)) for s, n in MOTION_STEP.findall(text)]

    for i in range(kills + 1):
        seen = len(logged())
        argv = resume if (run / "config.yaml").is_file() else fresh
        with open(logs / f"{i}.err", "w") as err:
            proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=err, env=env, cwd=tmp_path)
        if i == kills:  # the last run finishes
            assert proc.wait(timeout=600) == 0, (logs / f"{i}.err").read_text()
        else:
            assert wait_for(lambda: len(logged()) > seen, proc), (logs / f"{i}.err").read_text()  # noqa: B023
            time.sleep(rng.uniform(0.0, 1.0))
            if i % 2 == 0:
                wait_for(lambda: bool(temporaries(run)), proc)
            assert proc.poll() is None, f"cycle {i}: the run ended before its kill"
            proc.send_signal(signal.SIGKILL)
            proc.wait()
            during_write += bool(temporaries(run))
        first = logged()[seen:seen + 1]
        if first:  # the first step this process logged is the first one its state.pt had not done
            stage, done = progress
            assert first[0] == ((stage, done) if done < steps or stage == 1 else (1, 0)), (i, first, progress)
        now = motion_progress(run)
        assert now >= progress, f"cycle {i}: state went back from {progress} to {now}"
        progress = now
    assert progress == (1, steps) and (run / "motion_model.pt").is_file()
    print(json.dumps({"motion_kills": kills, "during_write": during_write}))


def _train_stderr_until(proc: subprocess.Popen, text: str, lines: list[str]) -> bool:
    """Read the process's stderr into ``lines`` until a line holds ``text`` (True) or the stream ends (False)."""
    for line in proc.stderr:
        lines.append(line)
        if text in line:
            return True
    return False


@pytest.mark.slow
@pytest.mark.parametrize("second", ["at-once", "while-exiting"])
def test_ctrl_c_twice_on_the_sb3_trainer_exits_130_cleanly_and_the_run_resumes(second, motion_file, tmp_path):
    """Two real SIGINTs to ``latentrl train --trainer sb3``: the second at once (stop without saving) or just after
    the save line (while the process exits). Either way: exit 130, no traceback, no half-written file, and a
    ``--resume`` starts at the newest checkpoint."""
    run = tmp_path / "run"
    argv = [sys.executable, "-m", "latentrl", "train", str(TINY), "--trainer", "sb3", "--set",
            f"env.motion={motion_file}", "--set", "ppo.checkpoint_every=2", "--total-steps", str(64 * 100_000),
            "--run-dir", str(run), "--no-progress"]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path)
    lines: list[str] = []
    try:
        wait_for(lambda: len(iteration_checkpoints(run)) >= 1, proc)
        proc.send_signal(signal.SIGINT)
        if second == "at-once":
            time.sleep(0.05)
        else:
            assert _train_stderr_until(proc, "interrupted: saved iteration", lines), "".join(lines)
            time.sleep(0.02)  # the process is on its way out (this used to end it by SIGINT, exit -2)
        proc.send_signal(signal.SIGINT)
        lines += proc.stderr.readlines()
        assert proc.wait(timeout=120) == 130, "".join(lines)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    err = "".join(lines)
    assert "Traceback" not in err and err.rstrip().endswith("latentrl: interrupted"), err
    assert not temporaries(run), "a temporary file was left"
    newest = max(read_checkpoint(p)["iteration"] for p in iteration_checkpoints(run))  # every one loads
    if second == "while-exiting":
        assert f"interrupted: saved iteration {newest} " in err, err
    resumed = subprocess.Popen([sys.executable, "-m", "latentrl", "train", "--resume", str(run), "--trainer", "sb3",
                                "--no-progress"],
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, env=env, cwd=tmp_path)
    try:
        wait_for(lambda: len(start_lines(run)) >= 2, resumed)
        assert start_lines(run)[-1] == (newest, 64 * newest), start_lines(run)
        resumed.send_signal(signal.SIGINT)
        assert resumed.wait(timeout=120) == 130, resumed.stderr.read()
    finally:
        if resumed.poll() is None:
            resumed.kill()
            resumed.wait()


OPTIMIZE_KILLS_CI = 3


def optimize_argv(tmp_path: Path, motion_file: Path, problems: int) -> list[str]:
    """``latentrl optimize`` of a small pelvis-target suite (written into ``tmp_path``) into ``tmp_path/out``."""
    joint = {"type": "joint", "frame": 10, "joint": "pelvis", "position": [0.0, 1.0, 0.9]}
    suite = tmp_path / "suite.json"
    suite.write_text(json.dumps({"format": "latentrl.constraints/1", "problems": [
        {"name": f"p{i}", "start": {"seed": 0}, "text": "walk", "primitives": 2, "constraints": [joint]}
        for i in range(problems)]}))
    return [sys.executable, "-m", "latentrl", "optimize", str(suite), "--motion", str(motion_file), "--batch", "2",
            "--out", str(tmp_path / "out"), "--no-progress"]


@pytest.mark.slow
def test_optimize_killed_or_interrupted_then_run_again_leaves_only_whole_files(motion_file, tmp_path, kill_count):
    """SIGKILL (and one SIGINT) of ``latentrl optimize`` at random moments; every file it left is whole, and the
    same command run again into the same ``--out`` finishes (the lock died with the process)."""
    from latentrl.motion.clip import load_motion_npz

    kills = kill_count or OPTIMIZE_KILLS_CI
    rng = random.Random(5)
    out = tmp_path / "out"
    argv = optimize_argv(tmp_path, motion_file, problems=6)
    env = {**os.environ, "OMP_NUM_THREADS": "1"}

    def whole(final: bool = False) -> None:
        if (out / "report.json").is_file():
            json.loads((out / "report.json").read_text())
        for motion in (out / "motions").glob("*.npz") if (out / "motions").is_dir() else []:
            load_motion_npz(motion)
        if final:  # a kill inside a write leaves its temporary file; the next run removes it
            assert not [p for p in out.rglob(".*.tmp*")], "a temporary file was left"

    landed = 0
    for i in range(kills):
        proc = subprocess.Popen([*argv, "--steps", "400"], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                env=env, cwd=tmp_path)
        wait_for(lambda: (out / ".lock").is_file(), proc)
        time.sleep(rng.uniform(0.5, 4.0))
        if proc.poll() is None:
            proc.send_signal(signal.SIGINT if i == 0 else signal.SIGKILL)
            landed += 1
        code = proc.wait(timeout=120)
        err = proc.stderr.read().decode()
        assert "Traceback" not in err, err
        if i == 0 and code != 0:
            assert code == 130 and err.strip().splitlines()[-1] == "latentrl: interrupted", err
        whole()
    done = subprocess.run([*argv, "--steps", "3"], capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)
    assert done.returncode == 0, done.stderr
    whole(final=True)
    report = json.loads((out / "report.json").read_text())
    assert sorted(p.stem for p in (out / "motions").glob("*.npz")) == [f"p{i}" for i in range(6)], report.keys()
    print(json.dumps({"optimize_signals": kills, "while_running": landed}))
    assert landed >= 1, "no signal reached a running optimize"


EVAL_KILLS_CI = 3
EVAL_PATHS = 8


def _eval_outputs_whole(out: Path) -> int:
    """Check what ``latentrl eval`` left in ``out``: no report or a valid one (and its plot and motions load);
    returns how many paths the report holds (0 without one)."""
    from PIL import Image

    from latentrl.evaluation.report import load_report
    from latentrl.motion.clip import load_motion_npz

    paths = 0
    if (out / "report.json").is_file():
        report = load_report(out / "report.json")
        paths = sum(len(suite["paths"]) for suite in report["suites"].values())
        assert 1 <= paths <= EVAL_PATHS, paths
    if (out / "paths.png").is_file():
        with Image.open(out / "paths.png") as png:
            png.load()
    for motion in (out / "motions").glob("*.npz") if (out / "motions").is_dir() else []:
        load_motion_npz(motion)
    return paths


@pytest.mark.slow
def test_eval_killed_at_random_moments_leaves_no_report_or_a_valid_one_and_a_rerun_completes(eval_files, tmp_path,
                                                                                           kill_count):
    """SIGKILL of ``latentrl eval`` at random moments (half of them inside a file write): the report it left is
    absent or loads, with the paths finished so far; plots and motions load; the same command into the same
    ``--out`` then finishes, removes the temporary files killed writes left and reports every path."""
    from latentrl.evaluation.report import load_report

    kills = kill_count or EVAL_KILLS_CI
    rng = random.Random(13)
    out = tmp_path / "out"
    suite = tmp_path / "paths.json"
    suite.write_text(json.dumps([{"goal_location": [[0.0, 0.0, 0.0], [0.0, 40.0 + i, 0.0]],
                                  "goal_text": ["walk", "walk"]} for i in range(EVAL_PATHS)]))
    argv = [sys.executable, "-m", "latentrl", "eval", str(eval_files["policy"]), "--motion",
            str(eval_files["motion"]), "--paths", str(suite), "--episodes", "2", "--max-steps", "6", "--out", str(out),
            "--no-progress"]
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    report = {"eval_kills": 0, "during_write": 0, "finished_before_kill": 0, "with_report": 0}

    def temporaries_left() -> list[Path]:
        return [p for p in out.rglob(".*.tmp*")] if out.is_dir() else []

    for i in range(kills):
        proc = subprocess.Popen(argv, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env, cwd=tmp_path)
        # the lock file stays after a kill: wait for this process to hold it (its PID written there)
        wait_for(lambda: (out / ".lock").is_file() and (out / ".lock").read_text().strip() == str(proc.pid), proc)  # noqa: B023
        time.sleep(rng.uniform(0.0, 3.0))
        if i % 2 == 0:
            before = set(temporaries_left())
            wait_for(lambda: bool(set(temporaries_left()) - before), proc)  # noqa: B023 - inside a write
        if proc.poll() is None:
            proc.send_signal(signal.SIGKILL)
            report["eval_kills"] += 1
        else:
            report["finished_before_kill"] += 1
        proc.wait(timeout=120)
        err = proc.stderr.read().decode()
        assert "Traceback" not in err, err
        report["during_write"] += bool(temporaries_left())
        report["with_report"] += _eval_outputs_whole(out) > 0
    done = subprocess.run(argv, capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)
    assert done.returncode == 0, done.stderr
    assert _eval_outputs_whole(out) == EVAL_PATHS
    assert not temporaries_left(), f"temporary files were left: {temporaries_left()}"
    final = load_report(out / "report.json")
    assert all(len(p["episodes"]) == 2 for s in final["suites"].values() for p in s["paths"])
    assert len(list((out / "motions").glob("*.npz"))) == 2 * EVAL_PATHS
    print(json.dumps(report))
    assert report["eval_kills"] >= 1, f"no kill reached a running eval: {report}"
