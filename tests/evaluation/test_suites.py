"""Our path suites: the shipped JSON files are exactly what the generators write, and they load."""

import math

import pytest

from latentrl.envs import load_paths
from latentrl.evaluation import suites


@pytest.mark.parametrize("name", sorted(suites.SUITES))
def test_shipped_file_equals_generator(name):
    shipped = suites.default_folder() / f"{name}.json"
    assert shipped.read_text(encoding="utf-8") == suites.suite_json(suites.SUITES[name]()), (
        f"{shipped} differs from the generator; run `python -m latentrl.evaluation.suites`"
    )


@pytest.mark.parametrize("name", sorted(suites.SUITES))
def test_suites_load_with_dart_texts(name):
    paths = load_paths(suites.default_folder() / f"{name}.json")
    assert len(paths) == 5
    assert all(t in suites.SKILLS for p in paths for t in p.texts)
    assert paths == suites.SUITES[name]()  # the JSON round trip loses nothing (mm-rounded coordinates)


def test_generators_are_deterministic_and_write_files(tmp_path):
    assert suites.random_smooth() == suites.random_smooth()
    written = suites.write_suites(tmp_path)
    assert sorted(p.name for p in written) == sorted(f"{n}.json" for n in suites.SUITES)


def test_suite_content_matches_its_description():
    behind = suites.sharp_turns()[2]
    assert behind.waypoints[0][:2] == (0.0, -3.0)  # straight behind the start (facing +y)
    assert len(set(suites.mixed_text()[0].texts)) == 3  # the skill changes along the way
    for path in suites.random_smooth():
        pts = [(0.0, 0.0)] + [w[:2] for w in path.waypoints]
        lengths = [math.dist(a, b) for a, b in zip(pts[:-1], pts[1:])]
        assert all(1.99 <= seg <= 4.01 for seg in lengths)


def test_mixed_skills_segments_suit_their_skill():
    for path in suites.mixed_skills():
        pts = [(0.0, 0.0)] + [w[:2] for w in path.waypoints]
        for text, a, b in zip(path.texts, pts[:-1], pts[1:]):
            lo, hi = suites.SKILL_SEGMENT_M[text]
            assert lo - 0.01 <= math.dist(a, b) <= hi + 0.01
        assert all(t != u for t, u in zip(path.texts[:-1], path.texts[1:]))  # the skill changes at every waypoint
