"""The wheel users install: small enough for a package index, holding only the default model and policies.

PyPI refuses files over 100 MB; the wheel must stay under 60 MB and carry at most 7 ``.pt`` files (the
default motion model and the ``*_default`` policies; older versions live in zoo/, outside the package).
It is built offline from a copy of the package sources (so stale ``build/`` folders of the checkout
cannot leak into it), installed with ``pip --target``, and read from there, not from the checkout.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MAX_WHEEL_BYTES = 60 * 1000 * 1000
MAX_PT_FILES = 11  # the default motion model and the ten shipped *_default policies

CHECK = """
import sys
from pathlib import Path
import latentrl
from latentrl.motion import load_motion_model
from latentrl.motion.checkpoint import default_model_path
from latentrl.ppo.checkpoint import read_checkpoint
from latentrl.resources import policy_file

target = Path(sys.argv[1]).resolve()
assert Path(latentrl.__file__).resolve().is_relative_to(target), latentrl.__file__
assert default_model_path().resolve().is_relative_to(target), default_model_path()
model = load_motion_model("default")
policy = policy_file("reach_walk_default")
assert policy.resolve().is_relative_to(target), policy
state = read_checkpoint(policy, map_location="cpu")
assert state["motion"]["sha256"] == model.info["sha256"], "the shipped policy was trained on another model"
print("ok", model.latent_shape)
"""


def _run(cmd: list[str], cwd: Path, env: dict[str, str]) -> str:
    done = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, f"{' '.join(cmd)} -> {done.returncode}\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}"
    return done.stdout


def test_wheel_is_small_ships_only_the_defaults_and_loads_installed(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env.update(PIP_NO_INDEX="1", PIP_DISABLE_PIP_VERSION_CHECK="1", OMP_NUM_THREADS="1")
    src = tmp_path / "src"
    shutil.copytree(ROOT / "latentrl", src / "latentrl", ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, src / name)
    wheels = tmp_path / "wheels"
    _run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w", str(wheels),
          str(src)], tmp_path, env)
    wheel = next(wheels.glob("latentrl-*.whl"))
    size = wheel.stat().st_size
    with zipfile.ZipFile(wheel) as zf:
        names = zf.namelist()
    pts = sorted(n for n in names if n.endswith(".pt"))
    print(f"wheel {wheel.name}: {size / 1e6:.1f} MB, {len(pts)} .pt files")
    assert size <= MAX_WHEEL_BYTES, f"{size / 1e6:.1f} MB"
    assert len(pts) <= MAX_PT_FILES, pts
    assert "latentrl/assets/default_motion.pt" in pts
    assert all(n == "latentrl/assets/default_motion.pt" or n.endswith("_default.pt") for n in pts), pts
    assert not any(n.startswith("zoo/") or "/zoo/" in n for n in names)

    target = tmp_path / "site"
    _run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target), str(wheel)],
         tmp_path, env)
    empty = tmp_path / "empty"
    empty.mkdir()
    env["PYTHONPATH"] = str(target)  # ahead of the checkout's editable install on sys.path
    out = _run([sys.executable, "-c", CHECK, str(target)], empty, env)
    assert out.startswith("ok"), out
