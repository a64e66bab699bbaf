"""The character's body in the browser: a capsule per bone (a tube and two round ends), shaded and lit.

Why batched meshes: the whole body is two Viser nodes (21 tubes, 22 joint spheres), so a frame is a few
array assignments however many bones move. A capsule of any length cannot be one scaled mesh (its round
ends would stretch), so each bone is a unit tube scaled to the bone's radius and length, and each joint a
unit sphere scaled to the largest radius of the bones that meet there: together they are the capsules
:mod:`latentrl.render` draws, with its radii and colours.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from latentrl.constants import CONTACT_HEIGHT_M
from latentrl.motion.skeleton import FOOT_JOINTS, HEAD, JOINT_NAMES, PARENTS
from latentrl.render import BONE_RADIUS, CENTRE, CONTACT, HEAD_RADIUS, side_colour

BONES = np.array([(PARENTS[j], j) for j in range(len(PARENTS)) if PARENTS[j] >= 0], dtype=np.int64)
"""(21, 2) parent, child joint index of every bone (the order of the tubes)."""


def _radius_of(child: int) -> float:
    return BONE_RADIUS[JOINT_NAMES[child].removeprefix("left_").removeprefix("right_")]


BONE_RADII = np.array([_radius_of(c) for _, c in BONES], dtype=np.float32)
"""(21,) tube radius of each bone, metres (the renderer's :data:`~latentrl.render.BONE_RADIUS`)."""


def _joint_radii() -> np.ndarray:
    radii = np.zeros(len(JOINT_NAMES), dtype=np.float32)
    for (a, c), r in zip(BONES, BONE_RADII):
        radii[a] = max(radii[a], r)
        radii[c] = max(radii[c], r)
    radii[HEAD] = HEAD_RADIUS
    return radii


JOINT_RADII = _joint_radii()
"""(22,) sphere radius at each joint: the largest radius of its bones; the head is a ball of HEAD_RADIUS."""


def unit_tube(segments: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """An open tube of radius 1 along z from -0.5 to 0.5: (2S, 3) vertices, (2S, 3) faces facing out."""
    angles = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack((np.cos(angles), np.sin(angles)), axis=1)
    vertices = np.concatenate((np.c_[ring, np.full(segments, -0.5)], np.c_[ring, np.full(segments, 0.5)]))
    i = np.arange(segments)
    j = (i + 1) % segments
    faces = np.concatenate((np.stack((i, j, j + segments), 1), np.stack((i, j + segments, i + segments), 1)))
    return vertices.astype(np.float32), faces.astype(np.uint32)


def unit_sphere(rings: int = 8, segments: int = 16) -> tuple[np.ndarray, np.ndarray]:
    """A sphere of radius 1 (latitude-longitude): vertices and outward-facing triangles."""
    theta = np.linspace(0.0, np.pi, rings + 1)[1:-1]
    phi = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    body = np.stack((np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)), axis=-1).reshape(-1, 3)
    vertices = np.concatenate(([[0.0, 0.0, 1.0]], body, [[0.0, 0.0, -1.0]]))
    top, bottom = 0, len(vertices) - 1
    faces = []
    for s in range(segments):
        n = (s + 1) % segments
        faces.append((top, 1 + s, 1 + n))
        last = 1 + (rings - 2) * segments
        faces.append((bottom, last + n, last + s))
        for r in range(rings - 2):
            a, b = 1 + r * segments, 1 + (r + 1) * segments
            faces.append((a + s, b + s, b + n))
            faces.append((a + s, b + n, a + n))
    return vertices.astype(np.float32), np.array(faces, dtype=np.uint32)


def z_to(directions: np.ndarray) -> np.ndarray:
    """(N, 4) wxyz quaternions turning +z onto each of (N, 3) directions (a zero direction: no turn).

    The half-way construction ``(1 + d_z, -d_y, d_x, 0)`` normalised; straight down (d_z = -1) is a half
    turn about x.
    """
    d = np.asarray(directions, dtype=np.float64)
    length = np.linalg.norm(d, axis=-1, keepdims=True)
    d = np.where(length > 1e-9, d / np.maximum(length, 1e-12), (0.0, 0.0, 1.0))
    q = np.stack((1.0 + d[:, 2], -d[:, 1], d[:, 0], np.zeros(len(d))), axis=1)
    down = q[:, 0] < 1e-9
    q[down] = (0.0, 1.0, 0.0, 0.0)
    return (q / np.linalg.norm(q, axis=1, keepdims=True)).astype(np.float32)


def bone_transforms(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(22, 3) joints -> each bone tube's (21, 3) centre, (21, 4) wxyz and (21, 3) scale (r, r, length)."""
    joints = np.asarray(joints, dtype=np.float32)
    a, c = joints[BONES[:, 0]], joints[BONES[:, 1]]
    length = np.linalg.norm(c - a, axis=1)
    scales = np.stack((BONE_RADII, BONE_RADII, length), axis=1)
    return (a + c) / 2, z_to(c - a), scales.astype(np.float32)


def foot_contact(joints: np.ndarray, ground: np.ndarray | float = 0.0) -> np.ndarray:
    """(2,) how much each foot (left, right) touches the ground under it, DART's ``2 - 2^clamp(h / 3 cm, 0, 1)``."""
    heights = np.asarray(joints, dtype=np.float32)[list(FOOT_JOINTS), 2] - np.asarray(ground, dtype=np.float32)
    return 2.0 - np.power(2.0, np.clip(heights / CONTACT_HEIGHT_M, 0.0, 1.0))


SIDE_COLOURS = np.array([side_colour(j) for j in range(len(JOINT_NAMES))], dtype=np.float32)


def body_colours(joints: np.ndarray, ground: np.ndarray | float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(21, 3) tube and (22, 3) sphere colours, uint8: as the renderer's body.

    A bone has its child's side colour (left blue, right orange, spine and head grey); the foot bones and the
    foot spheres turn green with their contact.
    """
    bones = SIDE_COLOURS[BONES[:, 1]].copy()
    spheres = SIDE_COLOURS.copy()
    spheres[0] = CENTRE
    for side, w in enumerate(foot_contact(joints, ground)):
        foot = FOOT_JOINTS[side]
        mixed = (1 - w) * SIDE_COLOURS[foot] + w * np.asarray(CONTACT, dtype=np.float32)
        bones[BONES[:, 1] == foot] = mixed
        spheres[foot] = mixed
    return bones.round().astype(np.uint8), spheres.round().astype(np.uint8)


class CapsuleBody:
    """Two batched-mesh nodes under ``/character``: bone tubes and joint spheres; :meth:`show` poses them.

    Args:
        server: a ``viser.ViserServer``.
        name: the scene path of the body.
    """

    OPAQUE, SEE_THROUGH = None, 0.45
    """Opacity alone, and while the skeleton is drawn inside it."""

    def __init__(self, server: Any, name: str = "/character"):
        scene = server.scene
        zeros = np.zeros((len(JOINT_NAMES), 3), dtype=np.float32)
        self.root = scene.add_frame(name, show_axes=False)
        centres, wxyzs, scales = bone_transforms(zeros)
        bone_colours, sphere_colours = body_colours(zeros)
        tube_v, tube_f = unit_tube()
        ball_v, ball_f = unit_sphere()
        self.tubes = scene.add_batched_meshes_simple(
            f"{name}/bones", tube_v, tube_f, wxyzs, centres, batched_scales=scales, batched_colors=bone_colours,
            lod="off", material="standard", cast_shadow=True, receive_shadow=False)
        self.spheres = scene.add_batched_meshes_simple(
            f"{name}/joints", ball_v, ball_f, np.tile((1.0, 0.0, 0.0, 0.0), (len(zeros), 1)), zeros,
            batched_scales=JOINT_RADII, batched_colors=sphere_colours, lod="off", material="standard",
            cast_shadow=True, receive_shadow=False)
        self._colours = (bone_colours, sphere_colours)

    def show(self, joints: np.ndarray, ground: np.ndarray | float = 0.0) -> None:
        """Pose the body on one frame's (22, 3) joints; ``ground``: the terrain z under each foot (or one z)."""
        joints = np.asarray(joints, dtype=np.float32)
        centres, wxyzs, scales = bone_transforms(joints)
        self.tubes.batched_positions = centres
        self.tubes.batched_wxyzs = wxyzs
        self.tubes.batched_scales = scales
        self.spheres.batched_positions = joints
        bones, spheres = body_colours(joints, ground)
        if not np.array_equal(bones, self._colours[0]):  # only the feet change colour: send them when they do
            self.tubes.batched_colors = bones
            self.spheres.batched_colors = spheres
            self._colours = (bones, spheres)

    @property
    def visible(self) -> bool:
        """Whether the body is drawn."""
        return bool(self.root.visible)

    @visible.setter
    def visible(self, value: bool) -> None:
        self.root.visible = bool(value)

    def see_through(self, on: bool) -> None:
        """Draw the body half transparent (``on``: a skeleton drawn inside it shows) or opaque."""
        opacity = self.SEE_THROUGH if on else self.OPAQUE
        self.tubes.opacity = opacity
        self.spheres.opacity = opacity
