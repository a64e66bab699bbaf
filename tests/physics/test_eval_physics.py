"""``latentrl eval --physics``: a shipped reach policy with physics in the loop, beside its kinematic run."""

import json

import numpy as np
import pytest
import torch

pytest.importorskip("mujoco")

from latentrl.app.cli import main  # noqa: E402
from latentrl.envs.path import WaypointPath  # noqa: E402
from latentrl.evaluation.config import EvalSettings  # noqa: E402
from latentrl.evaluation.physics_episodes import run_episode  # noqa: E402
from latentrl.evaluation.runner import policy_fn  # noqa: E402
from latentrl.motion.checkpoint import load_motion_model  # noqa: E402
from latentrl.physics.humanoid import build_humanoid  # noqa: E402
from latentrl.ppo import load_policy  # noqa: E402
from latentrl.resources import policy_file  # noqa: E402


def test_eval_physics_writes_both_runs(tmp_path):
    paths = tmp_path / "one.json"
    paths.write_text(json.dumps([{"goal_location": [[0.0, 3.0, 0.0]], "goal_text": ["walk"]}]))
    out = tmp_path / "ev"
    assert main(["eval", "reach_walk_default", "--paths", str(paths), "--episodes", "1", "--max-steps", "3",
                 "--device", "cpu", "--physics", "--out", str(out)]) == 0
    report = json.loads((out / "physics.json").read_text())
    assert report["format"] == "latentrl.eval.physics/1" and report["batch"] == 1
    (path,) = report["paths"]
    phys, kin = path["physics"], path["kinematic"]
    for key in ("success_rate", "reach_time_s", "penetration_mm", "floating_mm", "skating_mm"):
        assert np.isfinite(phys[key]) and np.isfinite(kin[key])
    assert phys["falls_total"] >= 0 and phys["assist_percent_body_weight"] >= 0
    assert "falls" not in kin
    assert path["episodes"]["physics"][0]["seed"] == path["episodes"]["kinematic"][0]["seed"]


def test_history_comes_from_simulation():
    model = load_motion_model("default", device="cpu")
    policy = load_policy(str(policy_file("reach_walk_default")), "cpu").policy
    settings = EvalSettings(episodes=1, max_steps=2, device="cpu")
    seen = []

    def check(env, executor):
        history = env.history_world()[0].double().numpy()
        seen.append(np.abs(history - executor.simulated[-2:]).max())
        assert np.abs(history - executor.planned[-1][-2:]).max() > 1e-3  # physics did not follow the plan exactly

    result = run_episode(policy_fn(policy), model, WaypointPath(((0.0, 3.0, 0.0),), ("walk",)), settings, 7,
                         humanoid=build_humanoid(1.72), assist_hz=2.0, on_step=check)
    assert len(seen) == 2 and max(seen) < 1e-3  # the env's history is the simulated frames (float32)
    assert result["falls"] >= 0 and "assist_percent_body_weight" in result
    # the kinematic run of the same seed plans from the model's own frames instead
    kin = run_episode(policy_fn(policy), model, WaypointPath(((0.0, 3.0, 0.0),), ("walk",)), settings, 7)
    assert "falls" not in kin and torch.isfinite(torch.tensor(kin["final_dist_m"]))
