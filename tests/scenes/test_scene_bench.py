"""``latentrl bench env --scene``: the 8-object scene's step-time ratio to the flat env of the same run."""

import argparse
import json

from latentrl.app.bench.env import bench_env


def test_bench_env_times_the_scene_beside_the_flat_env(tmp_path, capsys):
    args = argparse.Namespace(models=["tiny"], num_envs=[2], device=["cpu"], steps=1, max_seconds=60.0,
                              baseline=False, compile=False, amp=None, threads=None, json=str(tmp_path / "e.json"),
                              scene=True)
    assert bench_env(args) == 0
    (row,) = json.loads((tmp_path / "e.json").read_text())["models"]["tiny"]["results"]
    assert row["scene"]["env_steps_per_s"] > 0
    assert row["scene_cost"] == row["vector"]["env_steps_per_s"] / row["scene"]["env_steps_per_s"]
    assert "8-object scene: x" in capsys.readouterr().out
