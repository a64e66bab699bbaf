"""A scene from a mesh a user brings (a room, a table): voxelized, then merged into the scene's boxes.

Why boxes: every part of latentrl reads a scene as boxes and cylinders (the batched SDF, the terrain height,
the rays, the renderers, the viewer, ``paths.png``), so a mesh turned into boxes works everywhere at once, with
the same step cost as a hand-made scene of as many objects. The mesh is voxelized by trimesh (``pip install
'latentrl[mesh]'``) at ``voxel`` metres, its inside filled, and the filled voxels merged greedily into as few
axis-aligned boxes as the sweep finds (:func:`merge_boxes`). Each box covers its voxels whole, so the boxes hold
the mesh and reach at most one voxel beyond its surface: the collision checks err on the safe side.

The scene's floor is not an object: voxels whose centre lies within half a voxel of the floor (a room's floor
slab, a chair's feet) are dropped, and a box that starts within one voxel of the floor stands on it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from latentrl.errors import ConfigError, DataError
from latentrl.scenes.scene import Box, Scene
from latentrl.scenes.spec import MAX_COORD_M, MAX_OBJECTS, MAX_SIZE_M

MAX_VOXELS = 8_000_000
"""Cells of the voxel grid at most (its bounding box over ``voxel``³): 8 M booleans, a few seconds to merge."""
MAX_MESH_BYTES = 256 << 20
"""Largest mesh file read."""
UP_AXES = ("z", "y")


@dataclass
class MeshSettings:
    """How a mesh becomes a scene (``latentrl scene from-mesh``; docs/scenes.md)."""

    voxel: float = 0.1
    """Voxel edge, metres (0.01-1): the boxes reach at most this far beyond the mesh."""
    scale: float = 1.0
    """Multiplies the mesh's coordinates first (0.01 for a mesh in centimetres)."""
    up: str = "z"
    """The mesh's up axis: ``z`` (latentrl's, Blender's) or ``y`` (glTF's, most OBJ exports; turned to z up)."""
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    """Metres added after scaling and turning: where the mesh's origin goes in the scene."""
    floor_height: float = 0.0
    max_boxes: int = MAX_OBJECTS

    def check(self) -> None:
        """One-line :class:`ConfigError` for a setting out of range."""
        if not 0.01 <= self.voxel <= 1.0:
            raise ConfigError(f"voxel: expected metres in [0.01, 1], got {self.voxel:g}")
        if not 1e-4 <= self.scale <= 1e4:
            raise ConfigError(f"scale: expected a factor in [0.0001, 10000], got {self.scale:g}")
        if self.up not in UP_AXES:
            raise ConfigError(f"up: expected one of {', '.join(UP_AXES)}, got {self.up!r:.20}")
        if not all(np.isfinite(v) and abs(v) <= MAX_COORD_M for v in self.offset):
            raise ConfigError(f"offset: expected three finite metres within ±{MAX_COORD_M:g}, got {self.offset}")
        if not 1 <= self.max_boxes <= MAX_OBJECTS:
            raise ConfigError(f"max_boxes: expected 1-{MAX_OBJECTS} (a scene's objects at most), got {self.max_boxes}")


def merge_boxes(filled: np.ndarray) -> list[tuple[int, int, int, int, int, int]]:
    """Cover the True cells of a (X, Y, Z) grid with disjoint boxes ``(i0, j0, k0, i1, j1, k1)`` (inclusive).

    Greedy, from the top down: from the highest free cell (then lowest y, then x), a run along x, grown along y
    while the whole run is free, then down along z while the whole rectangle is. A table top is taken before its
    legs (one box each: 5, where a bottom-up sweep cuts the top around the legs into 9); a wall is one box.
    """
    todo = np.array(filled, dtype=bool, copy=True)
    nx, ny, nz = todo.shape
    boxes = []
    for k, j, i in np.argwhere(todo.transpose(2, 1, 0)[::-1]):
        k = nz - 1 - k
        if not todo[i, j, k]:
            continue
        i1 = i
        while i1 + 1 < nx and todo[i1 + 1, j, k]:
            i1 += 1
        j1 = j
        while j1 + 1 < ny and todo[i:i1 + 1, j1 + 1, k].all():
            j1 += 1
        k0 = k
        while k0 > 0 and todo[i:i1 + 1, j:j1 + 1, k0 - 1].all():
            k0 -= 1
        todo[i:i1 + 1, j:j1 + 1, k0:k + 1] = False
        boxes.append((int(i), int(j), int(k0), int(i1), int(j1), int(k)))
    return boxes


def load_mesh(path: str | Path, settings: MeshSettings):
    """The mesh of ``path`` (STL, OBJ, PLY, OFF, GLB/glTF: trimesh's loaders) scaled, turned z up and offset."""
    try:
        import trimesh
    except ImportError:
        raise ConfigError("a mesh needs trimesh: pip install 'latentrl[mesh]'") from None
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: mesh file not found" if not path.exists() else f"{path}: not a regular file")
    if path.stat().st_size > MAX_MESH_BYTES:
        raise DataError(f"{path}: {path.stat().st_size:,} bytes is larger than the {MAX_MESH_BYTES >> 20} MiB a "
                        "mesh may have")
    try:
        mesh = trimesh.load(str(path), force="mesh")
    except Exception as exc:  # noqa: BLE001 - trimesh raises many types for unreadable files
        raise DataError(f"{path}: not a mesh trimesh can read ({type(exc).__name__}: {str(exc)[:80]})") from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise DataError(f"{path}: no triangles in the file (expected a mesh: STL, OBJ, PLY, OFF, GLB)")
    if not np.isfinite(mesh.vertices).all():
        raise DataError(f"{path}: vertices with NaN or infinite coordinates")
    mesh = mesh.copy()
    mesh.apply_scale(settings.scale)
    if settings.up == "y":  # glTF's y up -> z up: (x, y, z) -> (x, -z, y)
        mesh.apply_transform(np.array([[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]], dtype=float))
    mesh.apply_translation(settings.offset)
    return mesh


def mesh_to_scene(path: str | Path, settings: MeshSettings | None = None) -> tuple[Scene, dict[str, float]]:
    """The boxes of the mesh in ``path`` as a scene, and what was done (``voxels``, ``boxes``, the bounds)."""
    settings = settings or MeshSettings()
    settings.check()
    mesh = load_mesh(path, settings)
    lo, hi = mesh.bounds
    pitch = settings.voxel
    cells = np.prod(np.ceil((hi - lo) / pitch) + 1)
    if cells > MAX_VOXELS:
        raise DataError(f"{path}: a {(hi - lo).round(2).tolist()} m mesh at --voxel {pitch:g} is {cells:,.0f} voxels, "
                        f"more than {MAX_VOXELS:,}; give a larger --voxel (or --scale if its unit is not metres)")
    if float(np.max(hi - lo)) > MAX_SIZE_M or float(np.max(np.abs([lo, hi]))) > MAX_COORD_M:
        raise DataError(f"{path}: the mesh spans {lo.round(2).tolist()} to {hi.round(2).tolist()} m, more than a scene "
                        f"holds ({MAX_SIZE_M:g} m objects within ±{MAX_COORD_M:g} m); check --scale and --offset")
    grid = mesh.voxelized(pitch).fill()
    filled = np.asarray(grid.matrix, dtype=bool)
    origin = np.asarray(grid.transform, dtype=float)[:3, 3]  # the centre of cell (0, 0, 0)
    centre_z = origin[2] + pitch * np.arange(filled.shape[2])
    floor = settings.floor_height
    filled[:, :, centre_z <= floor + pitch / 2] = False  # the floor is no object (a room's slab, the feet's layer)
    cover = merge_boxes(filled)
    if len(cover) > settings.max_boxes:
        raise DataError(f"{path}: {len(cover)} boxes at --voxel {pitch:g}, more than the {settings.max_boxes} a scene "
                        "may have; give a larger --voxel, or leave out detail the body never reaches")
    objects = []
    for i0, j0, k0, i1, j1, k1 in cover:
        low = origin + pitch * (np.array([i0, j0, k0]) - 0.5)
        high = origin + pitch * (np.array([i1, j1, k1]) + 0.5)
        on_floor = low[2] <= floor + pitch * 1.01
        base = floor if on_floor else float(low[2])
        objects.append(Box(center=(round(float(low[0] + high[0]) / 2, 6), round(float(low[1] + high[1]) / 2, 6)),
                           size=(round(float(high[0] - low[0]), 6), round(float(high[1] - low[1]), 6),
                                 round(float(high[2]) - base, 6)),
                           base=None if on_floor else round(base, 6)))
    info = {"voxels": int(filled.sum()), "boxes": len(objects), "voxel": pitch,
            "bounds_min": lo.round(4).tolist(), "bounds_max": hi.round(4).tolist()}
    return Scene(tuple(objects), floor), info
