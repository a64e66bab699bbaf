"""Scene SDFs, terrain height and rays against hand-computed values; gradients against finite differences."""

import math

import pytest
import torch

from latentrl.scenes import FAR_M, Box, Cylinder, Scene, SceneBatch, Seat, Stairs


def batch(*objects, floor=0.0, dtype=torch.float64) -> SceneBatch:
    return SceneBatch.from_scenes([Scene(tuple(objects), floor)], dtype=dtype)


def sdf(scene: SceneBatch, *points) -> list[float]:
    return scene.sdf(torch.tensor([points], dtype=torch.float64)).tolist()[0]


# a 2 x 1 x 1 m box standing on the floor at (0, 0): x in [-1, 1], y in [-0.5, 0.5], z in [0, 1]
BOX = Box((0.0, 0.0), (2.0, 1.0, 1.0))


def test_box_outside_inside_and_on_surface():
    s = batch(BOX)
    got = sdf(s, (3.0, 0.0, 0.5), (0.0, 2.5, 0.5), (0.0, 0.0, 3.0), (2.0, 1.5, 0.5), (2.0, 1.5, 2.0),
              (1.0, 0.0, 0.5), (0.0, 0.0, 0.5), (0.9, 0.0, 0.5), (0.0, 0.0, 1.0))
    expected = [2.0, 2.0, 2.0, math.sqrt(2.0), math.sqrt(3.0), 0.0, -0.5, -0.1, 0.0]
    assert got == pytest.approx(expected, abs=1e-12)


def test_yawed_box_is_the_box_turned():
    s = batch(Box((1.0, 1.0), (2.0, 1.0, 1.0), yaw_deg=90.0))  # now 1 m along x, 2 m along y
    got = sdf(s, (1.0, 3.0, 0.5), (3.0, 1.0, 0.5), (1.0, 1.9, 0.5))
    assert got == pytest.approx([1.0, 1.5, -0.1], abs=1e-12)
    s45 = batch(Box((0.0, 0.0), (2.0, 2.0, 1.0), yaw_deg=45.0))  # a corner now points along +x at sqrt(2)
    assert sdf(s45, (3.0, 0.0, 0.5)) == pytest.approx([3.0 - math.sqrt(2.0)], abs=1e-12)


def test_cylinder():
    s = batch(Cylinder((1.0, 0.0), radius=0.5, height=2.0))  # z in [0, 2]
    got = sdf(s, (3.0, 0.0, 1.0), (1.0, 0.0, 1.0), (1.0, 0.0, 1.9), (1.0, 0.0, 3.0), (4.0, 4.0, 4.0),
              (1.5, 0.0, 1.0))
    corner = math.hypot(math.hypot(3.0, 4.0) - 0.5, 2.0)
    assert got == pytest.approx([1.5, -0.5, -0.1, 1.0, corner, 0.0], abs=1e-12)


def test_seat_top_is_its_height():
    s = batch(Seat((0.0, 0.0), (0.5, 0.4), seat_height=0.45))
    assert sdf(s, (0.0, 0.0, 0.45), (0.0, 0.0, 1.0), (0.0, 0.0, 0.4)) == pytest.approx([0.0, 0.55, -0.05], abs=1e-12)
    assert s.height(torch.tensor([[[0.1, 0.1], [0.3, 0.0]]], dtype=torch.float64)).tolist() == [[0.45, 0.0]]


def test_stairs_surface_and_height():
    # 3 steps climbing along +y from (0, 0): treads y in [0, .3], [.3, .6], [.6, .9] at z .15, .3, .45, 1 m wide
    s = batch(Stairs((0.0, 0.0), 90.0, width=1.0, riser=0.15, tread=0.3, count=3))
    xy = torch.tensor([[[0.0, -0.1], [0.0, 0.1], [0.2, 0.45], [0.0, 0.8], [0.0, 1.0], [0.6, 0.5]]],
                      dtype=torch.float64)
    assert s.height(xy).tolist()[0] == pytest.approx([0.0, 0.15, 0.3, 0.45, 0.0, 0.0], abs=1e-12)
    got = sdf(s, (0.0, 0.1, 0.25), (0.0, 0.45, 0.3), (0.0, -0.2, 0.05), (0.0, 1.2, 0.2), (0.0, 0.75, 0.40),
              (0.0, 0.1, 0.15 + 0.3))
    # above tread 1 by 0.1; on tread 2; in front of the first riser; behind the back; inside the top step
    # 0.05 under its tread (its nearest face); above tread 1 by 0.3, nearest the top edge of step 2 (y .3, z .3)
    assert got == pytest.approx([0.1, 0.0, 0.2, 0.3, -0.05, math.hypot(0.2, 0.15)], abs=1e-12)


def test_minimum_over_objects_and_padding():
    scenes = [Scene((BOX,)), Scene((BOX, Cylinder((5.0, 0.0), 0.5, 1.0))), Scene(())]
    s = SceneBatch.from_scenes(scenes, dtype=torch.float64)
    assert s.box_mask.tolist() == [[True], [True], [False]] and s.cyl_mask.tolist() == [[False], [True], [False]]
    points = torch.tensor([[[4.0, 0.0, 0.5]]] * 3, dtype=torch.float64)
    assert s.sdf(points)[:, 0].tolist() == pytest.approx([3.0, 0.5, FAR_M])
    assert s.object_counts().tolist() == [1, 2, 0]


def test_floor_height_and_base():
    s = batch(Box((0.0, 0.0), (1.0, 1.0, 0.5)), Box((3.0, 0.0), (1.0, 1.0, 0.5), base=1.0), floor=0.2)
    xy = torch.tensor([[[0.0, 0.0], [3.0, 0.0], [9.0, 9.0]]], dtype=torch.float64)
    assert s.height(xy).tolist()[0] == pytest.approx([0.7, 1.5, 0.2])
    assert sdf(s, (3.0, 0.0, 0.8)) == pytest.approx([0.2])


def test_one_scene_answers_any_batch_and_shapes_are_kept():
    s = batch(BOX)
    points = torch.zeros(4, 5, 7, 3, dtype=torch.float64)
    points[..., 2] = 2.0
    assert s.sdf(points).shape == (4, 5, 7)
    assert torch.allclose(s.sdf(points), torch.ones(4, 5, 7, dtype=torch.float64))


def test_rays_hit_footprints():
    s = batch(BOX, Cylinder((0.0, 5.0), 1.0, 1.0))
    origin = torch.tensor([[0.0, -3.0]], dtype=torch.float64)
    corner = math.sqrt(0.5**2 + 2.5**2)
    dirs = torch.tensor([[[0.0, 1.0], [1.0, 0.0], [0.0, -1.0], [math.sqrt(0.5), math.sqrt(0.5)],
                          [0.5 / corner, 2.5 / corner]]], dtype=torch.float64)
    got = s.rays(origin, dirs, max_range=4.0).tolist()[0]
    # straight at the box (2.5 m); sideways, backwards and at 45 degrees (passing x = 1 at y = -2): nothing;
    # toward (0.5, -0.5), a point of the box's near face
    assert got == pytest.approx([2.5, 4.0, 4.0, 4.0, corner], abs=1e-12)
    far = s.rays(origin, dirs[:, :1], max_range=100.0).tolist()[0]
    assert far == pytest.approx([2.5])
    inside = s.rays(torch.tensor([[0.0, 5.5]], dtype=torch.float64), dirs, 4.0).tolist()[0]
    assert inside == pytest.approx([0.0] * 5)
    # the cylinder: from (0, 0) along +y, it starts at y = 4 (the box blocks first from inside it: 0)
    s2 = batch(Cylinder((0.0, 5.0), 1.0, 1.0))
    assert s2.rays(torch.tensor([[0.0, 0.0]], dtype=torch.float64), dirs[:, :1], 10.0).tolist() == [[4.0]]


def test_gradients_match_finite_differences():
    s = batch(Box((0.3, -0.2), (1.0, 0.6, 0.8), yaw_deg=30.0), Cylinder((2.0, 1.0), 0.4, 1.5),
              Stairs((-2.0, 0.0), 45.0, 1.0, 0.15, 0.3, 4))
    points = torch.tensor([[[1.7, 0.3, 0.2], [0.5, 0.1, 0.3], [2.1, 1.1, 0.9], [-1.5, 0.6, 0.7], [4.0, 3.0, 2.0],
                            [0.2, -0.9, 1.2]]], dtype=torch.float64, requires_grad=True)
    assert torch.autograd.gradcheck(s.sdf, (points,))
    grad, = torch.autograd.grad(s.sdf(points).sum(), points)
    assert torch.allclose(grad.norm(dim=-1), torch.ones(6, dtype=torch.float64), atol=1e-9)  # an SDF's |grad| is 1


def test_gradient_with_respect_to_the_scene():
    center = torch.tensor([[[0.0, 0.0, 0.5]]], dtype=torch.float64, requires_grad=True)
    half = torch.tensor([[[1.0, 0.5, 0.5]]], dtype=torch.float64, requires_grad=True)
    yaw = torch.tensor([[0.3]], dtype=torch.float64, requires_grad=True)
    points = torch.tensor([[[2.0, 0.7, 0.6], [0.2, 0.1, 0.4]]], dtype=torch.float64)

    def f(c, h, y):
        sb = SceneBatch.empty(1, 1, 0, dtype=torch.float64)
        sb.box_center, sb.box_half, sb.box_yaw = c, h, y
        sb.box_mask = torch.ones(1, 1, dtype=torch.bool)
        return sb.sdf(points)

    assert torch.autograd.gradcheck(f, (center, half, yaw))


def test_float32_on_the_batch_dtype():
    s = SceneBatch.from_scenes([Scene((BOX,))])
    assert s.box_center.dtype == torch.float32 and s.box_mask.dtype == torch.bool
    assert s.sdf(torch.tensor([[[3.0, 0.0, 0.5]]])).dtype == torch.float32


def test_set_rows_and_repeat():
    s = SceneBatch.from_scenes([Scene((BOX,))]).repeat(3)
    other = SceneBatch.from_scenes([Scene((Box((9.0, 9.0), (1.0, 1.0, 1.0)),))])
    s.set_rows(torch.tensor([1]), other)
    got = s.sdf(torch.tensor([[[9.0, 9.0, 0.5]]] * 3))[:, 0]
    assert got.tolist() == pytest.approx([math.hypot(8.0, 8.5), -0.5, math.hypot(8.0, 8.5)], rel=1e-6)
