"""Collision and foot-terrain contact: the kernels, the reward terms and the optimizer's scene loss."""

import json

import pytest
import torch

from latentrl.errors import DataError
from latentrl.motion.skeleton import FOOT_JOINTS, JOINT_NAMES
from latentrl.optim.losses import constraint_loss, scene_costs, scene_loss
from latentrl.optim.problems import parse_suite, stack_targets
from latentrl.rewards import SCENE_TERMS, RewardComposer, RewardInputs
from latentrl.rewards.skills import skill_code
from latentrl.scenes import Box, Scene, SceneBatch, Stairs, scene_to_dict
from latentrl.scenes.contact import (
    SKIN_RADIUS_M,
    clearance_cost,
    collision_cost,
    contact_cost,
    foot_terrain_gap,
    penetration,
)

WALL = Box((0.0, 2.0), (4.0, 0.2, 2.0))  # y in [1.9, 2.1], z in [0, 2]
LEFT, RIGHT = FOOT_JOINTS


def pose(n=1, t=1, y=0.0, z=0.9, feet_z=(0.03, 0.03), feet_y=None) -> torch.Tensor:
    """(n, t, 22, 3): every joint at (0, y, z), the feet at their heights (and ``feet_y``)."""
    joints = torch.zeros(n, t, 22, 3)
    joints[..., 1], joints[..., 2] = y, z
    for j, h in zip(FOOT_JOINTS, feet_z):
        joints[..., j, 2] = h
        if feet_y is not None:
            joints[..., j, 1] = feet_y
    return joints


def test_penetration_is_depth_inside_the_skin():
    scene = SceneBatch.from_scenes([Scene((WALL,))])
    clear = pose(y=0.0)
    assert penetration(clear, scene).abs().sum() == 0 and collision_cost(clear, scene).tolist() == [0.0]
    joints = pose(y=1.85)  # 5 cm in front of the wall: inside the pelvis' 10 cm skin by 5 cm
    depth = penetration(joints, scene)[0, 0]
    skin = torch.tensor([SKIN_RADIUS_M[n] for n in JOINT_NAMES])
    assert torch.allclose(depth, (skin - 0.05).clamp(min=0), atol=1e-6)
    assert float(depth[0]) == pytest.approx(0.05, abs=1e-6)
    inside = pose(y=2.0)  # in the wall's middle: 0.1 deep, plus the skin
    assert float(penetration(inside, scene)[0, 0, 0]) == pytest.approx(0.1 + 0.10, abs=1e-6)
    assert float(collision_cost(joints, scene)[0]) == pytest.approx(float(depth.sum()), abs=1e-6)


def test_collision_cost_averages_frames():
    scene = SceneBatch.from_scenes([Scene((WALL,))])
    joints = torch.cat((pose(y=0.0), pose(y=1.85)), dim=1)
    assert float(collision_cost(joints, scene)[0]) == pytest.approx(float(penetration(pose(y=1.85), scene).sum()) / 2,
                                                                   abs=1e-6)


def test_foot_terrain_gap_reads_the_stairs():
    stairs = SceneBatch.from_scenes([Scene((Stairs((0.0, 0.0), 90.0, 1.0, 0.15, 0.3, 3),))])
    on_tread = pose(feet_z=(0.17, 0.40), feet_y=0.1)  # tread 1 is at 0.15: the lower foot 2 cm above it
    assert float(foot_terrain_gap(on_tread, stairs)[0, 0]) == pytest.approx(0.02, abs=1e-6)
    assert float(contact_cost(on_tread, stairs)[0]) == 0.0
    floating = pose(feet_z=(0.25, 0.40), feet_y=0.1)  # 10 cm above: 7 cm beyond the 3 cm threshold
    assert float(contact_cost(floating, stairs)[0]) == pytest.approx(0.07, abs=1e-6)
    sunk = pose(feet_z=(0.05, 0.40), feet_y=0.1)  # 10 cm into the tread
    assert float(foot_terrain_gap(sunk, stairs)[0, 0]) == pytest.approx(-0.10, abs=1e-6)
    assert float(contact_cost(sunk, stairs)[0]) == pytest.approx(0.07, abs=1e-6)
    flat = pose(feet_z=(0.25, 0.40), feet_y=-1.0)  # off the stairs: the floor at 0
    assert float(foot_terrain_gap(flat, stairs)[0, 0]) == pytest.approx(0.25, abs=1e-6)


def _inputs(joints: torch.Tensor, scene=None) -> RewardInputs:
    n = joints.shape[0]
    history = joints[:, :1].expand(n, 2, 22, 3)
    return RewardInputs(torch.cat((history, joints), 1), torch.zeros(n, 3), torch.zeros(n, dtype=torch.bool),
                        torch.ones(n), scene=scene)


def test_clearance_grows_from_the_margin_to_contact_and_caps_there():
    scene = SceneBatch.from_scenes([Scene((WALL,))])
    skin = max(SKIN_RADIUS_M.values())  # every joint at one point: the widest skin is nearest
    at = [0.0, 1.9 - skin - 0.30, 1.9 - skin - 0.10, 1.9 - skin, 2.0]  # far, beyond the margin, 10 cm in, touch, in
    costs = [float(clearance_cost(pose(y=y), scene)[0]) for y in at]
    assert costs[0] == 0.0 and costs[1] == 0.0
    assert costs[2] == pytest.approx(0.25 - 0.10, abs=1e-5) and costs[3] == pytest.approx(0.25, abs=1e-5)
    assert costs[4] == pytest.approx(0.25, abs=1e-6)  # capped: collision_cost takes over inside the skin
    two = torch.cat((pose(y=0.0), pose(y=at[2])), dim=1)  # one clear frame, one near: the mean over frames
    assert float(clearance_cost(two, scene)[0]) == pytest.approx((0.25 - 0.10) / 2, abs=1e-5)


def test_reward_terms_are_the_kernels_negated():
    scene = SceneBatch.from_scenes([Scene((WALL, Stairs((3.0, 0.0), 90.0, 1.0, 0.15, 0.3, 3)))])
    joints = torch.cat((pose(y=1.85, feet_z=(0.2, 0.3)), pose(y=0.0)), dim=0)
    comp = RewardComposer(terms=SCENE_TERMS, weights={"collision": 2.0, "terrain_contact": 3.0})
    total, values = comp(_inputs(joints, scene))
    assert torch.allclose(values["collision"], -collision_cost(joints, scene))
    assert torch.allclose(values["terrain_contact"], -contact_cost(joints, scene))
    assert torch.allclose(values["clearance"], -clearance_cost(joints, scene))
    assert values["collision"][0] < 0 and values["collision"][1] == 0
    assert float(values["terrain_contact"][0]) == pytest.approx(-(0.2 - 0.03), abs=1e-6)
    assert torch.allclose(total, 2.0 * values["collision"] + 3.0 * values["terrain_contact"])


def test_collision_and_clearance_share_one_sdf_query_per_step():
    calls = []

    class Counted(SceneBatch):
        def sdf(self, points):
            calls.append(tuple(points.shape))
            return super().sdf(points)

    plain = SceneBatch.from_scenes([Scene((WALL,))])
    scene = Counted.__new__(Counted)
    scene.__dict__.update(plain.__dict__)  # the same tensors, with sdf() counted
    joints = torch.cat((pose(y=1.85), pose(y=0.0)), dim=0)
    _, values = RewardComposer(terms=("collision", "clearance"))(_inputs(joints, scene))
    assert calls == [(2, 1, 22, 3)]  # one query of the new frames, shared
    assert torch.allclose(values["collision"], -collision_cost(joints, plain))
    assert torch.allclose(values["clearance"], -clearance_cost(joints, plain))


def test_scene_terms_weigh_nothing_by_default_and_need_a_scene():
    comp = RewardComposer(terms=SCENE_TERMS)
    assert comp.weights == {"collision": 0.0, "terrain_contact": 0.0, "clearance": 0.0}
    with pytest.raises(ValueError, match="reward term 'collision' needs RewardInputs.scene"):
        comp(_inputs(pose()))


def suite(scene=None, **extra) -> dict:
    problem = {"name": "p", "primitives": 1, "constraints": [{"type": "joint", "frame": 7, "joint": "pelvis",
                                                               "position": [0, 1, 0.9]}], **extra}
    if scene is not None:
        problem["scene"] = scene
    return {"format": "latentrl.constraints/1", "problems": [problem]}


def test_a_problem_carries_a_scene_inline_or_from_a_file(tmp_path):
    scene = Scene((WALL,))
    (p,) = parse_suite(suite(scene_to_dict(scene)))
    assert p.scene == scene and p.scene_weights == (0.1, 0.1)
    (tmp_path / "room.json").write_text(json.dumps(scene_to_dict(scene)))
    (q,) = parse_suite(suite("room.json", scene_weights={"collision": 2}), "s.json", tmp_path)
    assert q.scene == scene and q.scene_weights == (2.0, 0.1)
    (r,) = parse_suite(suite())
    assert r.scene is None and stack_targets([r]).scene is None


@pytest.mark.parametrize(("scene", "extra", "message"), [
    (5, {}, "s.json: problem 'p' scene: expected a scene file name or a latentrl.scene/1 object, got 5"),
    ({"format": "latentrl.scene/1", "objects": [{"type": "box"}]}, {},
     "s.json: problem 'p': scene: objects[0].center: missing; a box needs type, center, size"),
    (None, {"scene_weights": {"colision": 1}}, "s.json: problem 'p' scene_weights: expected an object with some "
                                               "of collision, contact, got {'colision': 1}"),
    (None, {"scene_weights": {"contact": -1}}, "s.json: problem 'p' scene_weights.contact: must be >= 0, got -1.0"),
    ("missing.json", {}, "scene file not found: "),
])
def test_bad_problem_scenes(tmp_path, scene, extra, message):
    with pytest.raises(DataError) as info:
        parse_suite(suite(scene, **extra), "s.json", tmp_path)
    assert str(info.value).startswith(message)


def test_scene_loss_is_added_only_where_a_problem_has_a_scene():
    probs = parse_suite({"format": "latentrl.constraints/1", "problems": [
        suite(scene_to_dict(Scene((WALL,))), scene_weights={"collision": 1.0, "contact": 0.5})["problems"][0],
        {**suite()["problems"][0], "name": "q"}]})
    targets = stack_targets(probs)
    assert targets.scene_weights.tolist() == [[1.0, 0.5], [0.0, 0.0]]
    joints = pose(n=2, t=8, y=1.85, feet_z=(0.2, 0.2))
    plain = stack_targets(probs[1:] * 2)
    costs = scene_costs(joints, targets)
    expected = costs["collision"][0] + 0.5 * costs["contact"][0]
    loss = constraint_loss(joints, targets)
    assert float(loss[0] - constraint_loss(joints, plain)[0]) == pytest.approx(float(expected), abs=1e-6)
    assert float(loss[1]) == float(constraint_loss(joints, plain)[1])
    assert float(scene_loss(joints, targets)[1]) == 0.0


def test_the_scene_loss_pushes_joints_out_of_the_wall():
    (p,) = parse_suite(suite(scene_to_dict(Scene((WALL,))), scene_weights={"collision": 1.0, "contact": 0.0}))
    targets = stack_targets([p])
    joints = pose(t=8, y=1.85).requires_grad_(True)
    scene_loss(joints, targets).sum().backward()
    pelvis_grad = joints.grad[0, :, 0]
    assert (pelvis_grad[:, 1] > 0).all()  # descending moves -y, away from the wall's face at y = 1.9
    assert torch.allclose(pelvis_grad[:, [0, 2]], torch.zeros(8, 2))


def test_foot_floor_skate_and_skill_read_the_tread_under_each_foot():
    tread = SceneBatch.from_scenes([Scene((Box((0.0, 0.0), (2.0, 2.0, 0.2)),))])  # a 0.2 m platform
    standing = pose(feet_z=(0.2, 0.2), feet_y=0.0).expand(1, 8, 22, 3).clone()
    sliding = standing.clone()
    sliding[:, :, LEFT, 0] += 0.01 * torch.arange(8, dtype=torch.float32)[None]  # the left foot slides 1 cm/frame
    comp = RewardComposer(terms=("foot_floor", "skate", "skill"), weights={"skill": 1.0})

    def inputs(joints, scene=None):
        x = _inputs(joints, scene)
        x.skill = torch.full((joints.shape[0],), skill_code("walk"))
        return x

    _, on = comp(inputs(standing, tread))
    _, flat = comp(inputs(standing))
    assert float(on["foot_floor"][0]) == 0.0 and float(on["skate"][0]) == 0.0  # standing on the tread
    assert float(flat["foot_floor"][0]) == pytest.approx(-(0.2 - 0.03), abs=1e-6)  # 20 cm over z = 0
    _, on = comp(inputs(sliding, tread))
    _, flat = comp(inputs(sliding))
    assert float(on["skate"][0]) < -1e-3 and float(flat["skate"][0]) == 0.0  # only the tread sees the slide
    # off the platform a scene's terrain is the floor: the same values as no scene, to the bit
    off = pose(feet_z=(0.0, 0.1), feet_y=-3.0).expand(1, 8, 22, 3).clone()
    off[:, :, LEFT, 0] += 0.01 * torch.arange(8, dtype=torch.float32)[None]
    _, a = comp(inputs(off, tread))
    _, b = comp(inputs(off))
    assert all(torch.equal(a[k], b[k]) for k in ("foot_floor", "skate", "skill"))


def test_the_foot_terms_share_one_terrain_query_per_step():
    tread = SceneBatch.from_scenes([Scene((Box((0.0, 0.0), (2.0, 2.0, 0.2)),))])
    joints = pose(feet_z=(0.22, 0.3), feet_y=0.0).expand(2, 8, 22, 3).clone()
    calls = []
    height = tread.height

    def counted(xy):
        calls.append(xy.shape)
        return height(xy)

    tread.height = counted
    x = _inputs(joints, tread)
    x.skill = torch.full((2,), skill_code("walk"))
    _, values = RewardComposer(terms=("foot_floor", "skate", "skill", "terrain_contact"))(x)
    assert len(calls) == 1  # one query for the last history frame and the new frames
    tread.height = height
    assert torch.equal(values["terrain_contact"], -contact_cost(joints, tread))
    assert torch.equal(values["foot_floor"], values["terrain_contact"])  # with a scene they measure the same gap
