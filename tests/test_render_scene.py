"""latentrl.render draws the motion's scene (depth-ordered with the body) and its goal markers."""

import io

import numpy as np

from latentrl.motion.clip import MotionClip
from latentrl.render import (
    FACE_SHADES,
    GOAL,
    SCENE_COLOURS,
    WAYPOINT,
    Camera,
    _scaled,
    clip_frames,
    follow_targets,
    gif_bytes,
    render_clip,
    render_frames,
)
from latentrl.scenes import Box, Cylinder, Scene, Seat, Stairs, scene_to_json
from tests.test_render import t_pose


def shade_mask(frame: np.ndarray, colour, shades=FACE_SHADES, tol: int = 2) -> np.ndarray:
    """(H, W) pixels within ``tol`` of ``colour`` at any of ``shades``."""
    hits = [np.abs(frame.astype(int) - np.array(_scaled(colour, k))).max(axis=-1) <= tol for k in shades]
    return np.logical_or.reduce(hits)


def first_frame(joints, **kw) -> np.ndarray:
    return np.asarray(next(render_frames(joints, **kw)))


def test_a_box_beside_the_body_is_drawn_where_it_projects_and_not_without_the_scene():
    joints = t_pose(1, yaw=0.0)
    box = Box((1.2, 1.2), (0.6, 0.6, 0.8))
    with_box = first_frame(joints, scene=Scene((box,)))
    without = first_frame(joints)
    cam = Camera(follow_targets(joints)[0])
    x, y = np.round(cam.project(np.array([1.2, 1.2, 0.8]))[0]).astype(int)  # centre of its top face
    top = _scaled(SCENE_COLOURS[Box], FACE_SHADES[0])
    assert np.abs(with_box[y, x].astype(int) - top).max() <= 1, with_box[y, x]
    assert shade_mask(with_box, SCENE_COLOURS[Box]).sum() > 500  # top and two sides, at 480 px
    assert shade_mask(without, SCENE_COLOURS[Box]).sum() == 0
    ys, xs = np.nonzero(shade_mask(with_box, SCENE_COLOURS[Box]))
    assert xs.min() > with_box.shape[1] / 2  # right of the body (+x is image right), nowhere else
    # the scene given as its JSON text (what a motion file carries) draws the same picture
    assert (first_frame(joints, scene=scene_to_json(Scene((box,)))) == with_box).all()


def test_painters_order_puts_the_body_behind_a_wall_before_it_and_in_front_of_one_behind_it():
    joints = t_pose(1, yaw=0.0)  # pelvis at (0, 0.2, 0.95); the camera looks along +y from y ~ -2.2
    cam = Camera(follow_targets(joints)[0])
    x, y = np.round(cam.project(joints[0, 3])[0]).astype(int)  # spine1: the middle of the back
    near = first_frame(joints, scene=Scene((Box((0.0, -0.6), (1.0, 0.3, 1.6)),)))
    assert shade_mask(near, SCENE_COLOURS[Box])[y, x]  # the wall between camera and body hides the back
    far = first_frame(joints, scene=Scene((Box((0.0, 1.0), (1.6, 0.3, 2.0)),)))
    assert not shade_mask(far, SCENE_COLOURS[Box])[y, x]  # the body hides the wall behind it
    assert shade_mask(far, SCENE_COLOURS[Box]).sum() > 1000  # which shows around the body


def test_every_object_type_is_drawn_in_its_colour():
    joints = t_pose(1, yaw=0.0)
    objects = {Cylinder: Cylinder((-1.2, 1.5), 0.3, 1.2), Seat: Seat((1.2, 1.0), (0.5, 0.5), 0.45),
               Stairs: Stairs((-0.6, 2.5), 90.0, 1.2, 0.15, 0.3, 4)}
    frame = first_frame(joints, scene=Scene(tuple(objects.values())))
    for kind in objects:
        assert shade_mask(frame, SCENE_COLOURS[kind]).sum() > 200, kind.__name__


def test_waypoints_joint_targets_and_the_current_goal_are_marked():
    joints = t_pose(1, yaw=0.0)
    cam = Camera(follow_targets(joints)[0])
    raised = np.array([0.8, 1.5, 1.3])  # a hand target: a ball on a stalk
    on_floor = np.array([-0.8, 2.0, 0.0])  # a waypoint: a ring on the floor
    frame = first_frame(joints, goals=np.stack((raised, on_floor)))
    for point in (raised, on_floor):
        x, y = np.round(cam.project(point)[0]).astype(int)
        assert shade_mask(frame[y - 1 : y + 2, x - 1 : x + 2], WAYPOINT, (1.0, 1.3)).any(), point
    now = first_frame(joints, frame_goals=np.array([[0.8, 2.5, 0.0]]))
    x, y = np.round(cam.project(np.array([0.8, 2.5, 0.0]))[0]).astype(int)
    assert np.abs(now[y, x].astype(int) - GOAL).max() <= 1
    # a waypoint on a stair's tread is raised with it (a ring on the top step, not hidden under the stairs)
    stairs = Scene((Stairs((-1.0, 2.0), 90.0, 1.0, 0.2, 0.5, 3),))
    on_step = np.array([-1.0, 3.25, 0.0])  # the top tread, 0.6 m up
    frame = first_frame(joints, goals=on_step[None], scene=stairs)
    x, y = np.round(cam.project(on_step + [0, 0, 0.6])[0]).astype(int)
    assert shade_mask(frame[y - 1 : y + 2, x - 1 : x + 2], WAYPOINT, (1.0,)).any()


def test_a_clip_renders_with_its_scene_and_markers_and_an_in_memory_gif_decodes(tmp_path):
    from PIL import Image

    joints = t_pose(12, yaw=0.0)
    scene = Scene((Box((1.2, 1.2), (0.6, 0.6, 0.8)),))
    clip = MotionClip(joints, scene=scene_to_json(scene), waypoints=np.array([[0.0, 3.0, 0.0]], np.float32),
                      goals=np.array([[0.0, 3.0, 0.0]], np.float32), primitive=np.array([-1, -1] + [0] * 10, np.int32))
    frames = [np.asarray(f) for f in clip_frames(clip, stride=3, size=160)]
    assert len(frames) == 4 and frames[0].shape == (160, 160, 3)
    assert shade_mask(frames[0], SCENE_COLOURS[Box]).sum() > 20
    path = render_clip(tmp_path / "clip.gif", clip, size=160)
    with Image.open(path) as gif:
        assert gif.n_frames == 4 and gif.size == (160, 160)
    data = gif_bytes(clip_frames(clip, stride=3, size=160), fps=10)
    with Image.open(io.BytesIO(data)) as gif:
        assert gif.format == "GIF" and gif.n_frames == 4 and gif.info["duration"] == 100


def test_eval_render_draws_the_episodes_scene(eval_files, tmp_path):
    """``latentrl eval --scene FILE --render gif``: the episode GIF shows the scene's box in its colour."""
    import json

    from PIL import Image

    from latentrl.app.cli import main

    scene = tmp_path / "box.json"
    scene.write_text(scene_to_json(Scene((Box((0.8, 1.5), (0.6, 0.6, 0.9)),))))
    paths = tmp_path / "mini.json"
    paths.write_text(json.dumps([{"goal_location": [[0.0, 3.0, 0.0]], "goal_text": ["walk"]}]))
    out = tmp_path / "out"
    assert main(["eval", str(eval_files["policy"]), "--motion", str(eval_files["motion"]), "--paths", str(paths),
                 "--episodes", "1", "--max-steps", "2", "--device", "cpu", "--out", str(out), "--no-progress",
                 "--scene", str(scene), "--render", "gif"]) == 0
    with Image.open(out / "renders" / "mini_path0_ep000.gif") as gif:
        frame = np.asarray(gif.convert("RGB"))
    assert shade_mask(frame, SCENE_COLOURS[Box], tol=3).sum() > 200


def test_the_shadow_falls_on_the_platform_the_body_stands_on():
    from latentrl.render import SHADOW

    joints = t_pose(1, yaw=0.0)
    joints[..., 2] += 0.3  # standing on a 0.3 m platform
    frame = first_frame(joints, scene=Scene((Box((0.0, 0.2), (2.0, 2.0, 0.3)),)))
    cam = Camera(follow_targets(joints)[0] + [0.0, 0.0, 0.3])  # the camera rises with the terrain
    elbow = joints[0, 19].copy()  # the right elbow's shadow: on the top face, 0.3 m up
    elbow[2] = 0.3
    x, y = np.round(cam.project(elbow)[0]).astype(int)
    assert shade_mask(frame[y - 1 : y + 2, x - 1 : x + 2], SHADOW, (1.0,), tol=0).all()
