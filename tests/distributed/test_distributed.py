"""Data-parallel PPO with 2 CPU ranks (gloo) under torchrun, on the small reach env of the PPO tests.

Each launch is a real ``torch.distributed.run`` of ``worker.py`` with a subprocess timeout, so a hang
fails the test instead of blocking CI. One fresh run is shared by the checks that read it.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from latentrl.ppo import checkpoint as ckpt

ROOT = Path(__file__).resolve().parents[2]
WORKER = Path(__file__).with_name("worker.py")
LAUNCH_TIMEOUT_S = 120


def launch(nproc: int, mode: str, run_dir: Path) -> subprocess.CompletedProcess:
    """Run ``worker.py MODE RUN_DIR`` on ``nproc`` ranks (torchrun for 2 or more), bounded in time."""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]),
           "OMP_NUM_THREADS": "1", "LATENTRL_DIST_TIMEOUT": "60"}
    launcher = ["-m", "torch.distributed.run", "--standalone", "--nproc-per-node", str(nproc)] if nproc > 1 else []
    cmd = [sys.executable, *launcher, str(WORKER), mode, str(run_dir)]  # 1: a plain process, no process group
    return subprocess.run(cmd, env=env, cwd=ROOT, capture_output=True, text=True, timeout=LAUNCH_TIMEOUT_S)


def ok(proc: subprocess.CompletedProcess) -> None:
    assert proc.returncode == 0, proc.stdout[-3000:] + proc.stderr[-3000:]


@pytest.fixture(scope="module")
def fresh(tmp_path_factory) -> Path:
    run_dir = tmp_path_factory.mktemp("dist") / "run"
    ok(launch(2, "fresh", run_dir))
    return run_dir


def test_ranks_end_with_identical_weights_and_summed_steps(fresh):
    r0, r1 = (torch.load(fresh / f"rank{r}.pt", weights_only=False) for r in (0, 1))
    assert r0["world_size"] == r1["world_size"] == 2
    assert r0["state"].keys() == r1["state"].keys()
    for name in r0["state"]:  # parameters, and the normalizer's buffers
        assert torch.equal(r0["state"][name], r1["state"][name]), name
    # 2 ranks x 4 envs x 8 steps = 64 env steps per iteration; 2 iterations
    assert r0["env_steps"] == r1["env_steps"] == 128 and r0["iterations"] == 2
    assert float(r0["state"]["obs_normalizer.count"]) == 128  # both ranks' observations were folded in
    assert r0["rollout"] == r1["rollout"]  # episode statistics gathered from both ranks
    final = ckpt.read_checkpoint(fresh / ckpt.FINAL)
    assert final["env_steps"] == 128 and final["world_size"] == 2
    for name, value in final["policy"].items():
        assert torch.equal(value, r0["state"][name]), name


def test_rank0_alone_writes_and_logs_the_summed_step_count(fresh):
    from tests.ppo.helpers import scalars

    assert [p.name for p in ckpt.iteration_checkpoints(fresh)] == ["iter_1.pt"]
    assert len(list(fresh.glob("events.out.tfevents.*"))) == 1
    logged = scalars(fresh)
    assert [step for step, _ in logged["time/fps"]] == [64, 128]
    assert [step for step, _ in logged["eval/probe"]] == [64, 128]  # rank 0's evaluation, every iteration
    assert len((fresh / "train.log").read_text().splitlines()) >= 2


@pytest.mark.parametrize("nproc", [1, 2])
def test_a_checkpoint_of_two_ranks_resumes_on_one_or_two(fresh, tmp_path, nproc):
    run_dir = tmp_path / "run"
    shutil.copytree(fresh, run_dir)
    (run_dir / ckpt.FINAL).unlink()
    for r in (0, 1):
        (run_dir / f"rank{r}.pt").unlink()
    ok(launch(nproc, "resume", run_dir))
    r0 = torch.load(run_dir / "rank0.pt", weights_only=False)
    assert r0["world_size"] == nproc
    assert r0["env_steps"] == 128  # 64 steps from iter_1.pt, then 64 more on nproc ranks
    assert r0["iterations"] == 128 // (32 * nproc)
    assert ckpt.read_checkpoint(run_dir / ckpt.FINAL)["world_size"] == nproc


def test_a_failing_rank_stops_every_rank(tmp_path):
    from tests.distributed.worker import FAIL_MESSAGE

    proc = launch(2, "fail", tmp_path / "run")  # bounded by LAUNCH_TIMEOUT_S: a hang fails the test
    assert proc.returncode != 0
    assert FAIL_MESSAGE in proc.stdout + proc.stderr
    assert not (tmp_path / "run" / "rank0.pt").exists()  # rank 0 did not finish either
    assert not (tmp_path / "run" / ckpt.FINAL).exists()


def test_the_sb3_trainer_is_refused_under_torchrun(monkeypatch, capsys):
    from latentrl.app.cli import main

    for name, value in {"RANK": "0", "WORLD_SIZE": "2", "MASTER_ADDR": "127.0.0.1", "MASTER_PORT": "29999"}.items():
        monkeypatch.setenv(name, value)  # what torchrun sets
    assert main(["train", "configs/tiny.yaml", "--trainer", "sb3"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "trainer 'sb3' runs in one process only" in err


def test_nproc_relaunches_the_same_command_on_every_rank():
    from latentrl.app.train import TrainRequest

    req = TrainRequest(config="configs/tiny.yaml", overrides=["ppo.seed=4"], seed=2, run_dir="runs/x", nproc=2,
                       progress=False)
    assert req.argv() == ["train", "configs/tiny.yaml", "--set", "ppo.seed=4", "--trainer", "native", "--seed", "2",
                          "--run-dir", "runs/x", "--no-progress"]


def _children(pid: int) -> list[int]:
    try:
        return [int(x) for x in Path(f"/proc/{pid}/task/{pid}/children").read_text().split()]
    except OSError:
        return []


def _rank_pids(launcher: int) -> dict[int, int]:
    """rank -> PID of the ranks under ``latentrl train --nproc`` (launcher -> torchrun -> ranks)."""
    found = {}
    for torchrun in _children(launcher):
        for pid in _children(torchrun):
            try:
                env = Path(f"/proc/{pid}/environ").read_bytes().split(b"\0")
            except OSError:
                continue
            found.update({int(e[5:]): pid for e in env if e.startswith(b"RANK=")})
    return found


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="finds the ranks through /proc")
@pytest.mark.parametrize("victim", [0, 1])
def test_a_rank_killed_mid_run_stops_the_others_with_one_line_and_the_run_resumes(victim, tmp_path):
    """SIGKILL of one rank of ``latentrl train --nproc 2``: the other stops at once, one line names the rank
    and the signal and says how to resume; ``--resume RUN --nproc 2`` then finishes from the newest checkpoint."""
    import signal
    import time

    run = tmp_path / "run"
    total = 128 * 40  # 2 ranks x 8 envs x 8 steps = 128 env steps per iteration
    env = {**os.environ, "OMP_NUM_THREADS": "1", "LATENTRL_DIST_TIMEOUT": "60"}
    cmd = [sys.executable, "-m", "latentrl", "train", str(ROOT / "configs" / "tiny.yaml"), "--nproc", "2",
           "--total-steps", str(total), "--run-dir", str(run), "--no-progress"]
    proc = subprocess.Popen(cmd, env=env, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + LAUNCH_TIMEOUT_S
        while len(ckpt.iteration_checkpoints(run)) < 1 or len(_rank_pids(proc.pid)) < 2:
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "training did not reach its first checkpoint"
            time.sleep(0.05)
        os.kill(_rank_pids(proc.pid)[victim], signal.SIGKILL)
        _, err = proc.communicate(timeout=60)  # bounded: a hang fails here
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode != 0
    assert "Traceback" not in err and "ChildFailedError" not in err, err[-3000:]
    last = err.strip().splitlines()[-1]
    assert last == (f"latentrl: error: rank {victim} was killed by SIGKILL; torchrun stopped the other ranks; "
                    f"continue the run with: latentrl train --resume {run} --nproc 2"), err[-3000:]
    newest = ckpt.read_checkpoint(ckpt.iteration_checkpoints(run)[-1])

    resumed = subprocess.run([sys.executable, "-m", "latentrl", "train", "--resume", str(run), "--nproc", "2",
                              "--no-progress"], env=env, cwd=tmp_path, capture_output=True, text=True,
                             timeout=LAUNCH_TIMEOUT_S * 2)
    ok(resumed)
    log = (run / "train.log").read_text()
    assert f"start at iteration {newest['iteration']}, {newest['env_steps']} env steps" in log  # not from 0
    assert ckpt.read_checkpoint(run / ckpt.FINAL)["env_steps"] == total


TORCHRUN_STDERR = """\
latentrl: error: rank 1: all_gather_object with the other ranks failed (Connection reset by peer); another rank \
stopped or hung, so this one stops too
W1127 23:53:21.479000 8367 torch/distributed/elastic/multiprocessing/api.py:1028] Sending process 8465 closing signal \
SIGTERM
E1127 23:53:21.543000 8367 torch/distributed/elastic/multiprocessing/api.py:1002] failed (exitcode: -9) local_rank: \
1 (pid: 8469) of binary: /usr/bin/python
Traceback (most recent call last):
  File "<frozen runpy>", line 198, in _run_module_as_main
  File "/x/torch/distributed/launcher/api.py", line 383, in launch_agent
    raise ChildFailedError(
torch.distributed.elastic.multiprocessing.errors.ChildFailedError:
======================================================
latentrl FAILED
------------------------------------------------------
Failures:
[1]:
  rank      : 0 (local_rank: 0)
  exitcode  : -15 (pid: 8465)  (SIGTERM)
------------------------------------------------------
Root Cause (first observed failure):
[0]:
  rank      : 1 (local_rank: 1)
  exitcode  : -9 (pid: 8469)  (SIGKILL)
  traceback : Signal 9 (SIGKILL) received by PID 8469
======================================================
[rank0]: a line a rank printed after torchrun's report
"""


def test_torchruns_report_becomes_its_root_cause_and_the_ranks_lines_pass():
    from latentrl.ppo.distributed import TorchrunOutput

    out = TorchrunOutput()
    shown = [line for raw in TORCHRUN_STDERR.splitlines(keepends=True) for line in out.feed(raw)] + out.flush()
    assert shown == [TORCHRUN_STDERR.splitlines(keepends=True)[0], "[rank0]: a line a rank printed after torchrun's "
                     "report\n"]
    assert out.cause() == "rank 1 was killed by SIGKILL"


def test_a_rank_traceback_is_shown_and_an_exit_code_is_named():
    from latentrl.ppo.distributed import TorchrunOutput

    rank_traceback = ["Traceback (most recent call last):\n", '  File "x.py", line 1, in <module>\n',
                      "ValueError: a rank's own error\n"]
    report = ["Traceback (most recent call last):\n", "  File \"run.py\", line 9\n",
              "torch.distributed.elastic.multiprocessing.errors.ChildFailedError:\n", "=====\n", "Root Cause:\n",
              "  rank      : 0 (local_rank: 0)\n", "  exitcode  : 2 (pid: 7)\n", "=====\n"]
    out = TorchrunOutput()
    shown = [line for raw in rank_traceback + report for line in out.feed(raw)] + out.flush()
    assert shown == rank_traceback  # under --debug a rank's traceback is its message; torchrun's is not shown
    assert out.cause() == "rank 0 exited with code 2"


STOP_TOTAL = 128 * 40  # 2 ranks x 8 envs x 8 steps = 128 env steps per iteration
STOP_ENV = {**os.environ, "OMP_NUM_THREADS": "1", "LATENTRL_DIST_TIMEOUT": "60"}


def _stop_at_iteration_2(tmp_path: Path, stop, timeout_s: float, **popen) -> tuple[Path, subprocess.Popen, str]:
    """Start ``latentrl train --nproc 2`` in its own session, call ``stop(proc)`` once iteration 2 is logged and
    return the run folder, the finished launcher and its stderr (bounded: a hang fails here)."""
    import signal
    import time

    run = tmp_path / "run"
    cmd = [sys.executable, "-m", "latentrl", "train", str(ROOT / "configs" / "tiny.yaml"), "--nproc", "2",
           "--set", "ppo.checkpoint_every=0", "--total-steps", str(STOP_TOTAL), "--run-dir", str(run),
           "--no-progress"]
    proc = subprocess.Popen(cmd, env=STOP_ENV, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, start_new_session=True, **popen)
    try:
        deadline = time.monotonic() + LAUNCH_TIMEOUT_S
        log = run / "train.log"
        while not (log.is_file() and "iter 2 " in log.read_text()):
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "training did not reach its second iteration"
            time.sleep(0.05)
        stop(proc)
        _, err = proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
    return run, proc, err


def _resume_finishes_from(run: Path, tmp_path: Path, newest: dict) -> None:
    """``--resume RUN --nproc 2`` starts at the saved iteration (not from 0) and finishes the run."""
    resumed = subprocess.run([sys.executable, "-m", "latentrl", "train", "--resume", str(run), "--nproc", "2",
                              "--no-progress"], env=STOP_ENV, cwd=tmp_path, capture_output=True, text=True,
                             timeout=LAUNCH_TIMEOUT_S * 2)
    ok(resumed)
    start = f"start at iteration {newest['iteration']}, {newest['env_steps']} env steps"
    assert start in (run / "train.log").read_text()
    assert ckpt.read_checkpoint(run / ckpt.FINAL)["env_steps"] == STOP_TOTAL


@pytest.mark.slow
def test_ctrl_c_under_nproc_saves_once_shows_the_ranks_lines_and_the_run_resumes(tmp_path):
    """Ctrl-C (SIGINT to the process group, as a terminal sends it) of ``latentrl train --nproc 2``: the ranks
    save the iteration they are in and say so, torchrun's own traceback is not shown, exit 130; ``--resume``
    then starts there and finishes."""
    import signal

    run, proc, err = _stop_at_iteration_2(tmp_path, lambda p: os.killpg(p.pid, signal.SIGINT), 60)
    assert proc.returncode == 130, err[-3000:]
    assert "Traceback" not in err and err.strip().splitlines()[-1] == "latentrl: interrupted", err[-3000:]
    saved = ckpt.iteration_checkpoints(run)
    assert len(saved) == 1, saved  # checkpoint_every=0: the Ctrl-C wrote it
    newest = ckpt.read_checkpoint(saved[0])
    assert f"interrupted: saved iteration {newest['iteration']} " in err, err[-3000:]
    _resume_finishes_from(run, tmp_path, newest)


def test_ranks_that_see_a_signal_in_different_iterations_stop_at_the_same_one_and_rank_0_saves_it(tmp_path):
    """Rank 1 alone gets SIGINT, inside the second iteration: at that iteration's end every rank agrees to stop
    (one all-reduce of the flag), rank 0 saves it, and both stop with the same weights."""
    run = tmp_path / "run"
    ok(launch(2, "skew", run))
    r0, r1 = (torch.load(run / f"rank{r}.pt", weights_only=False) for r in (0, 1))
    assert r0["interrupted"] == r1["interrupted"] == 2, (r0["interrupted"], r1["interrupted"])
    for name in r0["state"]:
        assert torch.equal(r0["state"][name], r1["state"][name]), name
    saved = ckpt.iteration_checkpoints(run)
    assert [p.name for p in saved] == ["iter_2.pt"]  # checkpoint_every=0: the stop wrote it
    assert ckpt.read_checkpoint(saved[0])["env_steps"] == 128
    assert not (run / ckpt.FINAL).exists()


@pytest.mark.slow
def test_sigterm_to_the_nproc_launcher_alone_saves_one_iteration_on_every_rank_and_the_run_resumes(tmp_path):
    """SIGTERM to the PID of ``latentrl train --nproc 2`` only (Kubernetes signals the container's first process;
    ``kill PID``), started with SIGINT ignored as a background job is: the launcher passes it on, every rank
    stops at the same iteration, rank 0 saves it, exit 143; ``--resume RUN --nproc 2`` starts there and finishes."""
    import signal

    run, proc, err = _stop_at_iteration_2(  # the launcher's PID alone, SIGINT ignored as in a background job
        tmp_path, lambda p: p.send_signal(signal.SIGTERM), 90,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    assert proc.returncode == 143, err[-3000:]
    assert "Traceback" not in err and err.strip().splitlines()[-1] == "latentrl: interrupted by SIGTERM", err[-3000:]
    saved = ckpt.iteration_checkpoints(run)
    assert len(saved) == 1, saved  # checkpoint_every=0: the stop wrote it
    newest = ckpt.read_checkpoint(saved[0])
    notes = [line for line in err.splitlines() if line.startswith("interrupted: saved iteration")]
    assert len(notes) == 2 and len(set(notes)) == 1, err[-3000:]  # both ranks stopped at the same iteration
    assert notes[0].startswith(f"interrupted: saved iteration {newest['iteration']} "), err[-3000:]
    _resume_finishes_from(run, tmp_path, newest)


HUNG_STDERR = """\
latentrl: error: rank 0: all_gather_object timed out after 10 s (LATENTRL_DIST_TIMEOUT) waiting for the other \
ranks; another rank hung or stopped, so this one stops too
E1128 03:02:02.847000 17608 torch/distributed/elastic/multiprocessing/api.py:1002] failed (exitcode: 1) local_rank: \
0 (pid: 17691) of binary: /usr/bin/python
Traceback (most recent call last):
  File "/x/torch/distributed/launcher/api.py", line 383, in launch_agent
    raise ChildFailedError(
torch.distributed.elastic.multiprocessing.errors.ChildFailedError:
============================================================
latentrl FAILED
------------------------------------------------------------
Failures:
[1]:
  time      : 2026-11-28_03:02:02
  host      : localhost
  rank      : 1 (local_rank: 1)
  exitcode  : -9 (pid: 17692)  (SIGKILL)
  error_file: <N/A>
  traceback : Signal 9 (SIGKILL) received by PID 17692
------------------------------------------------------------
Root Cause (first observed failure):
[0]:
  time      : 2026-11-28_03:01:32
  host      : localhost
  rank      : 0 (local_rank: 0)
  exitcode  : 1 (pid: 17691)
  error_file: <N/A>
  traceback : To enable traceback see: https://pytorch.org/docs/stable/elastic/errors.html
============================================================
"""


def test_a_timed_out_rank_is_not_blamed_and_the_hung_one_is_named():
    from latentrl.ppo.distributed import TorchrunOutput

    out = TorchrunOutput()
    shown = [line for raw in HUNG_STDERR.splitlines(keepends=True) for line in out.feed(raw)] + out.flush()
    assert shown == []  # rank 0's own line is restated by the cause, with the rank that hung
    assert out.cause() == ("rank 0 timed out after 10 s (LATENTRL_DIST_TIMEOUT) waiting for the other ranks: rank 1 "
                           "hung (did not stop when asked; killed by SIGKILL)")


@pytest.mark.slow
@pytest.mark.skipif(not Path("/proc/self/task").is_dir(), reason="finds the ranks through /proc")
def test_a_rank_that_hangs_without_dying_stops_the_run_within_the_collective_timeout_in_one_line(tmp_path):
    """SIGSTOP of rank 1 of ``latentrl train --nproc 2`` (a rank that hangs, alive): rank 0's next collective times
    out after LATENTRL_DIST_TIMEOUT (10 s here), torchrun stops the run (SIGKILL of the stopped rank after its 30 s
    grace), and the launcher's last line names the timeout and the hung rank; no traceback; the newest checkpoint
    loads."""
    import signal
    import time

    run = tmp_path / "run"
    env = {**os.environ, "OMP_NUM_THREADS": "1", "LATENTRL_DIST_TIMEOUT": "10"}
    cmd = [sys.executable, "-m", "latentrl", "train", str(ROOT / "configs" / "tiny.yaml"), "--nproc", "2",
           "--total-steps", str(128 * 40), "--run-dir", str(run), "--no-progress"]
    proc = subprocess.Popen(cmd, env=env, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    stopped = None
    try:
        deadline = time.monotonic() + LAUNCH_TIMEOUT_S
        while len(ckpt.iteration_checkpoints(run)) < 1 or len(_rank_pids(proc.pid)) < 2:
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "training did not reach its first checkpoint"
            time.sleep(0.05)
        stopped = _rank_pids(proc.pid)[1]
        os.kill(stopped, signal.SIGSTOP)
        _, err = proc.communicate(timeout=120)  # bounded: 10 s timeout + torchrun's 30 s grace + start-up
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        if stopped is not None:  # torchrun killed it; never leave a stopped process behind
            with contextlib.suppress(ProcessLookupError):
                os.kill(stopped, signal.SIGKILL)
    assert proc.returncode == 1, err[-3000:]
    assert "Traceback" not in err and "ChildFailedError" not in err, err[-3000:]
    assert len([line for line in err.splitlines() if "error" in line]) == 1, err[-3000:]
    assert err.strip().splitlines()[-1] == (
        "latentrl: error: rank 0 timed out after 10 s (LATENTRL_DIST_TIMEOUT) waiting for the other ranks: rank 1 "
        "hung (did not stop when asked; killed by SIGKILL); torchrun stopped the other ranks; continue the run "
        f"with: latentrl train --resume {run} --nproc 2"), err[-3000:]
    ckpt.read_checkpoint(ckpt.iteration_checkpoints(run)[0])
