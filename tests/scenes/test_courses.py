"""Maze and stairs courses: the shipped files are the generator's, waypoints keep clear of the walls, the suites carry
their scenes and evaluate (tiny model: the default model has no stairs skills, and no maze policy ships)."""

import json

import pytest
import torch

from latentrl.app.cli import main
from latentrl.envs.path import WaypointPath, load_paths
from latentrl.errors import DataError
from latentrl.resources import packaged
from latentrl.scenes import Box, Scene, SceneBatch, Stairs, load_scene
from latentrl.scenes.courses import COURSES, SUITES, maze, scene_file_text, suite_file_text

TASKS = packaged("tasks")
MAZES = [name for name in COURSES if name.startswith("maze")]


def test_shipped_scenes_and_suites_are_the_generators_output():
    for name in COURSES:
        assert (TASKS / "scenes" / f"{name}.json").read_text() == scene_file_text(name), name
        assert load_scene(TASKS / "scenes" / f"{name}.json") == COURSES[name]().scene
    for name in SUITES:
        assert (TASKS / "paths" / f"{name}.json").read_text() == suite_file_text(name), name


def _along(waypoints, step=0.05):
    """Points every ``step`` metres along the polyline from the start (the origin) through ``waypoints``."""
    pts = [(0.0, 0.0), *waypoints]
    out = []
    for (x0, y0), (x1, y1) in zip(pts[:-1], pts[1:]):
        n = max(1, int(((x1 - x0) ** 2 + (y1 - y0) ** 2) ** 0.5 / step))
        out += [(x0 + (x1 - x0) * k / n, y0 + (y1 - y0) * k / n) for k in range(n + 1)]
    return out


@pytest.mark.parametrize("name", MAZES)
def test_maze_waypoints_and_segments_keep_clear_of_the_walls(name):
    course = COURSES[name]()
    batch = SceneBatch.from_scenes([course.scene])
    assert all(isinstance(o, Box) for o in course.scene.objects) and len(course.scene.objects) <= 64
    for z in (0.1, 0.9):  # a foot and the pelvis
        wps = torch.tensor([[(x, y, z) for x, y in course.waypoints]])
        assert float(batch.sdf(wps).min()) >= 0.6 - 1e-6
        line = torch.tensor([[(x, y, z) for x, y in _along(course.waypoints)]])
        assert float(batch.sdf(line).min()) >= 0.6 - 1e-6
    # the corridor is at least 1.2 m wide: a wall stands within 0.6 m + 1 cm of some point of every corridor
    assert min(float(batch.sdf(torch.tensor([[(x, y, 0.5)]]))) for x, y in course.waypoints) <= 0.6 + 0.31


def test_maze_is_perfect_and_reaches_the_last_row():
    course = maze(4, 4, seed=7, cell=2.0)
    assert course.waypoints[-1][1] == pytest.approx(6.0)  # row 3 of 2 m cells
    steps = [(abs(x1 - x0) + abs(y1 - y0)) for (x0, y0), (x1, y1)
             in zip([(0.0, 0.0), *course.waypoints[:-1]], course.waypoints)]
    assert all(s == pytest.approx(2.0) for s in steps)  # one cell at a time, never through a wall
    assert len(set(course.waypoints)) == len(course.waypoints)
    with pytest.raises(ValueError, match="maze: need"):
        maze(2, 1, seed=0)


def test_stairs_courses_rise_and_fall_with_risers_between_10_and_20_cm():
    for name in ("stairs_10", "stairs_15", "stairs_20", "stairs_turn"):
        course = COURSES[name]()
        flights = [o for o in course.scene.objects if isinstance(o, Stairs)]
        assert len(flights) == 2 and all(0.10 <= f.riser <= 0.20 for f in flights)
        batch = SceneBatch.from_scenes([course.scene])
        heights = batch.height(torch.tensor([list(course.waypoints)]))[0]
        top = flights[0].top
        # on the way up (mid flight), on the landing, on the way down, on the floor beyond
        assert 0 < float(heights[0]) < top and float(heights[1]) == pytest.approx(top)
        assert 0 < float(heights[2]) < top and float(heights[3]) == 0.0


def test_suites_load_with_their_scenes():
    for name in SUITES:
        paths = load_paths(TASKS / "paths" / f"{name}.json")
        assert [p.scene for p in paths] == [COURSES[s]().scene for s, _ in SUITES[name]]
    skills = load_paths(TASKS / "paths" / "stairs_skills.json")[0]
    assert skills.texts == ("walk up stairs", "walk up stairs", "walk down stairs", "walk down stairs")


def test_a_paths_scene_file_is_found_beside_the_path_file_and_bad_ones_are_one_line(tmp_path):
    (tmp_path / "room.json").write_text(scene_file_text("stairs_10"))
    entry = {"goal_location": [[0, 2, 0]], "goal_text": ["walk"]}
    (tmp_path / "p.json").write_text(json.dumps([{**entry, "scene": "room.json"}, {**entry, "scene": "maze_a"}]))
    first, second = load_paths(tmp_path / "p.json")
    assert first.scene == COURSES["stairs_10"]().scene and second.scene == COURSES["maze_a"]().scene
    for scene, message in ((3, "field 'scene' must be a scene file name or a latentrl.scene/1 object, got int"),
                           ("nope.json", "field 'scene': scene: scene file not found: nope.json"),
                           ({"random_obstacles": {}}, "field 'scene' must be a fixed scene"),
                           ({"format": "latentrl.scene/1", "objects": [{"type": "box"}]},
                            "field 'scene': env.scene: objects[0].center: missing")):
        (tmp_path / "bad.json").write_text(json.dumps([{**entry, "scene": scene}]))
        with pytest.raises(DataError) as err:
            load_paths(tmp_path / "bad.json")
        assert str(err.value).startswith(f"{tmp_path / 'bad.json'}: path 0: {message}")
        assert "\n" not in str(err.value)


@pytest.mark.parametrize("suite", ["maze", "stairs"])
def test_eval_paths_of_a_course_suite_reports_collisions_and_terrain_metrics(suite, eval_files, tmp_path, capsys):
    out = tmp_path / "ev"
    code = main(["eval", str(eval_files["policy"]), "--motion", str(eval_files["motion"]), "--paths", suite,
                 "--episodes", "1", "--max-steps", "2", "--out", str(out), "--device", "cpu"])
    assert code == 0, capsys.readouterr().err
    report = json.loads((out / "report.json").read_text())
    assert set(report["overall"]["metrics"]) >= {"collision", "scene_penetration_cm", "penetration_mm",
                                                 "floating_mm"}
    paths = report["suites"][suite]["paths"]
    assert len(paths) == len(SUITES[suite])
    for p in paths:
        ep = p["episodes"][0]
        assert {"collision", "penetration_mm", "floating_mm", "floor_cm"} <= set(ep)
    assert "collision rate" in (out / "report.md").read_text()


def test_stairs_episodes_measure_the_feet_against_the_treads(tiny_model):
    """Each episode's floor metrics and skill judgement on a stairs suite are the terrain-aware ones of its motion."""
    from latentrl.evaluation import metrics as M
    from latentrl.evaluation.config import EvalSettings
    from latentrl.evaluation.runner import run_path
    from latentrl.evaluation.skills import judge_clip
    from latentrl.motion.clip import MotionClip

    path = load_paths(TASKS / "paths" / "stairs.json")[2]  # 0.20 m risers
    motions = []
    result = run_path(lambda obs: torch.zeros(obs.shape[0], 16), tiny_model, path,
                      EvalSettings(episodes=2, max_steps=6), suite="stairs",
                      sink=lambda ep, m: motions.append(m) or None)
    terrain = SceneBatch.from_scenes([COURSES["stairs_20"]().scene])
    for ep, motion in zip(result.episodes, motions):
        assert ep.scene is not None and load_scene_text(ep.scene) == COURSES["stairs_20"]().scene
        expected = M.episode_metrics(torch.as_tensor(motion["joints"]), 30.0, 0.0, terrain)
        assert {k: ep.metrics[k] for k in expected} == pytest.approx(expected)
        assert {"collision", "scene_penetration_cm", "scene_penetration_max_cm"} <= set(ep.metrics)
        assert ep.segments == judge_clip(MotionClip.from_dict(motion), terrain)  # the judge stands on the treads

    # On a platform the start stands on, the flat judge sees no foot down; the evaluation's judge does.
    platform = Scene((Box((0.0, 0.0), (8.0, 8.0, 0.3)),))
    path = WaypointPath(((0.0, 2.0, 0.0),), ("walk",), scene=platform)
    result = run_path(lambda obs: torch.zeros(obs.shape[0], 16), tiny_model, path,
                      EvalSettings(episodes=1, max_steps=6), suite="platform",
                      sink=lambda ep, m: motions.append(m) or None)
    [seg] = result.episodes[0].segments
    clip = MotionClip.from_dict(motions[-1])
    assert clip.joints[2:, :, 2].min() > 0.29  # after the seed frames the body stands on the platform
    [flat] = judge_clip(clip)
    assert seg["measured"] and seg == judge_clip(clip, SceneBatch.from_scenes([platform]))[0]
    assert flat["left_only"] == flat["right_only"] == 0.0 and seg != flat


def load_scene_text(text):
    from latentrl.scenes import scene_from_json

    return scene_from_json(text)


def test_physics_eval_refuses_a_suite_whose_paths_run_in_a_scene(eval_files, tmp_path, capsys):
    code = main(["eval", str(eval_files["policy"]), "--motion", str(eval_files["motion"]), "--paths", "stairs",
                 "--physics", "--episodes", "1", "--max-steps", "2", "--out", str(tmp_path / "ev"), "--device", "cpu"])
    err = capsys.readouterr().err
    assert code == 2 and "--physics: stairs's paths run in a scene; the humanoid walks on the flat floor" in err
