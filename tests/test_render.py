"""latentrl.render: the shared motion .npz, the BVH export and the GIF/MP4 renderer (frames, pixels, decoding)."""

import numpy as np
import pytest

from latentrl.errors import DataError
from latentrl.motion.skeleton import JOINT_NAMES, PARENTS
from latentrl.render import (
    _SMPL_REST_OFFSETS,
    ZUP_TO_YUP,
    load_bvh,
    load_motion_npz,
    save_bvh,
    save_motion_npz,
)
from tests.helpers import walking_clip


def noisy_walk(frames: int = 40, seed: int = 0) -> np.ndarray:
    """A walking clip whose joints are jittered by ~1 cm, so bone lengths are not rigid (like generated motion)."""
    joints = walking_clip(frames, yaw=0.7)["joints"].numpy().astype(np.float64)
    return joints + 0.01 * np.random.default_rng(seed).standard_normal(joints.shape)


def t_pose(frames: int = 4, yaw: float = 0.5) -> np.ndarray:
    """The BVH rest pose itself, turned by ``yaw`` about z and walking along x."""
    rest = np.zeros((22, 3))
    rest[0] = [0.0, 0.0, 0.95]
    for j in range(1, 22):
        rest[j] = rest[PARENTS[j]] + _SMPL_REST_OFFSETS[j]
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return np.stack([rest @ rot.T + [0.1 * t, 0.2, 0.0] for t in range(frames)])


def motion_values(path) -> np.ndarray:
    """(T, 22, 6) channel values of our files (6 channels per joint, hierarchy order)."""
    lines = path.read_text().split("MOTION")[1].strip().splitlines()[2:]
    return np.array([line.split() for line in lines], dtype=np.float64).reshape(len(lines), 22, 6)


def test_bvh_round_trip_reproduces_joint_positions(tmp_path):
    joints = noisy_walk()
    out = save_bvh(tmp_path / "walk.bvh", joints, fps=30)
    back = load_bvh(out)
    assert back["joints"].shape == joints.shape and list(back["names"]) == list(JOINT_NAMES)
    assert np.abs(back["joints"] - joints).max() < 1e-3  # metres: under 1 mm (in practice ~1e-7)
    assert float(back["fps"]) == pytest.approx(30.0)
    assert list(back["parents"]) == list(PARENTS)


def test_bvh_is_y_up_centimetres_with_smpl_hierarchy(tmp_path):
    joints = noisy_walk(5)
    text = save_bvh(tmp_path / "walk.bvh", joints).read_text()
    assert text.startswith("HIERARCHY\nROOT pelvis\n")  # nothing before HIERARCHY: Blender requires it
    assert text.count("JOINT ") == 21 and text.count("End Site") == 5
    root = motion_values(tmp_path / "walk.bvh")[:, 0, :3]
    assert np.allclose(root, joints[:, 0] @ ZUP_TO_YUP.T * 100.0, atol=1e-4)  # pelvis height is +Y, in cm
    assert np.allclose(root[:, 1], joints[:, 0, 2] * 100.0, atol=1e-4)


def test_rest_pose_motion_has_zero_joint_rotations_and_root_yaw(tmp_path):
    path = save_bvh(tmp_path / "t.bvh", t_pose(yaw=0.5))
    values = motion_values(path)
    assert np.abs(values[:, 1:, 3:]).max() < 1e-4  # every joint at rest: no local rotation
    assert np.allclose(values[:, 0, 3:], [0.0, 0.0, np.degrees(0.5)], atol=1e-4)  # Z, X, Y: yaw about +Y
    assert np.abs(load_bvh(path)["joints"] - t_pose(yaw=0.5)).max() < 1e-6


def test_parser_reads_a_rotation_only_bvh(tmp_path):
    # A standard file: child joints carry rotations only, so OFFSETs place them.
    text = """HIERARCHY
ROOT hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT arm
  {
    OFFSET 10 0 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 5 0 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.5
0 100 0 0 0 0 0 0 0
0 100 0 90 0 0 0 0 0
"""
    path = tmp_path / "two.bvh"
    path.write_text(text)
    out = load_bvh(path)
    assert list(out["names"]) == ["hips", "arm"] and float(out["fps"]) == 2.0
    # file (Y-up, cm) -> ours (z up, m): frame 0 arm at x = 0.1 m, 1 m up; frame 1 the root turned 90 deg
    # about Y-up's z (= our -y), so the arm points up: 1.1 m.
    assert np.allclose(out["joints"][0], [[0.0, 0.0, 1.0], [0.1, 0.0, 1.0]], atol=1e-6)
    assert np.allclose(out["joints"][1], [[0.0, 0.0, 1.0], [0.0, 0.0, 1.1]], atol=1e-6)


def test_bvh_errors(tmp_path):
    with pytest.raises(DataError, match=r"joints. must be \(T, 22, 3\) with T > 0"):
        save_bvh(tmp_path / "x.bvh", np.zeros((3, 21, 3)))
    with pytest.raises(DataError, match="NaN"):
        save_bvh(tmp_path / "x.bvh", np.full((3, 22, 3), np.nan))
    bad = tmp_path / "bad.bvh"
    bad.write_text("HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 3 Xposition Yposition Zposition\n}\nMOTION\n"
                   "Frames: 2\nFrame Time: 0.1\n0 0 0\n")
    with pytest.raises(DataError, match="expected 2 frames x 3 channels"):
        load_bvh(bad)
    plain = tmp_path / "plain.txt"
    plain.write_text("nothing")
    with pytest.raises(DataError, match="not a BVH"):
        load_bvh(plain)


def test_motion_npz_round_trip(tmp_path):
    joints = noisy_walk(6).astype(np.float32)
    path = save_motion_npz(tmp_path / "m.npz", joints, texts=["walk"] * 6, actions=np.ones((1, 16)), success=True)
    back = load_motion_npz(path)
    assert np.array_equal(back["joints"], joints) and list(back["texts"]) == ["walk"] * 6
    assert back["actions"].shape == (1, 16) and bool(back["success"])


def test_gif_plays_in_real_time_at_its_size(tmp_path):
    from PIL import Image

    from latentrl.render import RENDER_SIZE, render_gif

    joints = t_pose(30, yaw=0.0).astype(np.float32)
    path = render_gif(tmp_path / "m.gif", joints, texts=["walk"] * 30, title="suite path 0 (walk)",
                      goals=np.array([[0.0, 1.0, 0.0], [0.0, 50.0, 0.0]]))
    with Image.open(path) as im:
        assert im.n_frames == 10 and im.info["duration"] == 100  # 30 frames at 30 fps, every 3rd: 1 s exactly
        assert im.size == (RENDER_SIZE, RENDER_SIZE)


def test_mp4_decodes_with_its_frame_count_and_size(tmp_path):
    imageio_ffmpeg = pytest.importorskip("imageio_ffmpeg")
    from latentrl.render import render_video

    path = render_video(tmp_path / "m.mp4", t_pose(31, yaw=0.3), texts=["walk"] * 31, size=320)
    reader = imageio_ffmpeg.read_frames(str(path))
    meta = next(reader)
    frames = [np.frombuffer(f, np.uint8).reshape(320, 320, 3) for f in reader]
    assert meta["size"] == (320, 320) and meta["fps"] == pytest.approx(30.0)
    assert len(frames) == 31  # every frame (MP4's default stride is 1)
    assert len(list(tmp_path.iterdir())) == 1  # the temporary file was renamed, nothing left beside it
    halved = render_video(tmp_path / "h.mp4", t_pose(31), stride=2, size=320)
    reader = imageio_ffmpeg.read_frames(str(halved))
    assert next(reader)["fps"] == pytest.approx(15.0) and sum(1 for _ in reader) == 16


def test_camera_puts_its_target_at_the_centre_and_a_metre_at_focal_over_distance():
    from latentrl.render import CAMERA_DISTANCE, FOCAL, RENDER_SIZE, Camera

    target = np.array([3.0, -2.0, 0.85])
    cam = Camera(target)
    pix, depth = cam.project(np.stack((target, target + [1.0, 0.0, 0.0], target + cam.up)))
    centre = RENDER_SIZE / 2
    metre = FOCAL * RENDER_SIZE / 2 / CAMERA_DISTANCE
    assert np.allclose(pix[0], [centre, centre]) and np.allclose(depth, CAMERA_DISTANCE)
    assert np.allclose(pix[1], [centre + metre, centre])  # +x (the body's right) is image right
    assert np.allclose(pix[2], [centre, centre - metre])  # up is image up


def test_a_known_joint_lands_on_its_pixel_in_its_side_colour():
    from latentrl.render import LEFT, RIGHT, Camera, follow_targets, render_frames

    joints = t_pose(1, yaw=0.0)  # arms stretched sideways, facing +y: seen from behind
    frame = np.asarray(next(render_frames(joints)))
    cam = Camera(follow_targets(joints)[0])
    for wrist, elbow, side in ((20, 18, LEFT), (21, 19, RIGHT)):
        x, y = np.round(cam.project((joints[0, wrist] + joints[0, elbow]) / 2)[0]).astype(int)
        pixel = frame[y, x].astype(int)
        shades = [np.clip(np.round(np.array(side) * k), 0, 255) for k in (0.62, 1.0, 1.3)]
        assert min(np.abs(pixel - s).max() for s in shades) <= 1, (x, y, pixel)
    left_x = cam.project(joints[0, 20])[0][0]
    assert left_x < frame.shape[1] / 2 < cam.project(joints[0, 21])[0][0]  # left hand on the image's left


def test_skeleton_style_and_bad_requests(tmp_path):
    from latentrl.render import render_frames, render_video

    body = np.asarray(next(render_frames(t_pose(1))))
    bones = np.asarray(next(render_frames(t_pose(1), style="skeleton")))
    assert body.shape == bones.shape and (body != bones).any()
    with pytest.raises(DataError, match=r"m\.avi: expected a \.gif or \.mp4 file"):
        render_video(tmp_path / "m.avi", t_pose(2))
    with pytest.raises(DataError, match="render style must be one of body, skeleton, got 'mesh'"):
        render_video(tmp_path / "m.gif", t_pose(2), style="mesh")
    with pytest.raises(DataError, match="render size must be a multiple of 16"):
        render_video(tmp_path / "m.gif", t_pose(2), size=100)
    assert not list(tmp_path.iterdir())


def test_viewer_and_renders_share_their_colours():
    from latentrl import render
    from latentrl.viewer import scene

    assert scene.side_colour(1) == render.LEFT and scene.side_colour(2) == render.RIGHT  # left_hip, right_hip
    assert tuple(scene.BONE_COLOURS[0, 0]) == render.LEFT  # pelvis -> left_hip


def test_foot_bones_turn_green_in_floor_contact_as_in_the_viewer():
    from latentrl.render import CONTACT, LEFT, RIGHT, FrameRenderer

    renderer = FrameRenderer(128)
    joints = t_pose(1)[0]
    feet = [b for b, (_, c) in enumerate(renderer.bones) if c in (10, 11)]  # ankle -> foot
    joints[:, 2] += 0.1 - joints[[10, 11], 2].min()  # both feet 10 cm up: their sides' colours
    assert [renderer._colours(joints)[b] for b in feet] == [LEFT, RIGHT]
    joints[:, 2] -= joints[[10, 11], 2].max()  # both on (or a little into) the floor: contact weight 1
    assert [renderer._colours(joints)[b] for b in feet] == [CONTACT, CONTACT]
