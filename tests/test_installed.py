"""Installed, not only checked out (issue 16, part 2): the wheel alone runs the commands from an empty folder.

Offline: the wheel is built without build isolation and installed without dependencies into a fresh
virtual environment that sees this interpreter's packages (torch and the rest) through a ``.pth``
file, so nothing is downloaded. The checkout is not on the path: configs, path suites, the default
motion model and the shipped policy must come from the installed package.
"""

from __future__ import annotations

import os
import site
import subprocess
import sys
import venv
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.slow


def run(cmd: list[str], cwd: Path, env: dict[str, str], timeout: int = 600) -> str:
    done = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, f"{' '.join(cmd)} -> {done.returncode}\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}"
    return done.stdout


def test_wheel_installs_and_runs_from_an_empty_folder(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env.update(OMP_NUM_THREADS="1", PIP_NO_INDEX="1", PIP_DISABLE_PIP_VERSION_CHECK="1", MPLBACKEND="Agg")
    wheels = tmp_path / "wheels"
    run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(wheels),
         str(ROOT)], tmp_path, env)
    wheel = next(wheels.glob("latentrl-*.whl"))
    home = tmp_path / "venv"
    venv.EnvBuilder(with_pip=False).create(home)
    python = home / "bin" / "python"
    target = Path(run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                      tmp_path, env).strip())
    # this interpreter's packages (torch, numpy, ...) without its editable latentrl: .pth files of a
    # folder named in a .pth are not processed, so the editable finder never loads
    (target / "_latentrl_test_deps.pth").write_text("\n".join(site.getsitepackages()) + "\n")
    run([sys.executable, "-m", "pip", "--python", str(python), "install", "--no-deps", "-q", str(wheel)]
        if _pip_has_python_flag() else
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target), str(wheel)],
        tmp_path, env)
    work = tmp_path / "empty"
    work.mkdir()
    where = run([str(python), "-c", "import latentrl; print(latentrl.__file__)"], work, env)
    assert where.startswith(str(target)), where
    cli = str(home / "bin" / "latentrl") if (home / "bin" / "latentrl").is_file() else None
    base = [cli] if cli else [str(python), "-m", "latentrl.app.cli"]
    out = run(base + ["quickstart", "--set", "env.num_envs=4", "--set", "ppo.num_steps=4", "--set",
                      "ppo.num_minibatches=1", "--set", "ppo.total_steps=16", "--set", "ppo.eval_every=0",
                      "--episodes", "1", "--max-steps", "2", "--run-dir", "run", "--no-progress"], work, env)
    assert "[quickstart] done" in out and (work / "run" / "eval" / "report.md").is_file()
    run(base + ["eval", "reach_walk_default", "--paths", "dart_walk_long", "--episodes", "1", "--max-steps", "3",
                "--out", "walk"], work, env)
    assert (work / "walk" / "report.json").is_file()
    run(base + ["motion", "sample", "--text", "walk", "--seconds", "1", "--out", "walk.npz"], work, env)
    assert (work / "walk.npz").is_file()
    assert sorted(p.name for p in work.iterdir()) == ["run", "walk", "walk.npz"]


def _pip_has_python_flag() -> bool:
    """pip >= 22.3 installs into another interpreter's environment with ``--python``."""
    import pip

    return tuple(int(x) for x in pip.__version__.split(".")[:2]) >= (22, 3)
