"""A mesh a user brings becomes scene boxes: the greedy cover on hand-made grids, known meshes, the command's errors."""

import json

import numpy as np
import pytest
import torch

from latentrl.errors import ConfigError, DataError
from latentrl.scenes import Box, Scene, SceneBatch, load_scene
from latentrl.scenes.mesh import MeshSettings, merge_boxes, mesh_to_scene

trimesh = pytest.importorskip("trimesh", reason="pip install 'latentrl[mesh]'")


def covered(shape, boxes) -> np.ndarray:
    """How many boxes cover each cell."""
    count = np.zeros(shape, dtype=int)
    for i0, j0, k0, i1, j1, k1 in boxes:
        count[i0:i1 + 1, j0:j1 + 1, k0:k1 + 1] += 1
    return count


def test_boxes_cover_every_filled_cell_once_and_nothing_else():
    rng = np.random.default_rng(0)
    for density in (0.1, 0.5, 0.9):
        filled = rng.random((7, 6, 5)) < density
        assert np.array_equal(covered(filled.shape, merge_boxes(filled)), filled.astype(int))
    assert merge_boxes(np.zeros((3, 3, 3), dtype=bool)) == []


def test_a_slab_on_legs_is_five_boxes_and_an_l_is_two():
    table = np.zeros((6, 4, 5), dtype=bool)
    table[:, :, 4] = True  # the top
    for i in (0, 5):
        for j in (0, 3):
            table[i, j, :4] = True
    boxes = merge_boxes(table)
    assert len(boxes) == 5 and boxes[0] == (0, 0, 4, 5, 3, 4)  # the top first, whole
    ell = np.zeros((4, 4, 1), dtype=bool)
    ell[:, 0] = True
    ell[0, :] = True
    assert np.array_equal(covered(ell.shape, merge_boxes(ell)), ell.astype(int)) and len(merge_boxes(ell)) == 2


def write_mesh(path, *parts) -> str:
    trimesh.util.concatenate(list(parts)).export(str(path))
    return str(path)


def box_mesh(extents, centre):
    mesh = trimesh.creation.box(extents=extents)
    mesh.apply_translation(centre)
    return mesh


def test_a_box_mesh_becomes_one_box_that_holds_it_within_a_voxel(tmp_path):
    """A 1.0 x 0.6 x 0.8 m crate at (2, 3) on the floor: one box standing on the floor, containing the crate and
    at most one voxel larger on each side; its SDF agrees with the crate's to a voxel."""
    file = write_mesh(tmp_path / "crate.stl", box_mesh((1.0, 0.6, 0.8), (2.0, 3.0, 0.4)))
    scene, info = mesh_to_scene(file, MeshSettings(voxel=0.1))
    (box,) = scene.objects
    assert info["boxes"] == 1 and box.base is None  # on the floor
    lo = np.array(box.center) - np.array(box.size[:2]) / 2
    hi = np.array(box.center) + np.array(box.size[:2]) / 2
    assert (lo <= [1.5 + 1e-9, 2.7 + 1e-9]).all() and (lo >= [1.4 - 1e-9, 2.6 - 1e-9]).all()
    assert (hi >= [2.5 - 1e-9, 3.3 - 1e-9]).all() and (hi <= [2.6 + 1e-9, 3.4 + 1e-9]).all()
    assert 0.8 - 1e-9 <= box.size[2] <= 0.9 + 1e-9
    exact = SceneBatch.from_scenes([Scene((Box((2.0, 3.0), (1.0, 0.6, 0.8)),))], dtype=torch.float64)
    voxels = SceneBatch.from_scenes([scene], dtype=torch.float64)
    points = torch.rand(1, 500, 3, dtype=torch.float64, generator=torch.Generator().manual_seed(0)) * 4 - 1
    points += torch.tensor([2.0, 3.0, 1.0], dtype=torch.float64)
    gap = exact.sdf(points) - voxels.sdf(points)
    assert float(gap.min()) >= -1e-9 and float(gap.max()) <= 0.1 * 3 ** 0.5  # boxes at least as close, by < a voxel


def test_a_table_on_a_floor_slab_y_up_is_its_top_and_legs(tmp_path):
    """A room mesh exported y up (glTF's axes) with a floor slab: the slab is dropped, the top floats at its
    height, the legs stand on the floor, and the terrain under the top is the top's upper face."""
    top = box_mesh((1.2, 0.8, 0.05), (0.0, 2.0, 0.725))
    legs = [box_mesh((0.05, 0.05, 0.7), (x, y, 0.35)) for x in (-0.55, 0.55) for y in (1.65, 2.35)]
    floor = box_mesh((6.0, 6.0, 0.02), (0.0, 2.0, -0.01))
    room = trimesh.util.concatenate([top, *legs, floor])
    room.apply_transform(np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], dtype=float))  # z up->y
    file = tmp_path / "room.glb"
    room.export(str(file))
    scene, info = mesh_to_scene(file, MeshSettings(voxel=0.05, up="y"))
    assert info["boxes"] == 5
    table_top, *leg_boxes = scene.objects
    assert table_top.base == pytest.approx(0.675) and table_top.size[:2] == pytest.approx((1.25, 0.85))
    assert all(b.base is None and b.size[2] == pytest.approx(0.675) for b in leg_boxes)
    height = SceneBatch.from_scenes([scene]).height(torch.tensor([[[0.0, 2.0], [0.0, 0.0]]]))
    assert height.tolist()[0] == pytest.approx([0.775, 0.0])


def test_scale_and_offset_place_the_mesh(tmp_path):
    file = write_mesh(tmp_path / "crate_cm.stl", box_mesh((100.0, 60.0, 80.0), (0.0, 0.0, 40.0)))
    scene, _ = mesh_to_scene(file, MeshSettings(voxel=0.1, scale=0.01, offset=(1.0, -2.0, 0.0)))
    assert scene.objects[0].center == pytest.approx((1.0, -2.0), abs=0.051)


def test_mesh_errors_name_the_file_and_the_fix(tmp_path):
    with pytest.raises(DataError, match=r"nothing\.stl: mesh file not found"):
        mesh_to_scene(tmp_path / "nothing.stl")
    junk = tmp_path / "junk.stl"
    junk.write_text("solid nothing\nendsolid\n")
    with pytest.raises(DataError, match=r"junk\.stl: (no triangles|not a mesh)"):
        mesh_to_scene(junk)
    cubes = [box_mesh((0.1, 0.1, 0.5), (x * 0.5, y * 0.5, 0.25)) for x in range(9) for y in range(9)]
    forest = write_mesh(tmp_path / "forest.stl", *cubes)
    with pytest.raises(DataError, match=r"forest\.stl: 81 boxes at --voxel 0\.1, more than the 64 .*larger --voxel"):
        mesh_to_scene(forest, MeshSettings(voxel=0.1))
    huge = write_mesh(tmp_path / "huge.stl", box_mesh((90.0, 90.0, 3.0), (0.0, 0.0, 1.5)))
    with pytest.raises(DataError, match=r"huge\.stl: .* voxels, more than 8,000,000; give a larger --voxel"):
        mesh_to_scene(huge, MeshSettings(voxel=0.02))
    for field, settings in (("voxel", MeshSettings(voxel=0.0)), ("up", MeshSettings(up="x")),
                            ("scale", MeshSettings(scale=float("nan")))):
        with pytest.raises(ConfigError, match=rf"^{field}: expected"):
            settings.check()


def test_latentrl_scene_from_mesh_writes_a_scene_every_reader_takes(tmp_path, capsys):
    from latentrl.app.cli import main

    file = write_mesh(tmp_path / "crate.obj", box_mesh((1.0, 0.6, 0.8), (0.0, 2.0, 0.4)))
    out = tmp_path / "crate.json"
    assert main(["scene", "from-mesh", file, "--out", str(out)]) == 0
    assert "-> 1 boxes" in capsys.readouterr().out
    scene = load_scene(out)
    assert len(scene.objects) == 1 and "crate.obj" in json.loads(out.read_text())["description"]
    # bad input: one line, exit 2, nothing written
    for args, message in ((["--voxel", "5"], "voxel: expected metres in [0.01, 1]"),
                          (["--out", str(tmp_path / "x.txt")], "--out: expected a .json scene file")):
        target = tmp_path / "bad.json"
        argv = ["scene", "from-mesh", file, "--out", str(target), *args]
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1
        assert not target.exists() and not (tmp_path / "x.txt").exists()
