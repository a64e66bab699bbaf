"""``latentrl scene from-mesh``: a mesh a user brings becomes a ``latentrl.scene/1`` file of boxes."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from latentrl.errors import ConfigError


@dataclass
class FromMeshRequest:
    """A mesh file, the scene file to write and how to voxelize (:class:`latentrl.scenes.mesh.MeshSettings`)."""

    mesh: str
    out: str
    voxel: float = 0.1
    scale: float = 1.0
    up: str = "z"
    offset: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    floor_height: float = 0.0
    max_boxes: int = 64


def from_mesh_command(req: FromMeshRequest) -> int:
    """Voxelize the mesh, merge its voxels into boxes, check the scene and write it atomically; print a summary."""
    from latentrl.safe_io import atomic_write_text
    from latentrl.scenes.mesh import MeshSettings, mesh_to_scene
    from latentrl.scenes.spec import parse_scene, scene_to_dict

    out = Path(req.out)
    if out.suffix != ".json":
        raise ConfigError(f"--out: expected a .json scene file, got {req.out!r:.80}")
    if out.is_dir():
        raise ConfigError(f"--out: {out} is a folder; expected a .json scene file")
    settings = MeshSettings(voxel=req.voxel, scale=req.scale, up=req.up, offset=tuple(req.offset),
                            floor_height=req.floor_height, max_boxes=req.max_boxes)
    scene, info = mesh_to_scene(req.mesh, settings)
    data = scene_to_dict(scene)
    data["description"] = f"{Path(req.mesh).name} at --voxel {req.voxel:g} ({info['voxels']} voxels)"
    parse_scene(data, str(out))  # what every reader will check
    atomic_write_text(out, json.dumps(data, indent=1) + "\n")
    print(f"{req.mesh}: {info['voxels']} voxels of {req.voxel:g} m -> {info['boxes']} boxes (mesh bounds "
          f"{info['bounds_min']} to {info['bounds_max']} m); wrote {out}")
    return 0
