"""The 3D scene both commands draw in Viser: a shaded floor, objects, the character, its trail and goals.

The character is a capsule body, a skeleton as an option, its feet coloured by contact.

The geometry (bone segments, colours, contact weights, the camera that frames a motion) is plain
numpy in functions of this module, :mod:`latentrl.viewer.body` and :mod:`latentrl.viewer.objects`, tested
without a browser; :class:`SkeletonScene` only hands those arrays to Viser's scene handles. World frame:
latentrl's (metres, z up, floor at the scene's floor height, 0 without a scene).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from latentrl.envs.reach_joint import JOINTS
from latentrl.motion.skeleton import ANKLE_JOINTS, FOOT_JOINTS, JOINT_NAMES, PARENTS, PELVIS
from latentrl.render import (  # the colours of the rendered GIFs and MP4s, so both agree  # noqa: F401
    AIRBORNE,
    CENTRE,
    CONTACT,
    FLOOR_DARK,
    FLOOR_LIGHT,
    GOAL,
    LEFT,
    RIGHT,
    SHADOW,
    TRAIL,
    WAYPOINT,
    side_colour,
)
from latentrl.render import GOAL_JOINT_COLOURS as GOAL_COLOURS_BY_NAME
from latentrl.scenes.scene import Scene
from latentrl.viewer.body import CapsuleBody
from latentrl.viewer.objects import SceneObjects

CONTACT_HEIGHT_M = 0.03
"""DART's skate threshold: a foot joint counts fully in contact at the floor, not at all 3 cm above it."""
TARGET_DIM, TARGET_ON = (150, 150, 160), (40, 200, 90)
"""Optimization targets and ghost keyframes: grey, green on their own frame."""
BONES = np.array([(PARENTS[j], j) for j in range(len(PARENTS)) if PARENTS[j] >= 0], dtype=np.int64)
"""(21, 2) parent, child joint index of every bone."""


BONE_COLOURS = np.array([[side_colour(c)] * 2 for _, c in BONES], dtype=np.uint8)
"""(21, 2, 3) colour of each bone end (the child's side: left blue, right orange, spine grey)."""


def bone_segments(joints: np.ndarray) -> np.ndarray:
    """(22, 3) joints of one frame -> (21, 2, 3) line segments parent -> child."""
    return np.asarray(joints, dtype=np.float32)[BONES]


def contact_weights(joints: np.ndarray, floor: np.ndarray | float = 0.0) -> np.ndarray:
    """(..., 22, 3) -> (..., 2) how much each foot (left, right) touches the floor, in [0, 1].

    The weight of DART's skate metric, ``2 - 2^clamp(h / 3 cm, 0, 1)`` with h the foot joint's height
    above ``floor`` (one z, or the ground z under each foot): 1 on the ground, 0 from 3 cm up.
    """
    heights = np.asarray(joints, dtype=np.float32)[..., list(FOOT_JOINTS), 2] - floor
    return 2.0 - np.power(2.0, np.clip(heights / CONTACT_HEIGHT_M, 0.0, 1.0))


def joint_colours(joints: np.ndarray, floor: np.ndarray | float = 0.0) -> np.ndarray:
    """(22, 3) joints -> (22, 3) uint8 colours: side colours, feet and ankles from grey (air) to green (contact)."""
    colours = np.array([side_colour(j) for j in range(len(JOINT_NAMES))], dtype=np.float32)
    weights = contact_weights(joints, floor)
    for side in range(2):
        w = float(weights[side])
        for j in (FOOT_JOINTS[side], ANKLE_JOINTS[side]):
            colours[j] = w * np.array(CONTACT) + (1 - w) * np.array(AIRBORNE)
    return colours.round().astype(np.uint8)


def trail_segments(pelvis: np.ndarray, height: float = 0.01, stride: int = 2) -> np.ndarray:
    """(T, 3) pelvis positions -> (K, 2, 3) floor-level segments through every ``stride``-th point (K >= 1)."""
    pts = np.asarray(pelvis, dtype=np.float32)[::stride, :3].copy()
    if len(pelvis) and (len(pelvis) - 1) % stride:
        pts = np.concatenate((pts, np.asarray(pelvis, dtype=np.float32)[-1:, :3]))
    pts[:, 2] = height
    if len(pts) < 2:
        pts = np.concatenate((pts, pts))[:2] if len(pts) else np.zeros((2, 3), np.float32)
    return np.stack((pts[:-1], pts[1:]), axis=1)


def frame_camera(joints: np.ndarray, waypoints: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Camera ``(position, look_at)`` that shows the whole motion (and path) from behind the start, above.

    The body starts facing +y, so the camera sits on the -y side of the bounding box, looking at its
    centre from about 35 degrees above the floor.
    """
    points = np.asarray(joints, dtype=np.float32)[:, PELVIS, :2]
    if waypoints is not None and len(waypoints):
        points = np.concatenate((points, np.asarray(waypoints, dtype=np.float32)[:, :2]))
    lo, hi = points.min(0), points.max(0)
    centre = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, 0.8], dtype=np.float32)
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1.5)
    distance = 1.2 * radius + 1.8
    position = centre + np.array([0.0, -0.82 * distance, 0.57 * distance], dtype=np.float32)
    return position, centre


GOAL_JOINT_COLOURS = {JOINTS[name]: rgb for name, rgb in GOAL_COLOURS_BY_NAME.items()}
"""Joint-goal targets by SMPL joint: :data:`latentrl.render.GOAL_JOINT_COLOURS`, the colours of paths.png."""


def waypoint_marks(waypoints: np.ndarray, joints: np.ndarray | None, floor: float
                   ) -> tuple[np.ndarray, list[tuple[int, int, int]]]:
    """(W, 3) marker centres and W colours of waypoints.

    Path waypoints (``joints`` None) sit 8 cm above the floor in the waypoint colour. Joint-goal targets sit at
    their own point (at least 8 cm up: a spot on the floor stays visible), coloured by their joint. ``joints``
    that do not fit (another length, an unknown index) are ignored: the plain markers.
    """
    w = np.asarray(waypoints, dtype=np.float32).reshape(-1, 3)
    lifted = np.stack((w[:, 0], w[:, 1], np.full(len(w), floor + 0.08, dtype=np.float32)), axis=1)
    ok = joints is not None and np.shape(joints) == (len(w),) and all(int(j) in GOAL_JOINT_COLOURS for j in joints)
    if not ok:
        return lifted, [WAYPOINT] * len(w)
    lifted[:, 2] = np.maximum(w[:, 2], floor + 0.08)
    return lifted, [GOAL_JOINT_COLOURS[int(j)] for j in joints]


def floor_extent(joints: np.ndarray, waypoints: np.ndarray | None = None, margin: float = 3.0) -> tuple:
    """``(centre_xy, size)`` of a square floor grid under the motion and its waypoints, in whole metres."""
    points = np.asarray(joints, dtype=np.float32)[:, PELVIS, :2]
    if waypoints is not None and len(waypoints):
        points = np.concatenate((points, np.asarray(waypoints, dtype=np.float32)[:, :2]))
    lo, hi = points.min(0) - margin, points.max(0) + margin
    size = float(np.ceil(max(hi - lo)))
    centre = np.round((lo + hi) / 2)
    return centre, max(size, 2 * margin)


FLOOR_SHADOW = 0.35
"""Opacity of the shadows the body and objects cast on the floor (0: none, 1: black)."""


class SkeletonScene:
    """Scene nodes of one character in a Viser server; every update is one property assignment.

    The character is a capsule body (:class:`~latentrl.viewer.body.CapsuleBody`) and, as an option, the
    skeleton of line segments and joint dots; both can be shown at once (the body then turns half
    transparent so the skeleton shows through). A hidden one is not updated while hidden.

    Args:
        server: a ``viser.ViserServer``.
        skeleton: draw the skeleton from the start (``--skeleton``).
        body: draw the capsule body from the start.
    """

    def __init__(self, server: Any, skeleton: bool = False, body: bool = True):
        self.server = server
        scene = server.scene
        scene.set_up_direction("+z")
        scene.configure_default_lights(enabled=True, cast_shadow=True)
        self.grid = scene.add_grid("/floor", 20.0, 20.0, plane="xy", cell_size=0.5, section_size=1.0,
                                   cell_color=FLOOR_DARK, section_color=SHADOW, plane_color=FLOOR_LIGHT,
                                   plane_opacity=1.0, shadow_opacity=FLOOR_SHADOW)
        zeros = np.zeros((len(JOINT_NAMES), 3), dtype=np.float32)
        self.pose = zeros
        """The (22, 3) joints shown now."""
        self.world: Scene | None = None
        """The scene drawn (None: the bare floor)."""
        self.floor_height = 0.0
        self._terrain: Any = None
        self.objects = SceneObjects(server)
        self.character = CapsuleBody(server)
        self.character.visible = bool(body)
        self.body = scene.add_frame("/body", show_axes=False, visible=bool(skeleton))
        self.bones = scene.add_line_segments("/body/bones", bone_segments(zeros), BONE_COLOURS, thickness=0.05)
        self.joints = scene.add_point_cloud("/body/joints", zeros, joint_colours(zeros), point_size=0.07,
                                            point_shape="circle", precision="float32", point_shading="flat")
        self.character.see_through(bool(skeleton) and bool(body))
        self.trail = scene.add_line_segments("/trail", trail_segments(zeros[:1]), TRAIL, thickness=0.025)
        self.path = scene.add_line_segments("/path", trail_segments(zeros[:1]), (200, 200, 210), thickness=0.012,
                                            visible=False)
        self.goal = scene.add_icosphere("/goal", radius=0.12, color=GOAL, visible=False)
        self.waypoints: list[Any] = []
        self.target_nodes: list[Any] = []
        self.ghosts: dict[int, Any] = {}
        self.targets: Any = None

    def set_scene(self, scene: Scene | None, dropped: int = 0) -> None:
        """Draw ``scene``'s objects (None: none) and put the floor at its floor height.

        ``dropped``: its last this many objects were dropped by hand (drawn in another colour).
        """
        from latentrl.scenes.scene import SceneBatch

        self.world = scene
        self.objects.show(scene, dropped)
        self.floor_height = 0.0 if scene is None else float(scene.floor_height)
        self._terrain = SceneBatch.from_scenes([scene]) if scene is not None and scene.objects else None
        pos = self.grid.position
        self.grid.position = (float(pos[0]), float(pos[1]), self.floor_height)

    def ground_under_feet(self, joints: np.ndarray) -> np.ndarray:
        """(2,) the terrain z under the left and right foot (a tread or box top, else the floor)."""
        if self._terrain is None:
            return np.full(2, self.floor_height, dtype=np.float32)
        import torch

        feet = torch.as_tensor(np.asarray(joints, dtype=np.float64)[None, list(FOOT_JOINTS), :2])
        return self._terrain.height(feet.to(self._terrain.floor_height.dtype))[0].numpy().astype(np.float32)

    def set_floor(self, centre_xy: np.ndarray, size: float) -> None:
        """Centre the floor grid at ``centre_xy`` with sides of ``size`` metres."""
        self.grid.width = self.grid.height = float(size)
        self.grid.position = (float(centre_xy[0]), float(centre_xy[1]), self.floor_height)

    def set_waypoints(self, waypoints: np.ndarray | None, joints: np.ndarray | None = None) -> None:
        """Numbered markers for a path's waypoints (replacing any previous path).

        With ``joints`` (one SMPL index per waypoint: a joint-goal episode's targets) they are coloured by joint
        and drawn at their own height (:func:`waypoint_marks`).
        """
        for handle in self.waypoints:
            handle.remove()
        self.waypoints = []
        if waypoints is None or not len(waypoints):
            self.path.visible = False
            return
        z = self.floor_height
        positions, colours = waypoint_marks(np.asarray(waypoints, dtype=np.float32), joints, z)
        for i, (p, colour) in enumerate(zip(positions, colours)):
            self.waypoints.append(self.server.scene.add_icosphere(f"/waypoints/{i}", radius=0.08, color=colour,
                                                                  position=tuple(map(float, p))))
            self.waypoints.append(self.server.scene.add_label(f"/waypoint_labels/{i}", str(i),
                                                              position=(float(p[0]), float(p[1]), float(p[2]) + 0.22)))
        start = np.zeros((1, 3), dtype=np.float32)
        self.path.points = trail_segments(np.concatenate((start, waypoints)), height=z + 0.005, stride=1)
        self.path.visible = True

    def show_pose(self, joints: np.ndarray) -> None:
        """Draw one frame's (22, 3) joints (the body, and the skeleton when it is shown)."""
        joints = np.asarray(joints, dtype=np.float32)
        self.pose = joints
        ground = self.ground_under_feet(joints)
        if self.character.visible:
            self.character.show(joints, ground)
        if self.body.visible:
            self.bones.points = bone_segments(joints)
            self.joints.points = joints
            self.joints.colors = joint_colours(joints, ground)

    def show_trail(self, pelvis: np.ndarray) -> None:
        """(T, 3) pelvis positions so far (at least one)."""
        self.trail.points = trail_segments(pelvis, height=self.floor_height + 0.01)

    def show_goal(self, goal: np.ndarray | None) -> None:
        """Show the goal marker at ``goal`` (world metres), or hide it for None."""
        if goal is None:
            self.goal.visible = False
            return
        self.goal.position = (float(goal[0]), float(goal[1]), self.floor_height + 0.12)
        self.goal.visible = True

    def set_targets(self, targets: np.ndarray | None, keyframes: dict[int, np.ndarray] | None = None) -> None:
        """Markers for an optimized motion's point targets and ghost skeletons for its keyframes (or none)."""
        for handle in self.target_nodes:
            handle.remove()
        self.target_nodes, self.ghosts = [], {}
        if targets is None or not len(targets):
            return
        pts = np.asarray(targets, dtype=np.float32)
        colours = np.tile(np.asarray(TARGET_DIM, dtype=np.uint8), (len(pts), 1))
        self.targets = self.server.scene.add_point_cloud("/targets", pts, colours, point_size=0.06,
                                                         point_shape="diamond", precision="float32",
                                                         point_shading="flat")
        self.target_nodes.append(self.targets)
        for frame, joints in (keyframes or {}).items():
            ghost = self.server.scene.add_line_segments(f"/ghosts/{frame}", bone_segments(joints), TARGET_DIM,
                                                        thickness=0.03)
            self.ghosts[frame] = ghost
            self.target_nodes.append(ghost)

    def show_targets_at(self, frame: int, target_frames: np.ndarray | None) -> None:
        """Brighten the targets and the ghost keyframe of ``frame``; dim the others."""
        if target_frames is None or not self.target_nodes:
            return
        on = np.asarray(target_frames) == frame
        colours = np.where(on[:, None], np.asarray(TARGET_ON, dtype=np.uint8), np.asarray(TARGET_DIM, dtype=np.uint8))
        self.targets.colors = colours.astype(np.uint8)
        for f, ghost in self.ghosts.items():
            colour = np.asarray(TARGET_ON if f == frame else TARGET_DIM, dtype=np.uint8)
            ghost.colors = np.broadcast_to(colour, np.asarray(ghost.points).shape).copy()

    def set_skeleton_visible(self, visible: bool) -> None:
        """Show or hide the skeleton (lines and joint dots)."""
        self.body.visible = bool(visible)
        self.character.see_through(self.body.visible and self.character.visible)
        self.show_pose(self.pose)

    def set_body_visible(self, visible: bool) -> None:
        """Show or hide the capsule body."""
        self.character.visible = bool(visible)
        self.character.see_through(self.body.visible and self.character.visible)
        self.show_pose(self.pose)
