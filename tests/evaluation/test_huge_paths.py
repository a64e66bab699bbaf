"""A 10,000-waypoint path (the limit) is handled end to end by ``latentrl eval``; one more is refused."""

import json
import time

from latentrl.app.cli import main
from latentrl.envs.path import MAX_WAYPOINTS
from tests.evaluation.conftest import write_paths


def long_path(n: int) -> list[dict]:
    return [{"goal_location": [[0.0, 0.5 + 0.3 * i, 0.0] for i in range(n)], "goal_text": ["walk", "run"] * (n // 2)}]


def test_ten_thousand_waypoints_are_evaluated(eval_files, tmp_path, capsys):
    assert MAX_WAYPOINTS == 10_000
    paths = write_paths(tmp_path, long_path(MAX_WAYPOINTS), "long.json")
    t0 = time.perf_counter()
    code = main(["eval", str(eval_files["policy"]), "--motion", str(eval_files["motion"]), "--paths", str(paths),
                 "--episodes", "2", "--max-steps", "2", "--device", "cpu", "--out", str(tmp_path / "out"),
                 "--no-render", "--no-motions"])
    assert code == 0, capsys.readouterr().err
    assert time.perf_counter() - t0 < 60  # plotting 10,000 numbered waypoints alone took 50 s before MAX_LABELS
    episode = json.loads((tmp_path / "out" / "report.json").read_text())["suites"]["long"]["paths"][0]["episodes"][0]
    assert len(episode["waypoint_times_s"]) == MAX_WAYPOINTS and episode["end"] == "timeout"
    assert (tmp_path / "out" / "paths.png").is_file()
