"""``latentrl eval``, ``compare`` and ``motion export-bvh`` end to end on the tiny model and a fresh policy."""

import json
import re

import numpy as np
import pytest

from latentrl.app.cli import main
from latentrl.app.evaluate import resolve_path_files
from latentrl.render import load_bvh, load_motion_npz
from tests.evaluation.conftest import FAR, NEAR, write_paths


def run_eval(eval_files, paths, out, *extra) -> int:
    return main(["eval", str(eval_files["policy"]), "--motion", str(eval_files["motion"]), "--paths", str(paths),
                 "--episodes", "2", "--max-steps", "3", "--device", "cpu", "--out", str(out), *extra])


@pytest.fixture(scope="module")
def evaluated(eval_files, tmp_path_factory):
    root = tmp_path_factory.mktemp("eval_cli")
    paths = write_paths(root, [NEAR, FAR], "mini.json")
    assert run_eval(eval_files, paths, root / "out", "--render", "gif") == 0
    return root / "out"


def _frames(path) -> int:
    import imageio_ffmpeg

    reader = imageio_ffmpeg.read_frames(str(path))
    next(reader)  # the header
    return sum(1 for _ in reader)


def test_eval_draws_nothing_by_default(eval_files, tmp_path, capsys):
    paths = write_paths(tmp_path, [NEAR], "mini.json")
    assert run_eval(eval_files, paths, tmp_path / "out", "--no-progress") == 0
    assert not (tmp_path / "out" / "renders").exists()
    assert json.loads((tmp_path / "out" / "report.json").read_text())["files"]["renders"] is None
    assert "renders:" not in capsys.readouterr().out


def test_eval_render_mp4_writes_decodable_videos(eval_files, tmp_path, capsys):
    pytest.importorskip("imageio_ffmpeg")
    paths = write_paths(tmp_path, [NEAR, FAR], "mini.json")
    out = tmp_path / "out"
    assert run_eval(eval_files, paths, out, "--render", "mp4", "--render-episodes", "2", "--no-progress") == 0
    videos = sorted(p.name for p in (out / "renders").glob("*.mp4"))
    assert videos == [f"mini_path{p}_ep00{e}.mp4" for p in (0, 1) for e in (0, 1)]
    assert not list((out / "renders").glob("*.gif"))
    far = load_motion_npz(out / "motions" / "mini_path1_ep000.npz")
    assert _frames(out / "renders" / "mini_path1_ep000.mp4") == far["joints"].shape[0]  # every frame, 26
    assert json.loads((out / "report.json").read_text())["files"]["renders"] == "renders/*.mp4"
    assert f"renders: {out / 'renders'}" in capsys.readouterr().out


def test_eval_writes_report_plot_motions_and_renders(evaluated):
    report = json.loads((evaluated / "report.json").read_text())
    suite = report["suites"]["mini"]
    assert [p["metrics"]["success_rate"]["mean"] for p in suite["paths"]] == [1.0, 0.0]
    assert report["overall"]["metrics"]["reach_time_s"]["mean"] == pytest.approx((10 / 30 + 26 / 30) / 2)
    assert report["policy"]["iteration"] == 0 and len(report["policy"]["sha256"]) == 64
    assert len(report["motion"]["sha256"]) == 64 and set(report["speed"]) == {"1", "2"}
    assert (evaluated / "paths.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    md = (evaluated / "report.md").read_text()
    assert re.search(r"\| mini \| 0 \([^)]+\) \| 1.00 ± 0.00 \|", md)  # each path row names its prompts
    assert re.search(r"\| mini \| 1 \([^)]+\) \| 0.00 ± 0.00 \|", md)
    motions = sorted((evaluated / "motions").glob("*.npz"))
    assert [m.name for m in motions] == [f"mini_path{p}_ep00{e}.npz" for p in (0, 1) for e in (0, 1)]
    far = load_motion_npz(motions[2])
    assert far["joints"].shape == (26, 22, 3) and far["actions"].shape[0] == 3 and not bool(far["success"])
    assert suite["paths"][1]["episodes"][0]["motion"] == "motions/mini_path1_ep000.npz"
    renders = sorted(p.name for p in (evaluated / "renders").iterdir())
    assert renders == ["mini_path0_ep000.bvh", "mini_path0_ep000.gif", "mini_path1_ep000.bvh", "mini_path1_ep000.gif"]
    bvh = load_bvh(evaluated / "renders" / "mini_path1_ep000.bvh")
    assert np.abs(bvh["joints"] - far["joints"]).max() < 1e-3


def test_compare_two_reports(evaluated, tmp_path, capsys):
    out = tmp_path / "cmp.md"
    assert main(["compare", str(evaluated), str(evaluated / "report.json"), "--out", str(out)]) == 0
    table = out.read_text()
    assert "| mini | out (0) |" in table and "| overall | out (1) |" in table
    assert table in capsys.readouterr().out


def test_malformed_path_file_names_path_and_field(eval_files, tmp_path, capsys):
    bad = write_paths(tmp_path, [NEAR, {"goal_location": [[0, 1, 0]], "goal_text": [""]}])
    assert run_eval(eval_files, bad, tmp_path / "out") == 2
    assert "paths.json: path 1, waypoint 0: field 'goal_text'" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_bad_settings_name_the_flag(eval_files, tmp_path, capsys):
    assert run_eval(eval_files, write_paths(tmp_path, [NEAR]), tmp_path / "o", "--max-steps", "0") == 2
    assert "--max-steps: must be >= 1, got 0" in capsys.readouterr().err


def test_policy_from_another_motion_model_is_refused(eval_files, tmp_path, capsys):
    from latentrl.motion.checkpoint import save_motion_model
    from tests.helpers import make_tiny_model

    other = save_motion_model(make_tiny_model(seed=1), tmp_path / "other.pt")
    paths = write_paths(tmp_path, [NEAR])
    code = main(["eval", str(eval_files["policy"]), "--motion", str(other), "--paths", str(paths),
                 "--out", str(tmp_path / "o"), "--device", "cpu"])
    assert code == 2 and "trained on motion model" in capsys.readouterr().err


def test_eval_takes_the_motion_model_the_policy_names(eval_files, tmp_path):
    """Without --motion, eval loads the model named in the policy's stored env config (not 'default')."""
    import torch

    from latentrl.motion.checkpoint import file_sha256

    state = torch.load(eval_files["policy"], weights_only=True)
    state["config"] = {"env": {"motion": str(eval_files["motion"]), "foot_lock": True, "guidance_scale": 3.0}}
    policy = tmp_path / "named.pt"
    torch.save(state, policy)
    out = tmp_path / "o"
    assert main(["eval", str(policy), "--paths", str(write_paths(tmp_path, [NEAR])), "--episodes", "1",
                 "--max-steps", "2", "--device", "cpu", "--out", str(out), "--no-render", "--no-motions"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["motion"]["sha256"] == file_sha256(eval_files["motion"])
    # the motion is stepped as in training: guidance and foot lock come from the stored env config too
    assert report["settings"]["foot_lock"] is True and report["settings"]["guidance_scale"] == 3.0
    assert report["settings"]["foot_lock_min_weight"] == 0.5  # the env default, stored config silent
    # a deployment setting that differs from training is taken and recorded; a bad one is a flag error
    assert main(["eval", str(policy), "--paths", str(write_paths(tmp_path, [NEAR])), "--episodes", "1",
                 "--max-steps", "2", "--device", "cpu", "--out", str(out), "--no-render", "--no-motions",
                 "--foot-lock-min-weight", "0.05"]) == 0
    assert json.loads((out / "report.json").read_text())["settings"]["foot_lock_min_weight"] == 0.05
    assert main(["eval", str(policy), "--foot-lock-min-weight", "0", "--device", "cpu"]) == 2


def test_eval_envs_take_the_training_envs_foot_lock(tiny_model):
    from latentrl.envs import load_paths
    from latentrl.envs.config import EnvConfig
    from latentrl.evaluation.config import EvalSettings
    from latentrl.evaluation.runner import make_env as path_env

    settings = EvalSettings()
    settings.take_training_env(EnvConfig(foot_lock=True, action_bound=3.0))
    assert settings.motion_kwargs() == {"guidance_scale": 5.0, "action_bound": 3.0, "foot_lock": True,
                                        "foot_lock_min_weight": 0.5, "amp": None}
    paths = load_paths(resolve_path_files(["sharp_turns"])[0])[:1]
    assert path_env(tiny_model, paths, 1, settings).foot_lock
    settings.take_training_env(EnvConfig(foot_lock=True, foot_lock_min_weight=0.05))
    assert path_env(tiny_model, paths, 1, settings).foot_lock_min_weight == 0.05
    settings.take_training_env(None)  # a checkpoint without a stored env: the env defaults
    assert settings.motion_kwargs() == {"guidance_scale": 5.0, "action_bound": 4.0, "foot_lock": False,
                                        "foot_lock_min_weight": 0.5, "amp": None}


def test_suite_names_resolve_to_shipped_files(tmp_path):
    files = resolve_path_files(["sharp_turns", "dart_walk_long.json"])
    assert [f.name for f in files] == ["sharp_turns.json", "dart_walk_long.json"]
    assert [f.stem for f in resolve_path_files(None)] == ["dart_walk_long", "dart_run_long", "dart_hop_long"]
    with pytest.raises(Exception, match="one of the suites"):
        resolve_path_files(["no_such_suite"])
    with pytest.raises(Exception, match="repeated"):
        resolve_path_files(["sharp_turns", "sharp_turns"])


def test_export_bvh_command(evaluated, tmp_path):
    motion = evaluated / "motions" / "mini_path0_ep000.npz"
    out = tmp_path / "walk.bvh"
    assert main(["motion", "export-bvh", str(motion), "--out", str(out)]) == 0
    back = load_bvh(out)
    assert np.abs(back["joints"] - load_motion_npz(motion)["joints"]).max() < 1e-3 and back["fps"] == pytest.approx(30)


def test_play_and_export_take_the_motion_model_the_policy_names(eval_files, tmp_path):
    """eval, play and export onnx share one rule: --motion, else the policy's stored env.motion, else 'default'."""
    import torch

    from latentrl.evaluation.trained import trained_motion
    from latentrl.resources import policy_file

    assert trained_motion(policy_file("reach_walk_default")) == "default"
    assert trained_motion(policy_file("reach_walk_default"), "my_model.pt") == "my_model.pt"
    state = torch.load(policy_file("reach_walk_default"), weights_only=True)
    state["config"]["env"]["motion"] = "default-v3"  # a policy trained on a model that is no longer shipped
    named = tmp_path / "named.pt"
    torch.save(state, named)
    assert trained_motion(named) == "default-v3"
    state.pop("config", None)
    bare = tmp_path / "bare.pt"
    torch.save(state, bare)
    assert trained_motion(bare) == "default"
    assert trained_motion(tmp_path / "missing.pt") == "default"  # the loaders then name the missing file


def test_eval_without_paths_runs_the_suites_of_the_policys_prompts():
    """A walk policy is judged on the walk suite alone, not on the run and hop suites it never learned."""
    from latentrl.app.evaluate import eval_suites

    spec, files = eval_suites("reach_walk_default", None)
    assert spec.name == "reach" and [f.name for f in files] == ["dart_walk_long.json"]
    _, files = eval_suites("reach_hop_left_default", None)
    assert [f.name for f in files] == ["dart_hop_long.json"]
    _, files = eval_suites("path_mixed_default", None)  # trained on all three prompts: all three suites
    assert [f.stem for f in files] == ["dart_walk_long", "dart_run_long", "dart_hop_long"]
    _, files = eval_suites("reach_walk_default", ["sharp_turns"])  # --paths still chooses
    assert [f.name for f in files] == ["sharp_turns.json"]


def test_an_interrupted_eval_leaves_the_report_of_the_paths_it_finished(eval_files, tmp_path, capsys, monkeypatch):
    """The report is rewritten after every path: Ctrl-C during the second path leaves a valid report of the first."""
    from latentrl.evaluation import runner
    from latentrl.evaluation.report import load_report

    paths = write_paths(tmp_path, [NEAR, FAR], "two.json")
    real, calls = runner.run_path, []

    def second_interrupted(*args, **kwargs):
        calls.append(kwargs["index"])
        if len(calls) == 2:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(runner, "run_path", second_interrupted)
    out = tmp_path / "out"
    assert run_eval(eval_files, paths, out, "--no-render", "--no-progress") == 130
    assert calls == [0, 1] and "interrupted" in capsys.readouterr().err
    report = load_report(out)
    assert [p["index"] for p in report["suites"]["two"]["paths"]] == [0]
    assert report["overall"]["paths"] == 1 and report["suites"]["two"]["metrics"]["success_rate"]["mean"] == 1.0
    assert "| two | 0 (" in (out / "report.md").read_text() and (out / "paths.png").is_file()
    assert not list(out.glob(".*.tmp"))  # written atomically: no temporary left


def test_eval_progress_bar_counts_paths_times_episodes(eval_files, tmp_path, capsys):
    """The bar (stderr) ends at paths x episodes; --no-progress hides it."""
    paths = write_paths(tmp_path, [NEAR, NEAR, NEAR], "three.json")
    assert run_eval(eval_files, paths, tmp_path / "a", "--no-render", "--no-motions") == 0
    assert "6/6" in capsys.readouterr().err
    assert run_eval(eval_files, paths, tmp_path / "b", "--no-render", "--no-motions", "--no-progress") == 0
    assert "6/6" not in capsys.readouterr().err
