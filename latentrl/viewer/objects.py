"""A scene's objects in the browser: boxes, cylinders, seats and each step of a staircase as shaded meshes.

Each object is drawn as the primitives its SDF is made of (:meth:`latentrl.scenes.Scene.primitives`), so
what the page shows is exactly what the envs collide with and stand on. The mesh list is plain data
(:func:`object_meshes`, tested without a browser); :class:`SceneObjects` hands it to Viser's box and
cylinder nodes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from latentrl.render import SCENE_COLOURS
from latentrl.scenes.scene import Scene

COLOURS = SCENE_COLOURS
"""Colour of each object type (RGB 0-255), the rendered videos' own: boxes warm grey, pillars blue-grey, seats
green, stairs stone."""
DROPPED = (214, 132, 70)
"""Boxes dropped by hand in ``latentrl play``: orange-brown, to tell them from the scene file's."""


@dataclass(frozen=True)
class ObjectMesh:
    """One mesh of a scene object: a 'box' or a 'cylinder', where it stands, how it is turned and coloured.

    ``size``: a box's (x, y, z) before turning, a cylinder's (radius, radius, height); ``yaw``: radians
    about +z; ``object_index``: the scene object it draws (a staircase has one mesh per step).
    """

    kind: str
    centre: tuple[float, float, float]
    size: tuple[float, float, float]
    yaw: float
    colour: tuple[int, int, int]
    object_index: int


def yaw_wxyz(yaw: float) -> tuple[float, float, float, float]:
    """The wxyz quaternion of a turn by ``yaw`` radians about +z."""
    return (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))


def object_meshes(scene: Scene, dropped: int = 0) -> list[ObjectMesh]:
    """The meshes that draw ``scene``: one per box or cylinder primitive (a staircase gives one per step).

    ``dropped``: the last this many objects were dropped by hand (drawn in :data:`DROPPED`).
    """
    out = []
    first_dropped = len(scene.objects) - int(dropped)
    for i, obj in enumerate(scene.objects):
        colour = DROPPED if i >= first_dropped else COLOURS[type(obj)]
        boxes, cylinders = Scene((obj,), scene.floor_height).primitives()
        for cx, cy, cz, hx, hy, hz, yaw in boxes:
            out.append(ObjectMesh("box", (cx, cy, cz), (2 * hx, 2 * hy, 2 * hz), yaw, colour, i))
        for cx, cy, cz, r, hh in cylinders:
            out.append(ObjectMesh("cylinder", (cx, cy, cz), (r, r, 2 * hh), 0.0, colour, i))
    return out


def scene_points(scene: Scene | None) -> np.ndarray:
    """(K, 3) the corners of every object's footprint (for framing the floor and camera around a scene)."""
    if scene is None:
        return np.zeros((0, 3), dtype=np.float32)
    points = []
    for m in object_meshes(scene):
        c, s = math.cos(m.yaw), math.sin(m.yaw)
        for dx, dy in ((-1, -1), (-1, 1), (1, -1), (1, 1)):
            x, y = dx * m.size[0] / 2, dy * m.size[1] / 2
            points.append((m.centre[0] + c * x - s * y, m.centre[1] + s * x + c * y, 0.0))
    return np.asarray(points, dtype=np.float32).reshape(-1, 3)


class SceneObjects:
    """The Viser nodes of one scene under ``/objects`` (replaced as a whole by :meth:`show`)."""

    def __init__(self, server: Any):
        self.server = server
        self.nodes: list[Any] = []
        self.meshes: list[ObjectMesh] = []

    def show(self, scene: Scene | None, dropped: int = 0) -> None:
        """Draw ``scene``'s objects (None: none), replacing what was drawn."""
        for node in self.nodes:
            node.remove()
        self.nodes, self.meshes = [], object_meshes(scene, dropped) if scene is not None else []
        add = self.server.scene
        for k, m in enumerate(self.meshes):
            name = f"/objects/{m.object_index}_{k}"
            if m.kind == "box":
                node = add.add_box(name, color=m.colour, dimensions=m.size, position=m.centre,
                                   wxyz=yaw_wxyz(m.yaw), flat_shading=True, cast_shadow=True, receive_shadow=True)
            else:
                node = add.add_cylinder(name, radius=m.size[0], height=m.size[2], color=m.colour,
                                        position=m.centre, radial_segments=32, cast_shadow=True,
                                        receive_shadow=True)
            self.nodes.append(node)
