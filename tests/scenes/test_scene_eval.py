"""Evaluation with a scene: collision rate and penetration in the report, obstacles in paths.png, the scene in the
motion file; flat evaluations unchanged."""

import json

import numpy as np
import pytest
import torch

from latentrl.envs.path import WaypointPath
from latentrl.errors import DataError
from latentrl.evaluation import report as R
from latentrl.evaluation.config import EvalSettings
from latentrl.evaluation.plots import save_paths_png
from latentrl.evaluation.results import SuiteResult
from latentrl.evaluation.runner import run_path
from latentrl.motion.clip import MotionClip
from latentrl.scenes import Box, Cylinder, Scene, SceneBatch, scene_from_json, scene_to_dict, scene_to_json
from latentrl.scenes.contact import scene_metrics

AROUND = Scene((Box((0.0, 0.0), (1.0, 1.0, 2.0)), Cylinder((0.0, 3.0), 0.3, 1.0)))  # the start stands in the box
PATH = WaypointPath(((0.0, 2.0, 0.0),), ("walk",))


def zero(obs: torch.Tensor) -> torch.Tensor:
    return torch.zeros(obs.shape[0], 16)


def test_scene_metrics_known_answers():
    scene = SceneBatch.from_scenes([Scene((Box((0.0, 0.0), (2.0, 2.0, 2.0)),))])
    joints = torch.zeros(3, 22, 3)
    joints[..., 0] = 5.0  # clear, then two frames with the pelvis 0.05 m and 0.3 m inside the box's face at x = 1
    joints[1, 0] = torch.tensor([0.95, 0.0, 1.0])
    joints[2, 0] = torch.tensor([0.70, 0.0, 1.0])
    m = scene_metrics(joints, scene)
    assert m["collision"] == 1.0
    assert m["scene_penetration_max_cm"] == pytest.approx(40.0, abs=1e-3)  # 0.3 deep + the 0.10 skin
    assert m["scene_penetration_cm"] == pytest.approx((0 + 15.0 + 40.0) / 3, abs=1e-3)
    clear = torch.full((2, 22, 3), 5.0)
    assert scene_metrics(clear, scene) == {"collision": 0.0, "scene_penetration_cm": 0.0,
                                           "scene_penetration_max_cm": 0.0}


def test_motion_clip_carries_the_scene(tmp_path):
    joints = np.zeros((4, 22, 3), np.float32)
    clip = MotionClip(joints, scene=scene_to_json(AROUND))
    clip.save(tmp_path / "m.npz")
    back = MotionClip.load(tmp_path / "m.npz")
    assert scene_from_json(back.scene) == AROUND and back.meta == {}
    assert back.cut(0).scene == back.scene and back.to_dict()["scene"] == back.scene
    MotionClip(joints).save(tmp_path / "old.npz")  # files without a scene load as before
    assert MotionClip.load(tmp_path / "old.npz").scene is None
    with pytest.raises(DataError, match="field 'scene' must be the scene's JSON text"):
        MotionClip(joints, scene=np.zeros(3))


def test_run_path_with_a_scene_reports_collisions_and_draws_it(tiny_model, tmp_path):
    settings = EvalSettings(episodes=2, max_steps=2)
    settings.scene = scene_to_dict(AROUND)
    motions = []
    result = run_path(zero, tiny_model, PATH, settings, suite="s", sink=lambda ep, m: motions.append(m) or "f")
    for ep, motion in zip(result.episodes, motions):
        assert ep.metrics["collision"] == 1.0 and ep.metrics["scene_penetration_max_cm"] > 0
        assert scene_from_json(motion["scene"]) == AROUND and ep.scene == motion["scene"]
    report = R.build_report([SuiteResult("s", "s.json", [result])], settings, policy={}, motion={})
    overall = report["overall"]["metrics"]
    assert overall["collision"]["mean"] == 1.0 and "scene_penetration_max_cm" in overall
    assert report["settings"]["scene"] == scene_to_dict(AROUND)
    assert "| collision rate | scene penetration (cm) | max scene penetration (cm) |" in R.report_markdown(report)
    png = save_paths_png(tmp_path / "paths.png", [SuiteResult("s", "s.json", [result])])
    assert png.stat().st_size > 1000


def test_random_obstacles_in_the_eval_env_and_flat_reports_unchanged(tiny_model):
    settings = EvalSettings(episodes=3, max_steps=1)
    settings.scene = {"random_obstacles": {"count": [3, 3], "distance": [1.0, 3.0]}}
    result = run_path(zero, tiny_model, PATH, settings, suite="s")
    scenes = [scene_from_json(ep.scene) for ep in result.episodes]
    assert all(1 <= len(s.objects) <= 3 for s in scenes) and len({s for s in scenes}) == 3
    flat = run_path(zero, tiny_model, PATH, EvalSettings(episodes=1, max_steps=1), suite="s")
    assert "collision" not in flat.episodes[0].metrics and flat.episodes[0].scene is None
    report = R.build_report([SuiteResult("s", "s.json", [flat])], EvalSettings(episodes=1, max_steps=1),
                            policy={}, motion={})
    assert "scene" not in report["settings"] and list(report["overall"]["metrics"]) == list(R.METRICS)
    assert json.dumps(report, default=str)


def test_eval_command_with_a_scene_for_a_policy_trained_without_one(eval_files, tmp_path, capsys):
    from latentrl.app.cli import main
    from tests.evaluation.conftest import NEAR, write_paths

    paths = write_paths(tmp_path, [NEAR], "mini.json")
    base = ["eval", str(eval_files["policy"]), "--motion", str(eval_files["motion"]), "--paths", str(paths),
            "--episodes", "2", "--max-steps", "2", "--device", "cpu", "--no-render", "--no-progress"]
    assert main([*base, "--out", str(tmp_path / "out"), "--scene", "random_obstacles"]) == 0
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["settings"]["scene"] == {"random_obstacles": {}} and report["settings"]["observe_scene"] is False
    assert "collision" in report["overall"]["metrics"]
    motion = MotionClip.load(next((tmp_path / "out" / "motions").glob("*.npz")))
    assert len(scene_from_json(motion.scene).objects) >= 1
    capsys.readouterr()
    assert main([*base, "--out", str(tmp_path / "bad"), "--scene", "nowhere.json"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--scene: scene file not found: nowhere.json" in err[0]


def far_scene_eval(eval_files, tmp_path) -> list[str]:
    """``latentrl eval`` arguments of the tiny policy on one near goal, in a scene whose one box stands 40 m away."""
    from tests.evaluation.conftest import NEAR, write_paths

    paths = write_paths(tmp_path, [NEAR], "mini.json")
    far = tmp_path / "far.json"
    far.write_text(json.dumps({"format": "latentrl.scene/1", "objects": [
        {"type": "box", "center": [30.0, 30.0], "size": [0.5, 0.5, 1.0]}]}))
    return ["eval", str(eval_files["policy"]), "--motion", str(eval_files["motion"]), "--paths", str(paths),
            "--episodes", "2", "--max-steps", "3", "--device", "cpu", "--no-render", "--no-progress",
            "--scene", str(far)]


def test_eval_avoid_records_its_settings_leaves_a_clear_plan_alone_and_a_stored_choice_is_the_default(
        eval_files, tmp_path, capsys):
    """``--avoid`` among far objects changes no metric (the filter acts only on a plan near an object); its
    settings go into report.json; a policy storing ``eval.avoid`` is filtered without the flag."""
    from latentrl.app.cli import main
    from latentrl.ppo.checkpoint import read_checkpoint, save_checkpoint

    base = far_scene_eval(eval_files, tmp_path)
    assert main([*base, "--out", str(tmp_path / "plain")]) == 0
    assert main([*base, "--out", str(tmp_path / "filtered"), "--avoid", "3", "--avoid-horizon", "1"]) == 0
    plain, filtered = (json.loads((tmp_path / d / "report.json").read_text()) for d in ("plain", "filtered"))
    assert "avoid" not in plain
    assert filtered["avoid"] == {"steps": 3, "horizon": 1, "margin": 0.1, "anchor": 0.1, "weight": 100.0, "lr": 0.3,
                                 "prior": 0.1, "samples": 0}
    assert filtered["overall"]["metrics"] == plain["overall"]["metrics"]
    state = read_checkpoint(eval_files["policy"], map_location="cpu")
    state["config"] = {**(state.get("config") or {}), "eval": {"avoid": 2, "avoid_margin": 0.2, "avoid_samples": 4}}
    stored = save_checkpoint(state, tmp_path / "stored.pt")
    capsys.readouterr()
    assert main([*base[:1], str(stored), *base[2:], "--out", str(tmp_path / "stored")]) == 0
    assert "--avoid 2 (the policy's stored evaluation setting; --avoid overrides)" in capsys.readouterr().out
    report = json.loads((tmp_path / "stored" / "report.json").read_text())
    assert report["avoid"]["steps"] == 2 and report["avoid"]["margin"] == 0.2 and report["avoid"]["horizon"] == 2
    assert report["avoid"]["samples"] == 4


def test_eval_route_records_its_settings_leaves_a_clear_way_alone_and_a_stored_choice_is_the_default(
        eval_files, tmp_path, capsys):
    """``--route`` where no object stands between the body and the goal changes no metric (the policy sees its own
    goal); its clearance goes into report.json's settings; a policy storing ``eval.route`` is guided without it."""
    from latentrl.app.cli import main
    from latentrl.ppo.checkpoint import read_checkpoint, save_checkpoint

    base = far_scene_eval(eval_files, tmp_path)
    assert main([*base, "--out", str(tmp_path / "plain")]) == 0
    assert main([*base, "--out", str(tmp_path / "guided"), "--route", "0.5"]) == 0
    plain, guided = (json.loads((tmp_path / d / "report.json").read_text()) for d in ("plain", "guided"))
    assert plain["settings"]["route"] is None and guided["settings"]["route"] == 0.5
    assert guided["overall"]["metrics"] == plain["overall"]["metrics"]
    state = read_checkpoint(eval_files["policy"], map_location="cpu")
    state["config"] = {**(state.get("config") or {}), "eval": {"route": 0.7}}
    stored = save_checkpoint(state, tmp_path / "stored.pt")
    capsys.readouterr()
    assert main([*base[:1], str(stored), *base[2:], "--out", str(tmp_path / "stored")]) == 0
    assert "--route 0.7 (the policy's stored evaluation setting; --route overrides)" in capsys.readouterr().out
    assert json.loads((tmp_path / "stored" / "report.json").read_text())["settings"]["route"] == 0.7


def test_a_policy_trained_blind_among_objects_is_evaluated_blind_in_its_scene_and_in_another(
        eval_files, tmp_path):
    """``env.observe_scene: false``: the eval env draws the training scene (or ``--scene``) without the rays the
    policy never had (with rays its observation would not fit the network)."""
    from latentrl.app.cli import main
    from latentrl.ppo.checkpoint import read_checkpoint, save_checkpoint
    from tests.evaluation.conftest import NEAR, write_paths

    state = read_checkpoint(eval_files["policy"], map_location="cpu")
    state["config"] = {"env": {"task": "path", "scene": {"random_obstacles": {}}, "observe_scene": False}}
    blind = save_checkpoint(state, tmp_path / "blind.pt")
    paths = write_paths(tmp_path, [NEAR], "mini.json")
    base = ["eval", str(blind), "--motion", str(eval_files["motion"]), "--paths", str(paths), "--episodes", "2",
            "--max-steps", "2", "--device", "cpu", "--no-render", "--no-progress"]
    for name, extra in (("own", []), ("other", ["--scene", "random_obstacles"])):
        assert main([*base, "--out", str(tmp_path / name), *extra]) == 0
        report = json.loads((tmp_path / name / "report.json").read_text())
        assert report["settings"]["observe_scene"] is False and "collision" in report["overall"]["metrics"]
