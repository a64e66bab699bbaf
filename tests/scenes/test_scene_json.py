"""The scene file: a round trip, and one line naming the field for each kind of bad input."""

import json

import pytest

from latentrl.errors import DataError
from latentrl.scenes import (
    Box,
    Cylinder,
    Scene,
    Seat,
    Stairs,
    load_scene,
    parse_scene,
    scene_from_json,
    scene_to_dict,
    scene_to_json,
)

SCENE = Scene((Box((1.0, 2.0), (0.6, 0.4, 1.0), 30.0), Cylinder((-1.0, 3.0), 0.25, 1.2, base=0.1),
               Seat((0.0, 4.0), (0.5, 0.5), 0.45, -90.0), Stairs((2.0, 0.0), 90.0, 1.2, 0.15, 0.3, 6)), 0.05)


def good() -> dict:
    return scene_to_dict(SCENE)


def test_round_trip_through_dict_text_and_file(tmp_path):
    assert parse_scene(scene_to_dict(SCENE)) == SCENE
    assert scene_from_json(scene_to_json(SCENE)) == SCENE
    path = tmp_path / "s.json"
    path.write_text(json.dumps(good()))
    assert load_scene(path) == SCENE
    assert "\n" not in scene_to_json(SCENE)


def test_defaults_and_an_empty_scene():
    s = parse_scene({"format": "latentrl.scene/1", "objects": [{"type": "box", "center": [0, 0], "size": [1, 1, 1]}]})
    assert s == Scene((Box((0.0, 0.0), (1.0, 1.0, 1.0)),), 0.0)
    assert parse_scene({"format": "latentrl.scene/1", "objects": []}) == Scene()


def edit(path: str, value):
    raw = good()
    node, *keys = [raw, *path.split(".")]
    for k in keys[:-1]:
        node = node[int(k)] if isinstance(node, list) else node[k]
    last = keys[-1]
    if value is KeyError:
        del node[last]
    elif isinstance(node, list):
        node[int(last)] = value
    else:
        node[last] = value
    return raw


BAD = [
    (edit("format", "latentrl.scene/2"), "s.json: format: expected 'latentrl.scene/1', got 'latentrl.scene/2'"),
    (edit("colour", 1), "s.json: colour: unknown field; expected format, objects, floor_height, description"),
    (edit("floor_height", float("nan")), "s.json: floor_height: expected a finite number, got nan"),
    (edit("objects", {}), "s.json: objects: expected a list of objects, got {}"),
    (edit("objects.0.type", "crate"), "s.json: objects[0].type: expected one of box, cylinder, seat, stairs, "
                                      "got 'crate'"),
    (edit("objects.0.size", [1, 2]), "s.json: objects[0].size: expected [x, y, z] (sizes > 0), got [1, 2]"),
    (edit("objects.0.size.1", -0.4), "s.json: objects[0].size[1]: expected a number > 0, got -0.4"),
    (edit("objects.0.size.1", 0), "s.json: objects[0].size[1]: expected a number > 0, got 0"),
    (edit("objects.0.size.2", 1e6), "s.json: objects[0].size[2]: expected a number in [0, 100], got 1000000.0"),
    (edit("objects.0.center.0", "1"), "s.json: objects[0].center[0]: expected a number, got '1'"),
    (edit("objects.0.center.0", True), "s.json: objects[0].center[0]: expected a number, got True"),
    (edit("objects.0.center.1", 5000), "s.json: objects[0].center[1]: expected a number in [-1000, 1000], got 5000"),
    (edit("objects.0.yaw", 3), "s.json: objects[0].yaw: unknown field for a box (did you mean 'yaw_deg'?); "
                               "expected type, center, size, yaw_deg, base"),
    (edit("objects.1.radius", KeyError), "s.json: objects[1].radius: missing; a cylinder needs type, center, "
                                         "radius, height"),
    (edit("objects.1.height", float("inf")), "s.json: objects[1].height: expected a finite number, got inf"),
    (edit("objects.2.seat_height", 4), "s.json: objects[2].seat_height: expected a number in [0, 3], got 4"),
    (edit("objects.3.count", 0), "s.json: objects[3].count: expected an integer in [1, 32], got 0"),
    (edit("objects.3.count", 2.5), "s.json: objects[3].count: expected an integer in [1, 32], got 2.5"),
    (edit("objects.3.riser", 2), "s.json: objects[3].riser: expected a number in [0, 1], got 2"),
    (edit("objects.3.direction_deg", None), "s.json: objects[3].direction_deg: expected a number, got None"),
    (edit("objects.3", [1]), "s.json: objects[3]: expected an object, got [1]"),
    (edit("description", 3), "s.json: description: expected a string"),
    ([1, 2], "s.json: scene: expected a JSON object with 'format' and 'objects'"),
]


@pytest.mark.parametrize(("raw", "message"), BAD, ids=[m.split(": ")[1] for _, m in BAD])
def test_bad_input_is_one_line_naming_the_field(raw, message):
    with pytest.raises(DataError) as info:
        parse_scene(raw, "s.json")
    assert str(info.value) == message
    assert info.value.exit_code == 2


def test_too_many_objects():
    raw = {"format": "latentrl.scene/1", "objects": [{"type": "box", "center": [0, 0], "size": [1, 1, 1]}] * 65}
    with pytest.raises(DataError, match=r"^s.json: objects: 65 objects, more than the 64 allowed$"):
        parse_scene(raw, "s.json")


def test_bad_files(tmp_path):
    with pytest.raises(DataError, match="scene file not found"):
        load_scene(tmp_path / "none.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{")
    with pytest.raises(DataError, match=r"bad.json: invalid JSON: .*line 1"):
        load_scene(bad)
    with pytest.raises(DataError, match=r"^<scene>: invalid JSON"):
        scene_from_json("[")


def test_the_shipped_scene_loads_by_name():
    from latentrl.envs.scene import resolve_scene

    scene = resolve_scene("obstacle_course")
    assert len(scene.objects) == 5 and {type(o).__name__ for o in scene.objects} == {"Box", "Cylinder", "Seat",
                                                                                      "Stairs"}
