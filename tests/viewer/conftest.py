"""Motions, evaluation folders and runs on disk for the viewer tests (hand-made, no model needed)."""

import json
from pathlib import Path

import numpy as np
import pytest

from latentrl.render import save_motion_npz
from tests.helpers import rest_joints


def walking(frames: int = 50, speed: float = 0.03) -> np.ndarray:
    """(T, 22, 3) the rest skeleton sliding along +y, feet on the floor."""
    rest = rest_joints().numpy()
    rest[:, 2] -= rest[:, 2].min()
    joints = np.repeat(rest[None], frames, axis=0)
    joints[:, :, 1] += speed * np.arange(frames)[:, None]
    return joints.astype(np.float32)


def write_eval(folder: Path, episodes: int = 2) -> Path:
    """A minimal evaluation folder: report.json naming one motion file per episode."""
    from latentrl.evaluation.report import FORMAT

    waypoints = [[0.0, 1.0, 0.0], [1.0, 2.0, 0.0]]
    eps = []
    for e in range(episodes):
        name = f"motions/demo_path0_ep{e:03d}.npz"
        steps = 6
        save_motion_npz(folder / name, walking(2 + 8 * steps), texts=[""] * 2 + ["walk"] * 8 * steps,
                        goals=np.array([waypoints[0]] * 3 + [waypoints[1]] * 3), waypoints=np.array(waypoints),
                        primitive=np.r_[[-1, -1], np.repeat(np.arange(steps), 8)], success=e == 0,
                        end="success" if e == 0 else "timeout", reach_time_s=1.7)
        eps.append({"episode": e, "success": e == 0, "end": "success" if e == 0 else "timeout", "steps": steps,
                    "reach_time_s": 1.7, "final_dist_m": 0.1, "skate_cm_s": 1.0, "floor_cm": 2.0, "motion": name})
    metrics = {"success_rate": {"mean": 0.5, "ci95": 0.1}, "reach_time_s": {"mean": 1.7, "ci95": 0.0},
               "skate_cm_s": {"mean": 1.0, "ci95": 0.0}, "floor_cm": {"mean": 2.0, "ci95": 0.0}}
    report = {"format": FORMAT, "policy": {"path": "final.pt"}, "settings": {},
              "suites": {"demo": {"paths": [{"index": 0, "waypoints": waypoints, "episodes": eps}]}},
              "overall": {"metrics": metrics}}
    (folder / "report.json").write_text(json.dumps(report))
    return folder


@pytest.fixture
def motion_file(tmp_path) -> Path:
    return save_motion_npz(tmp_path / "walk.npz", walking(), texts=["walk"] * 50)


@pytest.fixture
def eval_folder(tmp_path) -> Path:
    return write_eval(tmp_path / "eval")


def walk_controller(server):
    """``latentrl play``'s controller for the shipped walk policy, built as the command builds it (not started).

    The policy's training env settings: the shipped walk runs with the foot lock.
    """
    from latentrl.motion.checkpoint import load_motion_model
    from latentrl.ppo import load_policy
    from latentrl.resources import policy_file
    from latentrl.viewer.live import LiveController, SteeredReachEnv

    env = SteeredReachEnv(1, motion=load_motion_model("default"), texts=["walk", "run"], max_episode_steps=10**9,
                          autoreset_mode="Disabled", foot_lock=True)
    return LiveController(server, env, load_policy(policy_file("reach_walk_default")).policy, "test", "walk", seed=0)


@pytest.fixture
def server():
    """A bare Viser server on a free loopback port."""
    viser = pytest.importorskip("viser")
    srv = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield srv
    srv.stop()


@pytest.fixture
def guarded_server(monkeypatch):
    """latentrl's own server (origin check, connection bound) for ``play``, with a fresh stderr-line window."""
    pytest.importorskip("viser")
    from latentrl.viewer import guard
    from latentrl.viewer.server import start_server

    monkeypatch.setattr(guard, "_window", {"start": -float("inf"), "lines": 0})
    srv = start_server("127.0.0.1", 0, "test", "play")
    yield srv
    srv.stop()
