"""What the viewer draws: a capsule body that follows the motion, a scene's objects, boxes dropped in ``play``.

In-process Viser servers (and a raw WebSocket client for the ctrl-click), no browser: the node poses are
checked against the motion's joints and the scene's primitives, and a dropped box against the env's SDF and
its scene observation.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from latentrl.render import save_motion_npz
from latentrl.scenes import Box, Cylinder, Scene, Seat, Stairs, scene_to_dict, scene_to_json
from tests.viewer.conftest import walking
from tests.viewer.test_security import RawClient, wait_for

SCENE = Scene((Box((1.0, 2.0), (0.6, 0.4, 1.0), 30.0), Cylinder((-1.0, 3.0), 0.25, 1.2),
               Seat((0.0, 4.0), (0.5, 0.5), 0.45, -90.0), Stairs((2.0, 0.0), 90.0, 1.2, 0.15, 0.3, 3)))
"""One of each object type: 1 box, 1 cylinder, 1 seat and 3 steps, 6 meshes."""


@pytest.fixture
def server(guarded_server):
    """These tests drive play's own server (tests/viewer/conftest.py)."""
    return guarded_server


def rotate(wxyz: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate (3,) ``v`` by the unit quaternion ``wxyz``."""
    w, u = wxyz[0], np.asarray(wxyz[1:], dtype=np.float64)
    return v + 2 * np.cross(u, np.cross(u, v) + w * v)


def assert_body_on(body, joints: np.ndarray) -> None:
    """Joint spheres at the joints, each bone's tube from its parent joint to its child joint."""
    from latentrl.viewer.body import BONE_RADII, BONES

    assert np.allclose(body.spheres.batched_positions, joints, atol=1e-6)
    centres, wxyzs, scales = (np.asarray(x, dtype=np.float64) for x in (
        body.tubes.batched_positions, body.tubes.batched_wxyzs, body.tubes.batched_scales))
    assert centres.shape == (21, 3) and wxyzs.shape == (21, 4)
    for b, (a, c) in enumerate(BONES):
        tip = centres[b] + rotate(wxyzs[b], np.array([0.0, 0.0, 0.5 * scales[b, 2]]))
        assert np.allclose(tip, joints[c], atol=1e-5), (b, tip, joints[c])
        assert np.allclose(centres[b], (joints[a] + joints[c]) / 2, atol=1e-6)
    assert np.allclose(scales[:, :2], np.stack((BONE_RADII, BONE_RADII), 1))


def test_the_capsule_body_follows_the_motion_and_its_feet_turn_green(server):
    from latentrl.motion.skeleton import FOOT_JOINTS
    from latentrl.render import CONTACT, LEFT
    from latentrl.viewer.body import BONES
    from latentrl.viewer.scene import SkeletonScene

    scene = SkeletonScene(server)
    assert scene.character.visible and not scene.body.visible  # body by default, skeleton on request
    joints = walking(10)
    for frame in (0, 9):
        scene.show_pose(joints[frame])
        assert_body_on(scene.character, joints[frame])
    left_foot_bone = int(np.nonzero(BONES[:, 1] == FOOT_JOINTS[0])[0][0])
    assert joints[9, FOOT_JOINTS[0], 2] < 0.01  # on the floor: the contact colour
    assert np.abs(scene.character.tubes.batched_colors[left_foot_bone].astype(int) - CONTACT).max() <= 12
    lifted = joints[9].copy()
    lifted[:, 2] += 0.5
    scene.show_pose(lifted)
    assert tuple(scene.character.tubes.batched_colors[left_foot_bone]) == LEFT  # in the air: its side's colour
    scene.set_skeleton_visible(True)  # the skeleton catches up with the pose it missed while hidden
    assert np.allclose(scene.joints.points, lifted) and scene.character.tubes.opacity is not None
    scene.set_body_visible(False)
    assert not scene.character.visible and scene.character.tubes.opacity is None


def test_object_meshes_are_the_scene_primitives():
    from latentrl.scenes.scene import SceneBatch
    from latentrl.viewer.objects import object_meshes

    meshes = object_meshes(SCENE)
    assert [m.kind for m in meshes] == ["box", "cylinder", "box", "box", "box", "box"]
    assert [m.object_index for m in meshes] == [0, 1, 2, 3, 3, 3]
    box, cylinder, seat = meshes[0], meshes[1], meshes[2]
    assert np.allclose(box.centre, (1.0, 2.0, 0.5)) and np.allclose(box.size, (0.6, 0.4, 1.0))
    assert math.isclose(box.yaw, math.radians(30))
    assert np.allclose(cylinder.centre, (-1.0, 3.0, 0.6)) and np.allclose(cylinder.size, (0.25, 0.25, 1.2))
    assert np.allclose(seat.size, (0.5, 0.5, 0.45))
    steps = meshes[3:]
    assert np.allclose([s.size[2] for s in steps], (0.15, 0.30, 0.45))  # each step from the floor up
    # every mesh's centre is inside the scene's SDF and its top face is where the terrain height says
    batch = SceneBatch.from_scenes([SCENE])
    centres = torch.tensor([m.centre for m in meshes], dtype=torch.float32)
    assert (batch.sdf(centres[None]) < 0).all()
    tops = batch.height(centres[None, :, :2])[0]
    assert torch.allclose(tops[[0, 2, 3, 4, 5]], torch.tensor([1.0, 0.45, 0.15, 0.30, 0.45]), atol=1e-6)


def test_view_draws_the_scene_a_motion_carries(server, tmp_path):
    from latentrl.viewer.objects import yaw_wxyz
    from latentrl.viewer.playback import Player
    from latentrl.viewer.sources import open_source

    joints = walking(40)
    path = save_motion_npz(tmp_path / "walk.npz", joints, texts=["walk"] * 40, scene=scene_to_json(SCENE))
    from latentrl.viewer.record import Recorder

    player = Player(server, open_source(path), Recorder(tmp_path / "view.gif", "view"), skeleton=True)
    assert player.recorder.scene == SCENE  # --record draws it too
    nodes = player.scene.objects.nodes
    assert len(nodes) == 6 and player.scene.body.visible
    assert np.allclose(nodes[0].position, (1.0, 2.0, 0.5)) and np.allclose(nodes[0].dimensions, (0.6, 0.4, 1.0))
    assert np.allclose(nodes[0].wxyz, yaw_wxyz(math.radians(30)))
    assert np.allclose(nodes[1].position, (-1.0, 3.0, 0.6)) and math.isclose(nodes[1].radius, 0.25)
    assert math.isclose(nodes[1].height, 1.2)
    for frame in (5, 31):
        player.frame = float(frame)
        player._draw()
        assert_body_on(player.scene.character, joints[frame])
        assert np.allclose(player.scene.joints.points, joints[frame])
    bare = save_motion_npz(tmp_path / "bare.npz", joints, texts=["walk"] * 40)
    player.source = open_source(bare)
    player.select(player.source.entries[0].label)
    assert player.scene.objects.nodes == [] and player.scene.world is None


def test_view_of_a_bad_scene_plays_on_the_bare_floor(server, tmp_path, capsys):
    from latentrl.viewer.playback import Player
    from latentrl.viewer.sources import open_source

    bad = scene_to_dict(SCENE)
    bad["objects"][0]["size"] = [0.6, -1.0, 1.0]
    import json

    path = save_motion_npz(tmp_path / "walk.npz", walking(20), texts=["walk"] * 20, scene=json.dumps(bad))
    player = Player(server, open_source(path))
    assert player.scene.objects.nodes == [] and player.clip.frames == 20
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "objects[0].size[1]" in err[0] and "drawing no scene" in err[0], err


def scene_controller(server, tiny_model, trained_scene: Scene | None, scene: Scene | None = None, recorder=None):
    """``play``'s env and controller on the tiny model, for a policy trained in ``trained_scene`` (None: flat)."""
    from latentrl.ppo.config import PolicyConfig
    from latentrl.ppo.policy import ActorCritic
    from latentrl.viewer.live import LiveController, play_env

    config = {"env": {"texts": ["walk"], **({"scene": scene_to_dict(trained_scene)} if trained_scene else {})}}
    env = play_env({"config": config}, tiny_model, None, "cpu", "reach", scene)
    torch.manual_seed(0)
    policy = ActorCritic(env.single_observation_space.shape[0], env.single_action_space.shape[0],
                         PolicyConfig(latent_dim=32), env.metadata["observation_layout"])
    return LiveController(server, env, policy, "test", "walk", seed=0, recorder=recorder)


def test_a_ctrl_click_drops_a_box_the_env_collides_with_and_the_policy_sees(server, tiny_model, capsys):
    from latentrl.envs.scene import NUM_RAYS, RAY_RANGE_M
    from latentrl.viewer.live import DROP_BOX_SIZE

    live = scene_controller(server, tiny_model, trained_scene=Scene())  # trained among objects: it sees them
    env = live.env
    assert env.observe_scene and env.scene is not None and live.scene.objects.nodes == []
    pelvis = live.pelvis()
    forward = env.history_world()[0, -1, 0, :2]  # the rays are cast from the pelvis; put the box 2 m ahead
    rays_before = env.scene.rays(env.history_world())[0]
    assert torch.allclose(rays_before, torch.full((NUM_RAYS,), RAY_RANGE_M))
    drop = pelvis[:2] + np.array([0.0, 2.0])
    client = RawClient(server.get_port())
    try:
        client.send(type="ScenePointerMessage", event_type="click", ray_origin=(float(drop[0]), float(drop[1]), 3.0),
                    ray_direction=(0.0, 0.0, -1.0), screen_pos=[[0.5, 0.5]], modifier="cmd/ctrl")
        wait_for(lambda: live.dropped == 1, "a ctrl-click drops a box")
        with live.lock:  # the click's callback holds it until the box is drawn
            pass
    finally:
        client.close()
    assert live.goal is None, "the ctrl-click set no goal"
    (box,) = env.scene.spec.objects
    assert np.allclose(box.center, drop) and box.size == DROP_BOX_SIZE
    inside = torch.tensor([[[drop[0], drop[1], 0.5]]], dtype=torch.float32)
    assert float(env.scene.batch.sdf(inside)) < 0  # the env collides with it
    assert len(live.scene.objects.nodes) == 1 and np.allclose(live.scene.objects.nodes[0].position[:2], drop)
    rays = env.scene.rays(env.history_world())[0]
    assert float(rays.min()) < 2.0 - DROP_BOX_SIZE[1] / 2 + 0.05 and float(rays.min()) > 1.0, (rays, forward)
    obs, *_ = env.step(torch.zeros(1, env.single_action_space.shape[0]))  # and steps on with the new scene
    start, stop = env.observation_layout["scene_rays"]
    assert float(obs[0, start:stop].min()) < RAY_RANGE_M
    assert "scene: 1 object, 1 dropped (the policy sees them)" in live.status_text()
    assert "box dropped at" in capsys.readouterr().out
    live.clear_boxes()
    assert env.scene.spec.objects == () and live.scene.objects.nodes == [] and live.dropped == 0


def test_play_scene_flag_and_drop_bounds(server, tiny_model):
    live = scene_controller(server, tiny_model, trained_scene=None, scene=SCENE)
    env = live.env
    assert not env.observe_scene, "a policy trained on the flat floor gets no scene observation"
    assert env.scene.spec == SCENE and len(live.scene.objects.nodes) == 6
    pelvis = live.pelvis()
    assert not live.drop_box(pelvis[:2] + 0.1) and "within" in live.message and live.dropped == 0
    assert not live.drop_box((pelvis[0] + 80.0, pelvis[1])) and "more than 50 m" in live.message
    assert live.drop_box((pelvis[0] - 2.0, pelvis[1])) and "dropped a box" in live.message
    assert "scene: 5 objects, 1 dropped (the policy does not see them" in live.status_text()
    assert len(env.scene.spec.objects) == 5 and len(live.scene.objects.nodes) == 7
    live.clear_boxes()
    assert env.scene.spec == SCENE and len(live.scene.objects.nodes) == 6


def test_a_flat_policy_plays_in_an_empty_scene_as_on_the_flat_floor(server, tiny_model):
    """play gives every env a scene so boxes can be dropped; empty, it observes and steps as the flat env."""
    from latentrl.viewer.live import SteeredReachEnv

    live = scene_controller(server, tiny_model, trained_scene=None)
    assert live.env.scene is not None and live.env.scene.spec == Scene()
    flat = SteeredReachEnv(1, motion=tiny_model, texts=list(live.env.texts), max_episode_steps=10**9,
                            autoreset_mode="Disabled")
    assert live.env.single_observation_space.shape == flat.single_observation_space.shape
    flat.set_text("walk")  # as the controller did
    o1, _ = live.env.reset(seed=3)
    o2, _ = flat.reset(seed=3)
    a = torch.randn(1, flat.single_action_space.shape[0], generator=torch.Generator().manual_seed(0))
    assert torch.equal(o1, o2)
    live.env.set_goal((0.5, 2.0))
    flat.set_goal((0.5, 2.0))
    for _ in range(3):
        assert torch.equal(live.env.step(a)[0], flat.step(a)[0])


def test_play_scene_flag_refuses_bad_files_in_one_line(capsys, tmp_path):
    from tests.viewer.test_commands import one_line_error

    pytest.importorskip("viser")
    one_line_error(capsys, ["play", "reach_walk_default", "--scene", str(tmp_path / "none.json")],
                   "--scene: scene file not found")
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "latentrl.scene/1", "objects": [{"type": "box", "center": [0, 1], "size": [1, 0, 1]}]}')
    one_line_error(capsys, ["play", "reach_walk_default", "--scene", str(bad)], "objects[0].size[1]")
    one_line_error(capsys, ["play", "reach_walk_default", "--scene", "random_obstacles"], "takes a scene file")


def test_a_play_recording_draws_the_scene_with_the_dropped_boxes(server, tiny_model, tmp_path):
    from PIL import Image

    from latentrl.viewer.record import Recorder

    recorder = Recorder(tmp_path / "play.gif", "play")
    live = scene_controller(server, tiny_model, trained_scene=None, recorder=recorder)
    assert recorder.scene is None  # an empty scene: nothing to draw
    pelvis = live.pelvis()
    assert live.drop_box((pelvis[0], pelvis[1] + 1.2))
    assert recorder.scene == live.env.scene.spec and len(recorder.scene.objects) == 1
    live.set_goal((pelvis[0] + 1.0, pelvis[1]))
    for _ in range(2):
        live._generate()
        while live.frames:
            live._show_next()
    with_box = recorder.write()
    recorder.path = tmp_path / "bare.gif"
    recorder.set_scene(None)
    bare = recorder.write()
    a, b = (np.asarray(Image.open(p).convert("RGB"), dtype=np.int16) for p in (with_box, bare))
    assert (np.abs(a - b).max(axis=-1) > 40).sum() > 200, "the recording does not show the dropped box"


def test_play_observes_as_the_policy_was_trained(tiny_model):
    """A policy trained among objects with a height grid gets both groups; a flat one or a blind one neither."""
    from latentrl.viewer.live import play_env

    trained = {"env": {"texts": ["walk"], "scene": scene_to_dict(SCENE), "height_grid": 3}}
    layout = play_env({"config": trained}, tiny_model, None, "cpu").observation_layout
    assert "scene_rays" in layout and layout["scene_height_grid"][1] - layout["scene_height_grid"][0] == 9
    flat = play_env({"config": {"env": {"texts": ["walk"]}}}, tiny_model, None, "cpu", "joystick", SCENE)
    assert "scene_rays" not in flat.observation_layout and flat.scene.spec == SCENE
    blind = {"env": {"texts": ["walk"], "scene": scene_to_dict(SCENE), "observe_scene": False}}
    env = play_env({"config": blind}, tiny_model, None, "cpu")  # trained blind among objects: no rays
    assert "scene_rays" not in env.observation_layout and not env.observe_scene and env.scene.spec == SCENE


def test_the_body_and_skeleton_checkboxes_take_only_true_or_false(server, motion_file, capsys):
    """Checkbox values as a raw client sends them switch the drawing; odd values stop nothing.

    Viser casts a value to the checkbox's type (``bool``) before the handler; the handler refuses anything
    else in one line.
    """
    from latentrl.viewer.playback import Player
    from latentrl.viewer.sources import open_source

    player = Player(server, open_source(motion_file))
    scene = player.scene
    client = RawClient(server.get_port())
    try:
        client.gui(player.show_skeleton, True)
        wait_for(lambda: scene.body.visible, "the skeleton checkbox shows the skeleton")
        for bad in ("yes", 3, None, [True], ""):
            client.gui(player.show_body, bad)
        client.gui(player.show_body, True)  # Viser casts a value to the checkbox's bool; the page goes on
        wait_for(lambda: scene.character.visible, "the body checkbox shows the body")
        client.gui(player.show_body, False)
        wait_for(lambda: not scene.character.visible, "the body checkbox hides the body")
        assert scene.body.visible
    finally:
        client.close()
    err = [line for line in capsys.readouterr().err.splitlines() if "ignored body" in line]
    assert len(err) <= 4 and all(len(line) < 200 for line in err), err


def test_a_foot_on_a_tread_counts_as_in_contact(server):
    """Contact colours read the terrain under each foot: on a 0.3 m step the foot is green, beside it not."""
    from latentrl.motion.skeleton import FOOT_JOINTS
    from latentrl.render import CONTACT
    from latentrl.viewer.body import BONES
    from latentrl.viewer.scene import SkeletonScene

    scene = SkeletonScene(server)
    scene.set_scene(Scene((Box((0.0, 0.0), (4.0, 4.0, 0.3)),)))  # a platform under the whole body
    joints = walking(1)[0]
    joints[:, 2] += 0.3
    scene.show_pose(joints)
    bone = int(np.nonzero(BONES[:, 1] == FOOT_JOINTS[0])[0][0])
    assert np.abs(scene.character.tubes.batched_colors[bone].astype(int) - CONTACT).max() <= 12
    scene.set_scene(None)
    scene.show_pose(joints)  # the same pose 0.3 m above the bare floor: in the air
    assert np.abs(scene.character.tubes.batched_colors[bone].astype(int) - CONTACT).max() > 60


def test_random_obstacles_are_not_replaced(tiny_model):
    """EnvScene.replace takes a fixed scene's place; obstacles drawn per episode refuse it in one line."""
    from latentrl.envs.reach import ReachLocationEnv
    from latentrl.errors import ConfigError

    env = ReachLocationEnv(2, motion=tiny_model, scene={"random_obstacles": {}})
    with pytest.raises(ConfigError, match="only a fixed scene can be replaced"):
        env.scene.replace(SCENE)
    fixed = ReachLocationEnv(2, motion=tiny_model, scene=Scene())
    fixed.scene.replace(SCENE)
    assert fixed.scene.spec == SCENE and int(fixed.scene.batch.object_counts()[0]) == 6


def test_joint_goal_targets_are_coloured_by_joint_at_their_own_height():
    from latentrl.render import WAYPOINT
    from latentrl.viewer.scene import GOAL_JOINT_COLOURS, waypoint_marks

    targets = np.array([[0.0, 1.0, 0.0], [0.1, 2.0, 0.0], [0.3, 2.5, 1.1]], dtype=np.float32)
    plain, colours = waypoint_marks(targets, None, 0.0)
    assert plain[:, 2].tolist() == pytest.approx([0.08] * 3) and colours == [WAYPOINT] * 3
    marks, colours = waypoint_marks(targets, np.array([0, 10, 21]), 0.0)
    assert marks[:, 2].tolist() == pytest.approx([0.08, 0.08, 1.1])  # the wrist's target at its height
    assert colours == [GOAL_JOINT_COLOURS[0], GOAL_JOINT_COLOURS[10], GOAL_JOINT_COLOURS[21]]
    assert len(set(colours)) == 3
    for bad in (np.array([0, 10]), np.array([0, 10, 5])):  # the wrong length, a joint no goal takes
        assert waypoint_marks(targets, bad, 0.0)[1] == [WAYPOINT] * 3


def test_view_draws_joint_goal_targets_where_they_are(server, tmp_path):
    from latentrl.viewer.playback import Player
    from latentrl.viewer.sources import open_source

    joints = walking(40)
    targets = np.array([[0.0, 0.5, 0.0], [0.3, 1.0, 1.2]], dtype=np.float32)
    path = save_motion_npz(tmp_path / "goals.npz", joints, texts=["walk"] * 40, waypoints=targets,
                           waypoint_joints=np.array([0, 21], dtype=np.int32))
    player = Player(server, open_source(path), None, skeleton=False)
    spheres = [h for h in player.scene.waypoints if "/waypoints/" in h.name]
    assert [tuple(np.round(h.position, 3)) for h in spheres] == [(0.0, 0.5, 0.08), (0.3, 1.0, 1.2)]


def test_the_scene_filter_checkbox_moves_the_noise_off_a_pillar_ahead_and_only_then(server):
    """``play``'s scene filter (the policy's stored ``eval.avoid``; a checkbox): off, the walk policy's mean action
    heads into a pillar on the way to the goal; on, that action is moved; a pillar far away leaves it alone."""
    from latentrl.motion.checkpoint import load_motion_model
    from latentrl.optim.avoid import AvoidSettings, band
    from latentrl.optim.refine import predict
    from latentrl.ppo import load_policy
    from latentrl.resources import policy_file
    from latentrl.scenes.contact import collision_cost
    from latentrl.scenes.scene import Cylinder
    from latentrl.viewer.live import LiveController, play_env

    model, loaded = load_motion_model("default"), load_policy(policy_file("reach_walk_default"))

    def controller(pillar_y: float) -> LiveController:
        world = Scene([Cylinder(center=(0.05, pillar_y), radius=0.25, height=1.8)])
        env = play_env(loaded.checkpoint, model, None, "cpu", "reach", world)
        live = LiveController(server, env, loaded.policy, "test", "walk", deterministic=True, seed=0,
                              avoid=AvoidSettings(steps=8))
        live.set_goal((0.0, 6.0))  # straight through the pillar
        return live

    def plan_intrusion(live: LiveController, action: torch.Tensor) -> float:
        z = torch.zeros(2, 1, *model.latent_shape)
        z[0] = action.reshape(1, *model.latent_shape)
        with torch.no_grad():
            plan = predict(model, live.env.step_inputs(), z)
        return float(collision_cost(plan, live.env.scene.batch, band(plan, 0.1)))

    near = controller(0.8)
    assert near.filtering.value is True and "scene filter on (8 steps)" in near.status_text()
    filtered = near._action()
    near.filtering.value = False
    plain_action = near._action()
    assert plan_intrusion(near, plain_action) > 0  # the policy alone plans into the pillar
    assert not torch.equal(filtered, plain_action)
    assert plan_intrusion(near, filtered) < plan_intrusion(near, plain_action)
    far = controller(20.0)
    assert torch.equal(far._action(), plain_action)  # nothing near: the policy's own action
    drawn = controller(0.8)
    drawn.avoid.samples = 16
    assert "scene filter on (8 steps, 16 draws first)" in drawn.status_text()
    assert plan_intrusion(drawn, drawn._action()) < plan_intrusion(drawn, plain_action)
