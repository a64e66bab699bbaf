"""The scene file (``latentrl.scene/1``, docs/scenes.md): parse and check it, write it back.

::

    {"format": "latentrl.scene/1", "floor_height": 0.0,
     "objects": [{"type": "box", "center": [1.0, 2.0], "size": [0.6, 0.4, 1.0], "yaw_deg": 30},
                 {"type": "cylinder", "center": [-1.0, 3.0], "radius": 0.25, "height": 1.2},
                 {"type": "seat", "center": [0.0, 4.0], "size": [0.5, 0.5], "seat_height": 0.45, "yaw_deg": -90},
                 {"type": "stairs", "start": [2.0, 0.0], "direction_deg": 90, "width": 1.2,
                  "riser": 0.15, "tread": 0.3, "count": 6}]}

Everything is checked on load: a bad value is one line naming the file, the field (``objects[2].size[1]``)
and what was expected. Sizes are bounded so that a file cannot ask for a scene the envs cannot hold.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from latentrl.errors import DataError, closest
from latentrl.safe_io import read_json_file
from latentrl.scenes.scene import Box, Cylinder, Scene, SceneObject, Seat, Stairs

FORMAT = "latentrl.scene/1"
"""The ``format`` value a scene file carries."""
MAX_OBJECTS = 64
"""Objects in one scene, at most."""
MAX_STEPS = 32
"""Steps of one staircase, at most."""
MAX_COORD_M = 1000.0
"""Positions farther than this from the origin are refused."""
MAX_SIZE_M = 100.0
"""Largest size, radius or height of an object."""
MAX_SCENE_BYTES = 1 << 20
OBJECT_FIELDS: dict[str, dict[str, bool]] = {
    "box": {"type": True, "center": True, "size": True, "yaw_deg": False, "base": False},
    "cylinder": {"type": True, "center": True, "radius": True, "height": True, "base": False},
    "seat": {"type": True, "center": True, "size": True, "seat_height": True, "yaw_deg": False, "base": False},
    "stairs": {"type": True, "start": True, "direction_deg": True, "width": True, "riser": True, "tread": True,
               "count": True, "base": False},
}
"""Object type -> its fields (True: required)."""


class _At:
    """Builds one-line errors naming the source and the field."""

    def __init__(self, source: str):
        self.source = source

    def error(self, fld: str, what: str) -> DataError:
        return DataError(f"{self.source}: {fld}: {what}")

    def number(self, value: Any, fld: str, low: float = -MAX_COORD_M, high: float = MAX_COORD_M,
               positive: bool = False) -> float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(fld, f"expected a number, got {value!r:.40}")
        if not math.isfinite(value):
            raise self.error(fld, f"expected a finite number, got {value}")
        if positive and value <= 0:
            raise self.error(fld, f"expected a number > 0, got {value}")
        if not low <= value <= high:
            raise self.error(fld, f"expected a number in [{low:g}, {high:g}], got {value}")
        return float(value)

    def size(self, value: Any, fld: str, high: float = MAX_SIZE_M) -> float:
        return self.number(value, fld, 0.0, high, positive=True)

    def vector(self, value: Any, fld: str, n: int, sizes: bool = False) -> tuple[float, ...]:
        if not isinstance(value, (list, tuple)) or len(value) != n:
            what = "[x, y]" if n == 2 else "[x, y, z]"
            raise self.error(fld, f"expected {what} ({'sizes > 0' if sizes else 'metres'}), got {str(value)[:40]}")
        check = self.size if sizes else self.number
        return tuple(check(v, f"{fld}[{i}]") for i, v in enumerate(value))


def _object(raw: Any, at: _At, fld: str) -> SceneObject:
    if not isinstance(raw, dict):
        raise at.error(fld, f"expected an object, got {str(raw)[:40]}")
    kind = raw.get("type")
    if kind not in OBJECT_FIELDS:
        hint = closest(kind, tuple(OBJECT_FIELDS)) if isinstance(kind, str) else ""
        raise at.error(f"{fld}.type", f"expected one of {', '.join(OBJECT_FIELDS)}, got {kind!r:.30}{hint}")
    fields = OBJECT_FIELDS[kind]
    for name in raw:
        if name not in fields:
            raise at.error(f"{fld}.{name}", f"unknown field for a {kind}{closest(str(name), tuple(fields))}; "
                                            f"expected {', '.join(fields)}")
    for name, required in fields.items():
        if required and name not in raw:
            raise at.error(f"{fld}.{name}", f"missing; a {kind} needs {', '.join(k for k, r in fields.items() if r)}")
    base = None if raw.get("base") is None else at.number(raw["base"], f"{fld}.base")
    yaw = at.number(raw.get("yaw_deg", 0.0), f"{fld}.yaw_deg", -360.0, 360.0)
    if kind == "box":
        return Box(at.vector(raw["center"], f"{fld}.center", 2), at.vector(raw["size"], f"{fld}.size", 3, True),
                   yaw, base)
    if kind == "cylinder":
        return Cylinder(at.vector(raw["center"], f"{fld}.center", 2), at.size(raw["radius"], f"{fld}.radius"),
                        at.size(raw["height"], f"{fld}.height"), base)
    if kind == "seat":
        return Seat(at.vector(raw["center"], f"{fld}.center", 2), at.vector(raw["size"], f"{fld}.size", 2, True),
                    at.size(raw["seat_height"], f"{fld}.seat_height", 3.0), yaw, base)
    count = raw["count"]
    if isinstance(count, bool) or not isinstance(count, int) or not 1 <= count <= MAX_STEPS:
        raise at.error(f"{fld}.count", f"expected an integer in [1, {MAX_STEPS}], got {count!r:.30}")
    return Stairs(at.vector(raw["start"], f"{fld}.start", 2),
                  at.number(raw["direction_deg"], f"{fld}.direction_deg", -360.0, 360.0),
                  at.size(raw["width"], f"{fld}.width"), at.size(raw["riser"], f"{fld}.riser", 1.0),
                  at.size(raw["tread"], f"{fld}.tread", 5.0), count, base)


def parse_scene(raw: Any, source: str = "<scene>") -> Scene:
    """A :class:`Scene` from decoded JSON, checked (one-line :class:`~latentrl.errors.DataError` naming the field)."""
    at = _At(source)
    if not isinstance(raw, dict):
        raise at.error("scene", "expected a JSON object with 'format' and 'objects'")
    if raw.get("format") != FORMAT:
        raise at.error("format", f"expected {FORMAT!r}, got {raw.get('format')!r:.40}")
    for name in raw:
        if name not in ("format", "objects", "floor_height", "description"):
            raise at.error(str(name), "unknown field; expected format, objects, floor_height, description")
    if not isinstance(raw.get("description", ""), str):
        raise at.error("description", "expected a string")
    floor = at.number(raw.get("floor_height", 0.0), "floor_height", -MAX_SIZE_M, MAX_SIZE_M)
    objects = raw.get("objects")
    if not isinstance(objects, list):
        raise at.error("objects", f"expected a list of objects, got {str(objects)[:40]}")
    if len(objects) > MAX_OBJECTS:
        raise at.error("objects", f"{len(objects)} objects, more than the {MAX_OBJECTS} allowed")
    return Scene(tuple(_object(o, at, f"objects[{i}]") for i, o in enumerate(objects)), floor)


def load_scene(path: str | Path) -> Scene:
    """Read and check a ``latentrl.scene/1`` file."""
    raw = read_json_file(path, "scene file", MAX_SCENE_BYTES, DataError)
    return parse_scene(raw, str(path))


def scene_to_dict(scene: Scene) -> dict[str, Any]:
    """The JSON form of ``scene`` (what :func:`parse_scene` reads back to an equal scene)."""
    out = []
    for obj in scene.objects:
        if isinstance(obj, Box):
            d = {"type": "box", "center": list(obj.center), "size": list(obj.size), "yaw_deg": obj.yaw_deg}
        elif isinstance(obj, Cylinder):
            d = {"type": "cylinder", "center": list(obj.center), "radius": obj.radius, "height": obj.height}
        elif isinstance(obj, Seat):
            d = {"type": "seat", "center": list(obj.center), "size": list(obj.size), "seat_height": obj.seat_height,
                 "yaw_deg": obj.yaw_deg}
        else:
            d = {"type": "stairs", "start": list(obj.start), "direction_deg": obj.direction_deg, "width": obj.width,
                 "riser": obj.riser, "tread": obj.tread, "count": obj.count}
        if obj.base is not None:
            d["base"] = obj.base
        out.append(d)
    return {"format": FORMAT, "floor_height": scene.floor_height, "objects": out}


def scene_to_json(scene: Scene) -> str:
    """``scene`` as one line of JSON text."""
    import json

    return json.dumps(scene_to_dict(scene), separators=(",", ":"))


def scene_from_json(text: str, source: str = "<scene>") -> Scene:
    """:func:`parse_scene` of JSON text (one-line error on invalid JSON)."""
    import json

    try:
        raw = json.loads(text)
    except (json.JSONDecodeError, RecursionError, ValueError) as exc:
        raise DataError(f"{source}: invalid JSON: {str(exc)[:120]}") from None
    return parse_scene(raw, source)
