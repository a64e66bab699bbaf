"""Routes among objects (latentrl.scenes.route): lengths on hand-made scenes, clearance, carrots, bad settings."""

from __future__ import annotations

import math

import numpy as np
import pytest

from latentrl.errors import ConfigError
from latentrl.scenes.route import RouteMap, RouteSettings
from latentrl.scenes.scene import Box, Cylinder, Scene, SceneBatch

WALL = Scene([Box(center=(0.0, 2.0), size=(2.0, 0.2, 1.5))])
"""A wall 2 m wide across the way, 1.9-2.1 m ahead of a start at the origin; the goal beyond it at (0, 4)."""


def one(scene: Scene) -> SceneBatch:
    return SceneBatch.from_scenes([scene])


def test_on_an_empty_floor_the_route_is_the_straight_line_and_the_carrot_the_goal():
    s = RouteSettings(cell=0.05)
    m = RouteMap(one(Scene()), (0.0, 0.0), (3.0, 1.0), s)
    line = math.hypot(3.0, 1.0) - s.reach
    assert m.length((0.0, 0.0)) == pytest.approx(line, abs=0.03 * line + s.cell)  # 8-connected: within 3 %
    point, left = RouteMap(one(Scene()), (0.0, 0.0), (3.0, 1.0), RouteSettings(lookahead=math.inf)).carrot((0, 0))
    assert np.allclose(point, (3.0, 1.0)) and left == pytest.approx(math.hypot(3.0, 1.0))


def test_a_wall_between_start_and_goal_is_walked_around_clear_of_it():
    s = RouteSettings(clearance=0.3, cell=0.05, band_cost=math.inf)  # a hard band: no leg may enter it
    m = RouteMap(one(WALL), (0.0, 0.0), (0.0, 4.0), s)
    corners = [np.zeros(2), *m.corners((0.0, 0.0))]
    # around an end of the wall: at least the taut line via the clearance's corner (1.3, 1.9), at most 10 % more
    bound = math.hypot(1.3, 1.9) + math.hypot(1.3, 2.1 - 4.0 + 0.3)
    assert bound * 0.95 <= m.length((0.0, 0.0)) <= bound * 1.1
    assert max(abs(c[0]) for c in corners) >= 1.0 + 0.3 - s.cell  # it passes beyond the wall's end
    for p, q in zip(corners[:-1], corners[1:]):  # every leg keeps the clearance
        assert m.in_sight(p, q)


def test_the_carrot_lies_in_clear_sight_along_the_route_and_the_length_left_is_the_routes():
    m = RouteMap(one(WALL), (0.0, 0.0), (0.0, 4.0), RouteSettings(clearance=0.3, cell=0.05, lookahead=math.inf))
    point, left = m.carrot((0.0, 0.0))
    assert not np.allclose(point, (0.0, 4.0))  # the goal is behind the wall
    assert abs(point[0]) >= 1.0  # toward an end of the wall
    assert m.in_sight((0.0, 0.0), point)
    assert left == pytest.approx(m.length((0.0, 0.0)), abs=0.1)
    near, _ = RouteMap(one(WALL), (0.0, 0.0), (0.0, 4.0), RouteSettings(clearance=0.3, cell=0.05,
                                                                       lookahead=0.5)).carrot((0.0, 0.0))
    assert np.hypot(*near) <= 0.5 + 1e-9


def test_a_walker_inside_the_clearance_band_is_led_out_and_a_hard_band_still_lets_it_start():
    pillar = Scene([Cylinder(center=(0.0, 1.0), radius=0.3, height=1.5)])
    start = (0.45, 1.0)  # 15 cm from the pillar's surface, inside a 0.4 m band
    for band in (10.0, math.inf):
        m = RouteMap(one(pillar), start, (0.0, 4.0), RouteSettings(clearance=0.4, cell=0.05, band_cost=band))
        assert math.isfinite(m.length(start))
        point, _ = m.carrot(start)
        assert np.hypot(point[0], point[1] - 1.0) > 0.3 + 0.15 - 1e-6  # not toward the pillar


def test_a_walled_in_goal_has_no_route_and_the_walker_heads_straight_for_it():
    walls = Scene([Box(center=(0.0, 5.0), size=(3.0, 0.2, 2.0)), Box(center=(0.0, 3.0), size=(3.0, 0.2, 2.0)),
                   Box(center=(-1.4, 4.0), size=(0.2, 2.2, 2.0)), Box(center=(1.4, 4.0), size=(0.2, 2.2, 2.0))])
    m = RouteMap(one(walls), (0.0, 0.0), (0.0, 4.0), RouteSettings(clearance=0.2, cell=0.1))
    assert m.length((0.0, 0.0)) == math.inf and m.corners((0.0, 0.0)) == []
    point, left = m.carrot((0.0, 0.0))
    assert np.allclose(point, (0.0, 4.0)) and left == pytest.approx(4.0)


def test_off_the_grid_a_walker_heads_straight_for_the_goal():
    m = RouteMap(one(WALL), (0.0, 0.0), (0.0, 4.0), RouteSettings(margin=1.0))
    assert m.length((30.0, 0.0)) == math.inf
    point, left = m.carrot((30.0, 0.0))
    assert np.allclose(point, (0.0, 4.0)) and left == pytest.approx(math.hypot(30.0, 4.0))


@pytest.mark.parametrize("field, value", [("clearance", -0.1), ("cell", 0.0), ("margin", 100.0), ("reach", 3.0),
                                          ("band_cost", -1.0), ("lookahead", 0.1)])
def test_settings_out_of_range_fail_with_one_line_naming_the_field(field, value):
    with pytest.raises(ConfigError, match=rf"^route {field}: expected") as err:
        RouteSettings(**{field: value}).check()
    assert "\n" not in str(err.value)
