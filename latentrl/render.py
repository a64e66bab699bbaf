"""Motion files and pictures: the shared ``.npz`` motion format, GIF/MP4 animations and BVH export.

Animations (:func:`render_video`, :func:`render_clip`): Pillow draws a 2-D projection per frame (a body of
capsules on a shaded floor, or a skeleton) in the viewer's colours, with the motion's scene (boxes, pillars,
seats, stairs) and its goal markers; GIF through Pillow, MP4 through imageio-ffmpeg, an in-memory GIF for
TensorBoard (:func:`gif_bytes`).

BVH (:func:`save_bvh`, :func:`load_bvh`): the SMPL-22 skeleton, Y-up, centimetres, 6 channels per joint
so that the file reproduces the generated joint positions exactly (docs/evaluation.md, section 6).

Motion ``.npz``: :class:`latentrl.motion.clip.MotionClip` holds the shared format and its schema;
:func:`save_motion_npz` and :func:`load_motion_npz` are re-exported from there.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np

from latentrl.constants import CONTACT_HEIGHT_M
from latentrl.errors import DataError
from latentrl.motion.clip import (  # noqa: F401  (the old address)
    MAX_COORD_M,
    MAX_FPS,
    MotionClip,
    check_motion,
    load_motion_npz,
    save_motion_npz,
)
from latentrl.motion.skeleton import (
    FOOT_JOINTS,
    FPS,
    HEAD,
    JOINT_NAMES,
    NUM_JOINTS,
    PARENTS,
    SMPL_REST_OFFSETS,
    rest_offsets,
)
from latentrl.safe_io import atomic_write_bytes, atomic_write_with
from latentrl.scenes.scene import Box, Cylinder, Scene, SceneBatch, Seat, Stairs

# --------------------------------------------------------------------------- pictures
# Colours shared with the browser viewer (its scene module imports them from here), RGB 0-255.
LEFT, RIGHT, CENTRE = (60, 120, 220), (225, 105, 60), (90, 90, 100)
"""The body's sides: left blue, right orange, spine and head grey (the side of a bone's child joint)."""
CONTACT, AIRBORNE = (40, 190, 80), (150, 150, 150)
GOAL, WAYPOINT, TRAIL = (220, 40, 60), (250, 180, 40), (70, 70, 200)
SKY, FLOOR_LIGHT, FLOOR_DARK, SHADOW = (222, 228, 236), (200, 200, 196), (176, 176, 172), (140, 140, 138)
GOAL_JOINT_COLOURS = {"pelvis": (0, 0, 0), "left_foot": (31, 119, 180), "right_foot": (255, 127, 14),
                      "left_hand": (148, 103, 189), "right_hand": (140, 86, 75), "head": (127, 127, 127)}
"""Joint-goal targets by goal joint (a ReachJoint evaluation's paths.png and the viewer's markers): matplotlib's
black and tab: colours."""
SCENE_COLOURS = {Box: (168, 152, 136), Cylinder: (150, 162, 178), Seat: (118, 152, 110), Stairs: (186, 180, 168)}
"""Colour of each scene object type (the viewer's): boxes warm grey, pillars blue-grey, seats green, stairs stone."""
FACE_SHADES = (1.12, 0.86, 0.7)
"""Brightness of an object's faces: tops, sides facing the light (+x, -y: the camera's side), the others."""

RENDER_SIZE = 480
"""Width and height of rendered frames in pixels (a multiple of 16, as H.264 wants)."""
GIF_STRIDE = 3
"""GIFs keep every 3rd frame (10 frames/s: GIF frame times are whole centiseconds, so 15 frames/s would
play ~10% fast); MP4 keeps every frame."""
VIDEO_FORMATS = (".gif", ".mp4")
STYLES = ("body", "skeleton")
"""``body``: a capsule per bone and a head; ``skeleton``: thin bones and joint dots."""

CAMERA_DISTANCE = 2.6
"""Metres from the camera to the point it looks at (the smoothed pelvis, :data:`LOOK_HEIGHT` above the floor)."""
CAMERA_ELEVATION = 20.0
"""Degrees above the horizon; the camera sits on the -y side (behind a body that starts facing +y, as in the viewer)."""
LOOK_HEIGHT = 0.85
FOCAL = 1.3
"""Focal length in half image widths (a 75 degree field of view)."""
NEAR = 0.05
GOAL_RADIUS = 0.3
BONE_RADIUS = {"hip": 0.085, "knee": 0.075, "ankle": 0.055, "foot": 0.04, "spine1": 0.11, "spine2": 0.11,
               "spine3": 0.105, "neck": 0.06, "head": 0.05, "collar": 0.06, "shoulder": 0.055, "elbow": 0.05,
               "wrist": 0.04}
"""Capsule radius (m) of the bone that ends at each joint (side prefix dropped): pelvis->hip is "hip"."""
HEAD_RADIUS = 0.1


def _bone_radius(child: int) -> float:
    return BONE_RADIUS[JOINT_NAMES[child].removeprefix("left_").removeprefix("right_")]


def side_colour(joint: int) -> tuple[int, int, int]:
    """The colour of a joint's side of the body: left, right or centre."""
    name = JOINT_NAMES[joint]
    return LEFT if name.startswith("left") else RIGHT if name.startswith("right") else CENTRE


def _scaled(colour: Sequence[float], k: float) -> tuple[int, int, int]:
    return tuple(int(min(255, max(0, round(c * k)))) for c in colour)


def _mix(a: Sequence[float], b: Sequence[float], w: float) -> tuple[int, int, int]:
    return tuple(int(round((1 - w) * x + w * y)) for x, y in zip(a, b))


class Camera:
    """A pinhole camera at a fixed angle that looks at ``target`` from :data:`CAMERA_DISTANCE` behind and above.

    Plain numpy, so tests can check where a known point lands: ``target`` itself projects to the
    image centre.
    """

    def __init__(self, target: Sequence[float], size: int = RENDER_SIZE):
        e = np.radians(CAMERA_ELEVATION)
        self.forward = np.array([0.0, np.cos(e), -np.sin(e)])
        self.right = np.array([1.0, 0.0, 0.0])
        self.up = np.array([0.0, np.sin(e), np.cos(e)])
        self.position = np.asarray(target, dtype=np.float64) - CAMERA_DISTANCE * self.forward
        self.size = size
        self.focal = FOCAL * size / 2

    def project(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World points (..., 3) -> pixel coordinates (..., 2) (x right, y down) and depth (...) in metres."""
        v = np.asarray(points, dtype=np.float64) - self.position
        depth = v @ self.forward
        safe = np.where(depth > NEAR, depth, NEAR)
        x = self.size / 2 + self.focal * (v @ self.right) / safe
        y = self.size / 2 - self.focal * (v @ self.up) / safe
        return np.stack((x, y), axis=-1), depth


def follow_targets(joints: np.ndarray, window: int = 15, ground: np.ndarray | None = None) -> np.ndarray:
    """(T, 3) points the camera looks at: the pelvis xy averaged over ``window`` frames, :data:`LOOK_HEIGHT` up.

    The average keeps the picture from swaying with every step. ``ground`` (T,): the terrain height under
    the pelvis (stairs, a platform), averaged the same way and added to the height, so a climb stays in view.
    """
    xy = np.asarray(joints, dtype=np.float64)[:, 0, :2]
    z = np.zeros(len(xy)) if ground is None else np.asarray(ground, dtype=np.float64).reshape(len(xy))
    track = np.concatenate((xy, z[:, None]), axis=1)
    half = max(0, int(window) // 2)
    padded = np.concatenate((np.repeat(track[:1], half, 0), track, np.repeat(track[-1:], half, 0)))
    sums = np.concatenate((np.zeros((1, 3)), np.cumsum(padded, axis=0)))
    smooth = (sums[2 * half + 1 :] - sums[: -2 * half - 1]) / (2 * half + 1)
    smooth[:, 2] += LOOK_HEIGHT
    return smooth


MARKER_RADIUS = 0.07
"""Radius (m) of the ball that marks a raised target (a joint goal above the terrain)."""
RAISED_M = 0.05
"""A target more than this above the terrain under it is a ball on a stalk; lower ones are rings on the terrain."""
NOW_RADIUS = 0.16
"""Radius (m) of the ring of the goal in force at the frame (inside a waypoint's :data:`GOAL_RADIUS` ring)."""
_CORNERS = np.array([[-1, -1, -1], [1, -1, -1], [1, 1, -1], [-1, 1, -1], [-1, -1, 1], [1, -1, 1], [1, 1, 1],
                     [-1, 1, 1]], dtype=np.float64)
_FACES = (((0, 3, 2, 1), (0.0, 0.0, -1.0)), ((4, 5, 6, 7), (0.0, 0.0, 1.0)), ((0, 1, 5, 4), (0.0, -1.0, 0.0)),
          ((1, 2, 6, 5), (1.0, 0.0, 0.0)), ((2, 3, 7, 6), (0.0, 1.0, 0.0)), ((3, 0, 4, 7), (-1.0, 0.0, 0.0)))
"""A box's faces: corner indices (of :data:`_CORNERS`) and the outward normal before turning."""
_LIGHT = np.array([0.6, -0.8, 0.0])
"""Horizontal direction towards the light: side faces turned towards it take the brighter side shade."""
_RING = np.linspace(0, 2 * np.pi, 25)[:-1]


class Solid(NamedTuple):
    """One drawable primitive of a scene object: an upright box or a vertical cylinder, world metres."""

    kind: str
    """``box`` or ``cylinder``."""
    centre: np.ndarray
    """(3,) centre."""
    half: np.ndarray
    """(3,) half sizes before turning (a cylinder: radius, radius, half height)."""
    yaw: float
    """Radians about +z (boxes)."""
    colour: tuple[int, int, int]


class Marker(NamedTuple):
    """A target drawn in the frame: a ring on the terrain or, when raised above it, a ball on a stalk."""

    point: np.ndarray
    """(3,) the target; a ring's z is the terrain height under it."""
    ground: float
    """Terrain height under the target (the stalk's foot)."""
    colour: tuple[int, int, int]
    radius: float
    """Ring radius, metres (balls: :data:`MARKER_RADIUS`)."""
    raised: bool


def as_scene(scene: Scene | str | None) -> Scene | None:
    """A :class:`~latentrl.scenes.Scene` from a scene or its ``latentrl.scene/1`` JSON text (a clip's ``scene``)."""
    if scene is None or isinstance(scene, Scene):
        return scene
    from latentrl.scenes.spec import scene_from_json

    return scene_from_json(str(scene), "motion scene")


def scene_solids(scene: Scene | None) -> list[Solid]:
    """The boxes and cylinders that draw ``scene`` (a staircase gives one box per step), in its types' colours."""
    out: list[Solid] = []
    for obj in (scene.objects if scene is not None else ()):
        boxes, cylinders = Scene((obj,), scene.floor_height).primitives()
        colour = SCENE_COLOURS[type(obj)]
        out.extend(Solid("box", np.array(b[:3]), np.array(b[3:6]), float(b[6]), colour) for b in boxes)
        out.extend(Solid("cylinder", np.array(c[:3]), np.array((c[3], c[3], c[4])), 0.0, colour) for c in cylinders)
    return out


def terrain_heights(scene: Scene | None, xy: np.ndarray, batch: SceneBatch | None = None) -> np.ndarray:
    """(...) terrain z under (..., 2) points: the floor, or the top of the highest object over it.

    ``batch``: the scene as a one-row float64 :class:`SceneBatch`, when the caller keeps one for many queries.
    """
    xy = np.asarray(xy, dtype=np.float64)
    if scene is None:
        return np.zeros(xy.shape[:-1])
    if not scene.objects:
        return np.full(xy.shape[:-1], scene.floor_height)
    import torch

    batch = batch if batch is not None else SceneBatch.from_scenes([scene], dtype=torch.float64)
    flat = torch.as_tensor(xy.reshape(1, -1, 2))
    return batch.height(flat).reshape(xy.shape[:-1]).numpy()


def markers(points: np.ndarray | None, colour: tuple[int, int, int], scene: Scene | None,
            radius: float = GOAL_RADIUS) -> list[Marker]:
    """Markers for targets (W, 2 or 3) (z defaults to the terrain): rings on the terrain, balls where raised."""
    if points is None or not len(points):
        return []
    pts = np.asarray(points, dtype=np.float64).reshape(len(points), -1)
    ground = terrain_heights(scene, pts[:, :2])
    out = []
    for p, g in zip(pts, ground):
        z = p[2] if len(p) > 2 else g
        raised = z > g + RAISED_M
        out.append(Marker(np.array((p[0], p[1], z if raised else g)), float(g), colour,
                          MARKER_RADIUS if raised else radius, bool(raised)))
    return out


def _closest_point(solid: Solid, p: np.ndarray) -> np.ndarray:
    """The point of ``solid`` nearest to ``p`` (``p`` itself when inside)."""
    d = p - solid.centre
    if solid.kind == "cylinder":
        r = np.hypot(d[0], d[1])
        k = min(1.0, solid.half[0] / r) if r > 0 else 0.0
        return solid.centre + np.array((d[0] * k, d[1] * k, np.clip(d[2], -solid.half[2], solid.half[2])))
    c, s = np.cos(solid.yaw), np.sin(solid.yaw)
    local = np.clip(np.array((c * d[0] + s * d[1], -s * d[0] + c * d[1], d[2])), -solid.half, solid.half)
    return solid.centre + np.array((c * local[0] - s * local[1], s * local[0] + c * local[1], local[2]))


def _under(solid: Solid, point: np.ndarray) -> bool:
    """Whether ``point`` lies on the top face of ``solid`` (its footprint holds it, at its top's height)."""
    d = point - solid.centre
    if abs(d[2] - solid.half[2]) > 1e-4:
        return False
    if solid.kind == "cylinder":
        return bool(np.hypot(d[0], d[1]) <= solid.half[0])
    c, s = np.cos(solid.yaw), np.sin(solid.yaw)
    return bool(abs(c * d[0] + s * d[1]) <= solid.half[0] and abs(-s * d[0] + c * d[1]) <= solid.half[1])


def _clip_near(cam: Camera, points: np.ndarray) -> np.ndarray:
    """The part of a convex polygon (K, 3) in front of the camera's near plane (Sutherland-Hodgman, one plane)."""
    depth = (points - cam.position) @ cam.forward - NEAR
    if (depth > 0).all():
        return points
    out = []
    for i in range(len(points)):
        a, b, da, db = points[i - 1], points[i], depth[i - 1], depth[i]
        if (da > 0) != (db > 0):
            out.append(a + (b - a) * (da / (da - db)))
        if db > 0:
            out.append(b)
    return np.asarray(out).reshape(-1, 3)


def _hull(points: np.ndarray) -> np.ndarray:
    """Convex hull (monotone chain) of 2-D points (K, 2), in order around it."""
    pts = sorted(map(tuple, np.asarray(points)))

    def half(seq):
        chain: list = []
        for q in seq:
            while len(chain) >= 2 and ((chain[-1][0] - chain[-2][0]) * (q[1] - chain[-2][1])
                                       - (chain[-1][1] - chain[-2][1]) * (q[0] - chain[-2][0])) <= 0:
                chain.pop()
            chain.append(q)
        return chain[:-1]

    return np.array(half(pts) + half(pts[::-1]))


class FrameRenderer:
    """Draws one frame of a motion with Pillow: sky, shaded floor tiles, pelvis track, goals, shadow, scene and body.

    Why Pillow: a 2-D projection drawn with a few hundred polygons costs a few milliseconds per frame,
    where a matplotlib 3-D figure costs tens.

    Args:
        size: width and height in pixels.
        style: ``body`` (capsules, a head, a shadow) or ``skeleton`` (thin bones and joint dots).
        title: text above the picture.
        scene: the scene the motion moves in (a :class:`~latentrl.scenes.Scene` or its JSON text), or None.
    """

    def __init__(self, size: int = RENDER_SIZE, style: str = "body", title: str = "",
                 scene: Scene | str | None = None):
        from PIL import Image, ImageDraw, ImageFont

        if style not in STYLES:
            raise DataError(f"render style must be one of {', '.join(STYLES)}, got '{style}'")
        self.size, self.style, self.title = int(size), style, title
        self._image, self._draw = Image, ImageDraw
        self.font = ImageFont.load_default(size=max(10, self.size // 36))
        self.small = ImageFont.load_default(size=max(9, self.size // 44))
        self.background = self._backdrop()
        self.legend = self._legend()
        self.bones = [(PARENTS[j], j) for j in range(1, NUM_JOINTS)]
        self.radii = np.array([_bone_radius(j) for _, j in self.bones])
        self.colours = [side_colour(j) for _, j in self.bones]
        self.scene = as_scene(scene)
        self.solids = scene_solids(self.scene)
        self.floor_z = self.scene.floor_height if self.scene is not None else 0.0
        self._terrain = None
        if self.solids:
            import torch

            self._terrain = SceneBatch.from_scenes([self.scene], dtype=torch.float64)

    def _backdrop(self):
        """The sky, a vertical gradient: what every frame starts from."""
        img = self._image.new("RGB", (self.size, self.size), SKY)
        draw = self._draw.Draw(img)
        for y in range(0, self.size, 4):
            draw.rectangle((0, y, self.size, y + 4), fill=_scaled(SKY, 1.0 - 0.12 * (1 - y / self.size)))
        return img

    def _legend(self):
        """The legend (left, right, track, goal) as an RGBA strip, pasted onto every frame."""
        height = self.small.size + 4
        strip = self._image.new("RGBA", (self.size, height), (0, 0, 0, 0))
        draw = self._draw.Draw(strip)
        x = 8
        for colour, name in ((LEFT, "left"), (RIGHT, "right"), (CONTACT, "foot on floor"), (TRAIL, "pelvis track"),
                             (WAYPOINT, "goal")):
            draw.rectangle((x, 4, x + 12, height - 2), fill=colour)
            draw.text((x + 16, 2), name, fill=(40, 40, 40), font=self.small)
            x += 24 + int(draw.textlength(name, font=self.small))
        return strip

    def _floor(self, draw, cam: Camera, target: np.ndarray) -> None:
        """1 m tiles in two shades around the target, fading into the sky with distance (on-screen ones only)."""
        x0, y0 = int(np.floor(target[0])) - 6, int(np.floor(target[1])) - 2
        xs, ys = np.meshgrid(np.arange(x0, x0 + 13), np.arange(y0, y0 + 14), indexing="ij")
        pix, depth = cam.project(np.stack((xs, ys, np.full(xs.shape, self.floor_z)), axis=-1).astype(np.float64))
        quads = np.stack((pix[:-1, :-1], pix[1:, :-1], pix[1:, 1:], pix[:-1, 1:]), axis=2)  # (12, 13, 4, 2)
        depths = np.stack((depth[:-1, :-1], depth[1:, :-1], depth[1:, 1:], depth[:-1, 1:]), axis=2)
        lo, hi = quads.min(axis=2), quads.max(axis=2)
        shown = (depths.min(axis=2) > NEAR) & (hi >= 0).all(axis=-1) & (lo <= self.size).all(axis=-1)
        light = ((xs[:-1, :-1] + ys[:-1, :-1]) % 2).astype(bool)[..., None]
        base = np.where(light, np.array(FLOOR_LIGHT, float), np.array(FLOOR_DARK, float))
        fade = np.clip((depths.mean(axis=2) - 6.0) / 8.0, 0.0, 1.0)[..., None]
        colours = np.rint((1 - fade) * base + fade * np.array(SKY, float)).astype(int)
        for i, k in zip(*np.nonzero(shown)):
            draw.polygon(quads[i, k].ravel().tolist(), fill=tuple(colours[i, k].tolist()))

    def _path(self, draw, cam: Camera, points: np.ndarray, colour, width: int) -> None:
        """A floor-level polyline through ``points`` (T, 2+), every 2nd point, cut where it passes behind the camera."""
        if len(points) < 2:
            return
        pts = np.concatenate((points[::2, :2], points[-1:, :2]))
        pix, depth = cam.project(np.concatenate((pts, np.full((len(pts), 1), self.floor_z + 0.005)), axis=1))
        keep = np.concatenate(([False], depth > NEAR, [False]))
        edges = np.flatnonzero(np.diff(keep.astype(np.int8)))
        for start, stop in zip(edges[::2], edges[1::2]):
            if stop - start > 1:
                draw.line([tuple(q) for q in pix[start:stop]], fill=colour, width=width, joint="curve")

    def _colours(self, p: np.ndarray) -> list[tuple[int, int, int]]:
        """Each bone's colour: its side's, the foot bones turning green with their floor contact (as in the viewer).

        The contact weight is DART's skate weight ``2 - 2^clamp(h / 3 cm, 0, 1)`` of the foot joint's height.
        """
        colours = list(self.colours)
        for b, (_, c) in enumerate(self.bones):
            if c in FOOT_JOINTS:
                w = 2.0 - 2.0 ** float(np.clip(p[c, 2] / CONTACT_HEIGHT_M, 0.0, 1.0))
                colours[b] = _mix(colours[b], CONTACT, w)
        return colours

    def _capsules(self, draw, cam: Camera, p: np.ndarray, shadow: bool) -> None:
        """Bones as round-capped thick lines, far ones first; ``shadow``: the same flattened onto the terrain.

        Three passes (dark rim, colour, light core) over all bones: a body reads as one shaded piece
        rather than a chain of beads.
        """
        if shadow:
            p = p.copy()
            p[:, 2] = self.floor_z if self._terrain is None else terrain_heights(self.scene, p[:, :2], self._terrain)
        pix, depth = cam.project(p)
        if depth.min() <= NEAR:
            return
        scale = cam.focal / depth
        colours = self._colours(p)
        order = sorted(range(len(self.bones)), key=lambda b: -(depth[self.bones[b][0]] + depth[self.bones[b][1]]))
        passes = ((1.0, 1.0),) if shadow else ((1.0, 0.62), (0.78, 1.0), (0.3, 1.3))
        head = pix[HEAD] + (0.0, -0.4 * HEAD_RADIUS * scale[HEAD])
        for k, shade in passes:
            for b in order:
                a, c = self.bones[b]
                colour = SHADOW if shadow else _scaled(colours[b], shade)
                r = max(0.75, k * self.radii[b] * 0.5 * (scale[a] + scale[c]))
                draw.line((tuple(pix[a]), tuple(pix[c])), fill=colour, width=max(1, int(round(2 * r))))
                for q in (pix[a], pix[c]):
                    draw.ellipse((q[0] - r, q[1] - r, q[0] + r, q[1] + r), fill=colour)
            h = max(1.0, HEAD_RADIUS * scale[HEAD] * (1.0 if k == 1.0 else 0.92 if k > 0.5 else 0.4))
            q = head + ((0.0, 0.0) if k > 0.5 else (-0.3 * h, -0.3 * h))
            colour = SHADOW if shadow else _scaled(CENTRE, shade * 1.2)
            draw.ellipse((q[0] - h, q[1] - h, q[0] + h, q[1] + h), fill=colour)

    def _skeleton(self, draw, cam: Camera, p: np.ndarray) -> None:
        pix, depth = cam.project(p)
        if depth.min() <= NEAR:
            return
        width = max(2, self.size // 160)
        for (a, c), colour in zip(self.bones, self._colours(p)):
            draw.line((tuple(pix[a]), tuple(pix[c])), fill=colour, width=width)
        for j in range(NUM_JOINTS):
            r = width * 1.2
            draw.ellipse((pix[j, 0] - r, pix[j, 1] - r, pix[j, 0] + r, pix[j, 1] + r), fill=side_colour(j))

    def _polygon(self, draw, cam: Camera, points: np.ndarray, colour) -> None:
        """A filled, outlined 3-D convex polygon (K, 3), cut at the near plane."""
        points = _clip_near(cam, points)
        if len(points) >= 3:
            pix, _ = cam.project(points)
            draw.polygon([tuple(q) for q in pix], fill=colour, outline=_scaled(colour, 0.8))

    def _box(self, draw, cam: Camera, solid: Solid) -> None:
        """The faces of a box that face the camera (never more than three, so never overlapping), shaded."""
        c, s = np.cos(solid.yaw), np.sin(solid.yaw)
        turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        corners = solid.centre + (_CORNERS * solid.half) @ turn.T
        for index, normal in _FACES:
            n = turn @ np.array(normal)
            face = corners[list(index)]
            if n @ (face.mean(axis=0) - cam.position) >= 0:
                continue
            shade = FACE_SHADES[0] if n[2] > 0.5 else FACE_SHADES[1] if n @ _LIGHT > 0 else FACE_SHADES[2]
            self._polygon(draw, cam, face, _scaled(solid.colour, shade))

    def _cylinder(self, draw, cam: Camera, solid: Solid) -> None:
        """A pillar: the hull of its two rims (its outline from any view) and the top when seen from above."""
        r, h = solid.half[0], solid.half[2]
        rims = [np.stack((solid.centre[0] + r * np.cos(_RING), solid.centre[1] + r * np.sin(_RING),
                          np.full_like(_RING, solid.centre[2] + z)), axis=1) for z in (-h, h)]
        pix, depth = cam.project(np.concatenate(rims))
        if depth.min() <= NEAR:  # a pillar across the camera plane: left out rather than drawn wrong
            return
        draw.polygon([tuple(q) for q in _hull(pix)], fill=_scaled(solid.colour, FACE_SHADES[1]),
                     outline=_scaled(solid.colour, FACE_SHADES[1] * 0.8))
        if cam.position[2] > solid.centre[2] + h:
            self._polygon(draw, cam, rims[1], _scaled(solid.colour, FACE_SHADES[0]))

    def _marker(self, draw, cam: Camera, marker: Marker) -> None:
        """A ring on the terrain, or a ball on a stalk down to the terrain."""
        x, y, z = marker.point
        if not marker.raised:
            ring = np.stack((x + marker.radius * np.cos(_RING), y + marker.radius * np.sin(_RING),
                             np.full_like(_RING, z + 0.01)), axis=1)
            self._polygon(draw, cam, ring, marker.colour)
            return
        pix, depth = cam.project(np.array(((x, y, z), (x, y, marker.ground + 0.01))))
        if depth.min() <= NEAR:
            return
        draw.line((tuple(pix[0]), tuple(pix[1])), fill=_scaled(marker.colour, 0.7), width=max(1, self.size // 240))
        rad = max(2.0, marker.radius * cam.focal / depth[0])
        (u, v) = pix[0]
        draw.ellipse((u - rad, v - rad, u + rad, v + rad), fill=marker.colour, outline=_scaled(marker.colour, 0.62))
        draw.ellipse((u - 0.55 * rad, v - 0.6 * rad, u - 0.05 * rad, v - 0.1 * rad), fill=_scaled(marker.colour, 1.3))

    def _depth_ordered(self, draw, cam: Camera, p: np.ndarray, items: list[Marker]) -> None:
        """Scene objects, markers off the floor, the shadow and the body by the painter's algorithm, far first.

        An object (or raised marker) is behind the body when its point nearest to the pelvis is farther from
        the camera than the pelvis: a separating test that holds for convex objects clear of the body (a body
        standing on a step, beside a pillar, behind a wall). Each side is then drawn far to near; a ring on
        an object's top is drawn right after that object, and the shadow after everything behind the body.
        """
        pelvis = p[0]
        on_top: dict[int, list[Marker]] = {}
        loose = []
        for marker in items:
            holder = None if marker.raised else next(
                (k for k, solid in enumerate(self.solids) if _under(solid, marker.point)), None)
            if holder is None:
                loose.append(marker)
            else:
                on_top.setdefault(holder, []).append(marker)
        behind: list[tuple[float, int, object]] = []
        front: list[tuple[float, int, object]] = []
        for k, solid in enumerate(self.solids):
            side = front if (pelvis - _closest_point(solid, pelvis)) @ cam.forward > 0 else behind
            side.append((-float((solid.centre - cam.position) @ cam.forward), k, solid))
        for marker in loose:
            side = front if (pelvis - marker.point) @ cam.forward > 0 else behind
            side.append((-float((marker.point - cam.position) @ cam.forward), -1, marker))
        for group in (behind, None, front):
            if group is None:
                if self.style == "body":
                    self._capsules(draw, cam, p, shadow=True)
                    self._capsules(draw, cam, p, shadow=False)
                else:
                    self._skeleton(draw, cam, p)
                continue
            for _, k, item in sorted(group, key=lambda e: e[0]):
                if k < 0:
                    self._marker(draw, cam, item)
                    continue
                (self._box if item.kind == "box" else self._cylinder)(draw, cam, item)
                for marker in on_top.get(k, ()):
                    self._marker(draw, cam, marker)

    def draw(self, joints: np.ndarray, target: np.ndarray, track: np.ndarray | None = None,
             goals: np.ndarray | None = None, label: str = "", marks: Sequence[Marker] = ()):
        """One frame (a PIL RGB image) of joints (22, 3) seen by a :class:`Camera` looking at ``target``.

        ``goals`` (W, 2 or 3): waypoints drawn as :data:`WAYPOINT` markers; ``marks``: markers made already
        (:func:`markers`, what :func:`render_frames` passes so that terrain heights are found once).
        """
        img = self.background.copy()
        draw = self._draw.Draw(img)
        cam = Camera(target, self.size)
        self._floor(draw, cam, target)
        if track is not None:
            self._path(draw, cam, track, TRAIL, max(1, self.size // 240))
        marks = [*markers(goals, WAYPOINT, self.scene), *marks]
        flat = [not m.raised and m.ground <= self.floor_z + 1e-6 for m in marks]
        for m, on_floor in zip(marks, flat):
            if on_floor:
                self._marker(draw, cam, m)
        p = np.asarray(joints, dtype=np.float64)
        self._depth_ordered(draw, cam, p, [m for m, on_floor in zip(marks, flat) if not on_floor])
        if self.title:
            draw.text((8, 6), self.title, fill=(30, 30, 30), font=self.small)
        if label:
            draw.text((8, 10 + self.small.size), label, fill=(10, 10, 10), font=self.font)
        img.paste(self.legend, (0, self.size - self.legend.height - 6), self.legend)
        return img


def render_frames(joints: np.ndarray, fps: float = FPS, texts: Sequence[str] | None = None, title: str = "",
                  stride: int = 1, size: int = RENDER_SIZE, goals: np.ndarray | None = None, style: str = "body",
                  scene: Scene | str | None = None, frame_goals: np.ndarray | None = None):
    """Yield the PIL frames of a motion (T, 22, 3): every ``stride``-th frame, the camera following the pelvis.

    ``goals`` (W, 2 or 3): the episode's waypoints or joint targets (:data:`WAYPOINT` rings, balls where
    raised); ``scene``: the objects around the motion (a Scene or its JSON text); ``frame_goals`` (T, 3):
    the goal in force at each frame (a smaller :data:`GOAL` marker).
    """
    joints = np.asarray(joints, dtype=np.float64)
    renderer = FrameRenderer(size, style, title, scene)
    scene = renderer.scene
    targets = follow_targets(joints, ground=terrain_heights(scene, joints[:, 0, :2]) if scene is not None else None)
    marks = markers(goals, WAYPOINT, scene)
    now = None
    if frame_goals is not None and len(frame_goals):
        now = np.asarray(frame_goals, dtype=np.float64)
        distinct, inverse = np.unique(now, axis=0, return_inverse=True)
        now_marks = markers(distinct, GOAL, scene, NOW_RADIUS)
    for i in range(0, len(joints), max(1, int(stride))):
        text = texts[i] if texts is not None and i < len(texts) else ""
        extra = [now_marks[int(inverse.reshape(-1)[min(i, len(now) - 1)])]] if now is not None else []
        yield renderer.draw(joints[i], targets[i], joints[: i + 1, 0], None, f"{i / fps:5.2f} s  {text}".strip(),
                            [*marks, *extra])


def clip_goals(clip: MotionClip) -> np.ndarray | None:
    """(T, 3) the goal in force at each frame of a clip (its per-primitive ``goals``), or None if it has none.

    Seed frames show the first primitive's goal.
    """
    if clip.goals is None or not len(clip.goals) or clip.primitive is None or len(clip.primitive) != clip.frames:
        return None
    goals = np.asarray(clip.goals, dtype=np.float64)
    return goals[np.clip(np.asarray(clip.primitive), 0, len(goals) - 1)]


def clip_frames(clip: MotionClip, stride: int = 1, size: int = RENDER_SIZE, title: str = "", style: str = "body"):
    """:func:`render_frames` of a :class:`MotionClip` with everything it carries: scene, waypoints, goals."""
    return render_frames(clip.joints, clip.fps, clip.texts, title, stride, size, clip.waypoints, style,
                         scene=clip.scene, frame_goals=clip_goals(clip))


PALETTE_COLOURS = (LEFT, RIGHT, CENTRE, CONTACT, AIRBORNE, GOAL, WAYPOINT, TRAIL, SKY, FLOOR_LIGHT, FLOOR_DARK,
                   SHADOW, *SCENE_COLOURS.values())


def _gif_palette(first):
    """One 255-colour palette for the whole GIF: the first frame plus every colour the renderer draws with.

    Quantizing each frame to a fixed palette (no dithering) is ~40x cheaper than Pillow's adaptive
    palette per frame, and the picture has few colours anyway.
    """
    from PIL import Image

    shades = [_scaled(c, k) for c in PALETTE_COLOURS for k in (0.62, 0.7, 0.8, 0.86, 1.0, 1.12, 1.2, 1.3)]
    strip = Image.new("RGB", (len(shades), 1))
    strip.putdata(shades)
    sample = Image.new("RGB", (first.width, first.height + 8))
    sample.paste(first, (0, 0))
    sample.paste(strip.resize((first.width, 8), Image.Resampling.NEAREST), (0, first.height))
    return sample.quantize(colors=255, method=Image.Quantize.MEDIANCUT)


def _write_gif(tmp, frames, duration_ms: int) -> None:
    from PIL import Image

    first = next(frames)
    palette = _gif_palette(first)
    indexed = (f.quantize(palette=palette, dither=Image.Dither.NONE) for f in frames)
    first.quantize(palette=palette, dither=Image.Dither.NONE).save(
        tmp, format="GIF", save_all=True, append_images=indexed, duration=duration_ms, loop=0)


def _write_mp4(tmp: Path, frames, fps: float, size: int) -> None:
    try:
        import imageio_ffmpeg
    except ImportError:
        raise DataError(f"{tmp.name.split('.tmp')[0]}: MP4 needs imageio-ffmpeg: pip install 'latentrl[video]' "
                        "(or write a .gif)") from None
    writer = imageio_ffmpeg.write_frames(str(tmp), (size, size), fps=fps, codec="libx264", pix_fmt_out="yuv420p",
                                         macro_block_size=16, ffmpeg_log_level="error", quality=None,
                                         output_params=["-crf", "23", "-preset", "veryfast", "-f", "mp4"])
    writer.send(None)
    try:
        for frame in frames:
            writer.send(frame.tobytes())
    finally:
        writer.close()


def video_problem(path: str | Path) -> str | None:
    """Why ``path`` cannot name a rendered video here (a .gif, or a .mp4 with imageio-ffmpeg installed), or None."""
    import importlib.util

    suffix = Path(path).suffix.lower()
    if suffix not in VIDEO_FORMATS:
        return f"must name a .gif or .mp4 file, got '{path}'"
    if suffix == ".mp4" and importlib.util.find_spec("imageio_ffmpeg") is None:
        return f"{path}: MP4 needs imageio-ffmpeg: pip install 'latentrl[video]' (or name a .gif)"
    return None


def render_video(path: str | Path, joints: np.ndarray, fps: float = FPS, texts: Sequence[str] | None = None,
                 title: str = "", stride: int | None = None, size: int = RENDER_SIZE,
                 goals: np.ndarray | None = None, style: str = "body", scene: Scene | str | None = None,
                 frame_goals: np.ndarray | None = None) -> Path:
    """Render a motion (T, 22, 3) as a GIF or MP4 (by ``path``'s suffix), atomically; returns ``path``.

    ``stride`` keeps every n-th frame (default: :data:`GIF_STRIDE` for GIF, 1 for MP4); the file
    plays in real time at ``fps / stride``. MP4 (H.264) needs ``latentrl[video]`` (imageio-ffmpeg).
    ``goals``, ``scene`` and ``frame_goals``: as :func:`render_frames` draws them.
    """
    if Path(path).suffix.lower() not in VIDEO_FORMATS:
        raise DataError(f"{path}: expected a .gif or .mp4 file")
    if style not in STYLES:
        raise DataError(f"render style must be one of {', '.join(STYLES)}, got '{style}'")
    if int(size) % 16 or int(size) < 64:
        raise DataError(f"render size must be a multiple of 16 and >= 64, got {size}")
    joints, fps = check_motion(joints, fps, str(path))
    mp4 = Path(path).suffix.lower() == ".mp4"
    stride = max(1, int(stride if stride is not None else (1 if mp4 else GIF_STRIDE)))
    frames = render_frames(joints, fps, texts, title, stride, size, goals, style, scene, frame_goals)
    if mp4:
        return atomic_write_with(path, lambda tmp: _write_mp4(tmp, frames, fps / stride, int(size)))
    return atomic_write_with(path, lambda tmp: _write_gif(tmp, frames, int(round(1000 * stride / fps))))


def render_clip(path: str | Path, clip: MotionClip, title: str = "", stride: int | None = None,
                size: int = RENDER_SIZE, style: str = "body") -> Path:
    """:func:`render_video` of a :class:`MotionClip` with everything it carries: its scene, waypoints and goals."""
    return render_video(path, clip.joints, clip.fps, clip.texts, title, stride, size, clip.waypoints, style,
                        scene=clip.scene, frame_goals=clip_goals(clip))


def gif_bytes(frames, fps: float) -> bytes:
    """PIL frames as an animated GIF in memory (what TensorBoard's image plugin plays), at ``fps`` frames/s."""
    import io

    buffer = io.BytesIO()
    _write_gif(buffer, iter(frames), int(round(1000 / fps)))
    return buffer.getvalue()


def render_gif(path: str | Path, joints: np.ndarray, fps: float = FPS, texts: Sequence[str] | None = None,
               title: str = "", stride: int = GIF_STRIDE, size: int = RENDER_SIZE,
               goals: np.ndarray | None = None, style: str = "body") -> Path:
    """Animate a motion (T, 22, 3) as a GIF: :func:`render_video` with a ``.gif`` path (kept for callers)."""
    return render_video(path, joints, fps, texts, title, stride, size, goals, style)


# --------------------------------------------------------------------------- BVH
# BVH is Y-up by convention; latentrl's world is z-up. ZUP_TO_YUP maps (x right, y forward, z up) to
# (x right, y up, z backward): a proper rotation (-90 degrees about x), so a body facing +y (ours)
# faces -z in the file, which Blender's default BVH import (forward -Z, up Y) turns back into +y.
ZUP_TO_YUP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
BVH_UNITS_PER_M = 100.0
"""BVH files are written in centimetres (the usual mocap unit; import with scale 0.01 in Blender)."""
BVH_ROTATION_CHANNELS = ("Zrotation", "Xrotation", "Yrotation")
"""Channel order of every joint's rotation: R = Rz(z) Rx(x) Ry(y) (column vectors), degrees."""

_SMPL_REST_OFFSETS = SMPL_REST_OFFSETS  # the old address (tests and scripts import it from here)
# End Site offsets of the leaf joints (toes forward, head up, hands along the arm), metres, z up.
_END_SITES = {10: (0.0, 0.06, 0.0), 11: (0.0, 0.06, 0.0), 15: (0.0, 0.0, 0.12), 20: (-0.09, 0.0, 0.0),
              21: (0.09, 0.0, 0.0)}


def _children(j: int) -> list[int]:
    return [c for c, p in enumerate(PARENTS) if p == j]


def _dfs_order() -> list[int]:
    """SMPL joints in BVH's depth-first hierarchy order (children in index order)."""
    order, stack = [], [0]
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(reversed(_children(j)))
    return order


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 1e-12, n, 1.0)


def _swing(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(T, 3, 3) shortest-arc rotations taking unit vectors a (T, 3) onto unit vectors b (T, 3)."""
    v, c = np.cross(a, b), np.einsum("ti,ti->t", a, b)
    k = np.zeros(a.shape[:1] + (3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -v[:, 2], v[:, 1], -v[:, 0]
    k -= np.swapaxes(k, 1, 2)
    rot = np.eye(3) + k + k @ k / np.maximum(1.0 + c, 1e-12)[:, None, None]
    flip = c < -1.0 + 1e-9  # opposite vectors: half turn about any axis perpendicular to a
    if flip.any():
        axis = np.cross(a[flip], np.array([1.0, 0.0, 0.0]))
        axis = np.where(np.linalg.norm(axis, axis=-1, keepdims=True) < 1e-6, np.cross(a[flip], [0.0, 1.0, 0.0]), axis)
        u = _unit(axis)
        rot[flip] = 2.0 * u[:, :, None] * u[:, None, :] - np.eye(3)
    return rot


def _kabsch(rest: np.ndarray, observed: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotations best mapping rest vectors (K, 3) onto observed ones (T, K, 3) (least squares)."""
    u, _, vt = np.linalg.svd(np.einsum("kc,tkd->tcd", rest, observed))
    v = np.swapaxes(vt, 1, 2)
    d = np.sign(np.linalg.det(v @ np.swapaxes(u, 1, 2)))
    v[:, :, 2] *= np.where(d == 0, 1.0, d)[:, None]
    return v @ np.swapaxes(u, 1, 2)


_bone_offsets = rest_offsets


def _global_rotations(joints: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(T, 22, 3, 3) world rotations that swing each joint's rest bones onto the observed ones.

    Joints with several children (pelvis, spine3) take the least-squares rotation of all their
    bones; joints with one child the shortest arc from the parent-rotated rest bone (so twist is
    inherited from the parent and stays smooth); leaves copy their parent.
    """
    t = len(joints)
    glob = np.zeros((t, NUM_JOINTS, 3, 3))
    for j in range(NUM_JOINTS):
        base = glob[:, PARENTS[j]] if j > 0 else np.broadcast_to(np.eye(3), (t, 3, 3))
        kids = _children(j)
        if len(kids) > 1:
            glob[:, j] = _kabsch(offsets[kids], joints[:, kids] - joints[:, j : j + 1])
        elif kids:
            observed = joints[:, kids[0]] - joints[:, j]
            a = _unit(base @ offsets[kids[0]])
            b = np.where(np.linalg.norm(observed, axis=-1, keepdims=True) > 1e-9, _unit(observed), a)
            glob[:, j] = _swing(a, b) @ base
        else:
            glob[:, j] = base
    return glob


def _axis_rotation(axis: str, degrees: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotations by ``degrees`` (T,) about the x, y or z axis."""
    r = np.radians(degrees)
    c, s = np.cos(r), np.sin(r)
    m = np.zeros(r.shape + (3, 3))
    i, k = {"x": (1, 2), "y": (2, 0), "z": (0, 1)}[axis]
    m[:, "xyz".index(axis), "xyz".index(axis)] = 1.0
    m[:, i, i], m[:, i, k], m[:, k, i], m[:, k, k] = c, -s, s, c
    return m


def _euler_zxy_degrees(rot: np.ndarray) -> np.ndarray:
    """(T, 3, 3) -> (T, 3) angles (z, x, y) in degrees with rot = Rz Rx Ry (the channel order)."""
    x = np.arcsin(np.clip(rot[:, 2, 1], -1.0, 1.0))
    z = np.arctan2(-rot[:, 0, 1], rot[:, 1, 1])
    y = np.arctan2(-rot[:, 2, 0], rot[:, 2, 2])
    lock = np.abs(rot[:, 2, 1]) > 1.0 - 1e-9  # gimbal lock: put everything in z (x is +-90)
    z = np.where(lock, np.arctan2(rot[:, 1, 0], rot[:, 0, 0]), z)
    y = np.where(lock, 0.0, y)
    return np.degrees(np.stack((z, x, y), axis=-1))


def _zxy_matrix(angles: np.ndarray) -> np.ndarray:
    return _axis_rotation("z", angles[:, 0]) @ _axis_rotation("x", angles[:, 1]) @ _axis_rotation("y", angles[:, 2])


def _bvh_channels(joints_y: np.ndarray, glob_zup: np.ndarray) -> np.ndarray:
    """(T, 22, 6) channel values per joint: position (cm, in the parent's frame) then Z, X, Y rotation (deg).

    The written (rounded) angles are re-composed before the translations are derived from them, so
    the file's forward kinematics reproduce ``joints_y`` exactly, whatever rotations were chosen.
    """
    t = len(joints_y)
    glob_y = ZUP_TO_YUP @ glob_zup @ ZUP_TO_YUP.T
    values = np.zeros((t, NUM_JOINTS, 6))
    chain = np.zeros((t, NUM_JOINTS, 3, 3))
    for j in range(NUM_JOINTS):
        parent = np.broadcast_to(np.eye(3), (t, 3, 3)) if j == 0 else chain[:, PARENTS[j]]
        angles = np.round(_euler_zxy_degrees(np.swapaxes(parent, 1, 2) @ glob_y[:, j]), 6)
        chain[:, j] = parent @ _zxy_matrix(angles)
        rel = joints_y[:, j] - (joints_y[:, PARENTS[j]] if j > 0 else 0.0)
        values[:, j, :3] = np.einsum("tji,tj->ti", parent, rel)  # parent^T @ rel
        values[:, j, 3:] = angles
    return values


def _bvh_hierarchy(offsets_y: np.ndarray, root_offset: np.ndarray) -> list[str]:
    """HIERARCHY lines: joints depth-first, 6 channels each, End Sites on the leaves (file units and axes)."""
    lines = ["HIERARCHY"]
    channels = "CHANNELS 6 Xposition Yposition Zposition " + " ".join(BVH_ROTATION_CHANNELS)

    def emit(j: int, depth: int) -> None:
        pad = "  " * depth
        off = root_offset if j == 0 else offsets_y[j]
        lines.extend([f"{pad}{'ROOT' if j == 0 else 'JOINT'} {JOINT_NAMES[j]}", f"{pad}{{",
                      f"{pad}  OFFSET {off[0]:.5f} {off[1]:.5f} {off[2]:.5f}", f"{pad}  {channels}"])
        for c in _children(j):
            emit(c, depth + 1)
        if j in _END_SITES:
            end = ZUP_TO_YUP @ np.asarray(_END_SITES[j]) * BVH_UNITS_PER_M
            lines.extend([f"{pad}  End Site", f"{pad}  {{", f"{pad}    OFFSET {end[0]:.5f} {end[1]:.5f} {end[2]:.5f}",
                          f"{pad}  }}"])
        lines.append(f"{pad}}}")

    emit(0, 0)
    return lines


def save_bvh(path: str | Path, joints, fps: float = FPS) -> Path:
    """Write world joints (T, 22, 3) (metres, z up) as a BVH file of the SMPL-22 skeleton, atomically.

    The file is Y-up (:data:`ZUP_TO_YUP`) and in centimetres. OFFSETs are a T-pose with the motion's
    median bone lengths. Generated joint positions are not rigid (bone lengths drift a little), so
    rotations alone cannot reproduce them: **every joint has 6 channels**, its position in the parent's
    frame (which replaces the OFFSET, as Blender and MotionBuilder read non-root position channels)
    and a ZXY rotation that swings the rest bones onto the observed ones, so the skeleton also
    animates sensibly in tools that ignore the child positions. :func:`load_bvh` reproduces the
    input positions to well under 1 mm. BVH has no comment syntax, so these conventions are
    documented here and in docs/evaluation.md, not inside the file.
    """
    joints, fps = check_motion(joints, fps, str(path))
    offsets = _bone_offsets(joints)
    leg = offsets[1] + offsets[4] + offsets[7] + offsets[10]  # rest pelvis height: the rest pose stands on the floor
    root_offset = ZUP_TO_YUP @ np.array([0.0, 0.0, max(-leg[2], 0.0)]) * BVH_UNITS_PER_M
    joints_y = joints @ ZUP_TO_YUP.T * BVH_UNITS_PER_M
    values = _bvh_channels(joints_y, _global_rotations(joints, offsets))
    order = _dfs_order()
    lines = _bvh_hierarchy(offsets @ ZUP_TO_YUP.T * BVH_UNITS_PER_M, root_offset)
    lines += ["MOTION", f"Frames: {len(joints)}", f"Frame Time: {1.0 / float(fps):.8f}"]
    flat = values[:, order].reshape(len(joints), -1) + 0.0  # + 0.0 turns -0.0 into 0.0
    lines += [" ".join(f"{v:.6f}" for v in row) for row in flat]
    return atomic_write_bytes(path, ("\n".join(lines) + "\n").encode("ascii"))


def _parse_hierarchy(tokens: list[str], source: str) -> tuple[list[str], list[int], list, list[list[str]], int]:
    """BVH HIERARCHY tokens -> (names, parents, offsets, channels, index of the token after it)."""
    names, parents, offsets, channels = [], [], [], []
    stack: list[int] = []
    i, end_site = 1, False
    while i < len(tokens) and tokens[i].upper() != "MOTION":
        tok = tokens[i].upper()
        if tok in ("ROOT", "JOINT"):
            names.append(tokens[i + 1])
            parents.append(stack[-1] if stack else -1)
            i += 2
        elif tok == "END":  # "End Site": its offset only shapes bone tails
            end_site, i = True, i + 2
        elif tok == "{":
            stack.append(-2 if end_site else len(names) - 1)
            end_site, i = False, i + 1
        elif tok == "}":
            stack.pop()
            i += 1
        elif tok == "OFFSET":
            if stack[-1] != -2:
                offsets.append([float(v) for v in tokens[i + 1 : i + 4]])
            i += 4
        elif tok == "CHANNELS":
            n = int(tokens[i + 1])
            channels.append(tokens[i + 2 : i + 2 + n])
            i += 2 + n
        else:
            raise DataError(f"{source}: unexpected token '{tokens[i]}' in HIERARCHY")
    if not names or len(offsets) != len(names) or len(channels) != len(names):
        raise DataError(f"{source}: every ROOT/JOINT needs an OFFSET and CHANNELS")
    return names, parents, offsets, channels, i


def _bvh_forward_kinematics(offsets, channels, parents, values: np.ndarray) -> np.ndarray:
    """(T, J, 3) joint positions in file units and axes from channel values (T, C).

    Position channels give the joint's translation in its parent's frame (replacing the OFFSET);
    rotation channels compose in the listed order (``Zrotation Xrotation Yrotation`` -> Rz Rx Ry).
    """
    t, col = len(values), 0
    pos = np.zeros((t, len(offsets), 3))
    glob = np.zeros((t, len(offsets), 3, 3))
    for j, chans in enumerate(channels):
        trans = np.broadcast_to(np.asarray(offsets[j], dtype=np.float64), (t, 3)).copy()
        rot = np.broadcast_to(np.eye(3), (t, 3, 3))
        for name in chans:
            axis, kind = name[0].lower(), name[1:].lower()
            if kind == "position":
                trans[:, "xyz".index(axis)] = values[:, col]
            else:
                rot = rot @ _axis_rotation(axis, values[:, col])
            col += 1
        p = parents[j]
        pos[:, j] = trans if p < 0 else pos[:, p] + np.einsum("tij,tj->ti", glob[:, p], trans)
        glob[:, j] = rot if p < 0 else glob[:, p] @ rot
    return pos


def load_bvh(path: str | Path) -> dict[str, np.ndarray]:
    """Read a BVH file (a small parser for round trips and checks) back into latentrl's convention.

    Returns ``joints`` (T, J, 3) world metres, z up (the inverse of :func:`save_bvh`'s axes and
    centimetres), ``fps``, ``names`` and ``parents``. Joints come in SMPL order when the file holds
    exactly the 22 SMPL joint names, otherwise in file order.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"BVH file not found: {path}")
    tokens = path.read_text(encoding="ascii", errors="replace").split()
    if not tokens or tokens[0].upper() != "HIERARCHY":
        raise DataError(f"{path}: not a BVH file (it must start with HIERARCHY)")
    try:
        names, parents, offsets, channels, i = _parse_hierarchy(tokens, str(path))
        frames, frame_time = int(tokens[i + 2]), float(tokens[i + 5])
        width = sum(len(c) for c in channels)
        values = np.asarray(tokens[i + 6 : i + 6 + frames * width], dtype=np.float64)
    except (IndexError, ValueError) as exc:
        raise DataError(f"{path}: malformed BVH ({str(exc)[:120]})") from None
    if values.size != frames * width:
        raise DataError(f"{path}: MOTION holds {values.size} values, expected {frames} frames x {width} channels")
    joints = _bvh_forward_kinematics(offsets, channels, parents, values.reshape(frames, width))
    joints = joints @ ZUP_TO_YUP / BVH_UNITS_PER_M  # inverse of the proper rotation is its transpose
    if sorted(names) == sorted(JOINT_NAMES):
        order = [names.index(n) for n in JOINT_NAMES]
        joints, names = joints[:, order], list(JOINT_NAMES)
        parents = list(PARENTS)
    return {"joints": joints.astype(np.float32), "fps": np.float32(1.0 / frame_time), "names": np.asarray(names),
            "parents": np.asarray(parents, dtype=np.int32)}
