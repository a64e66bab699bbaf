"""Scene kernels shared by rewards, the noise optimizer and the evaluation: collision and foot-terrain contact.

DART's scene losses (``optim_scene_mld.py``, paper eq. 13-14), on analytic SDFs instead of a voxel grid:

- **collision** (``cons_coll``): a joint is in collision when the scene's signed distance at it is below its
  *skin radius* (:data:`SKIN_RADIUS_M`, roughly the body's half-thickness around that joint), by
  ``max(0, skin - sdf)`` metres;
- **contact** (``cons_cont``): the lower foot's height above the terrain under it should stay within the
  contact threshold: ``max(0, |min_f (z_f - height(xy_f))| - threshold)``.

Joints are world coordinates, (N, T, 22, 3); the scene batch has N rows or one.
"""

from __future__ import annotations

import torch

from latentrl.constants import CONTACT_HEIGHT_M
from latentrl.motion.contacts import foot_positions
from latentrl.motion.skeleton import JOINT_NAMES
from latentrl.scenes.scene import SceneBatch

SKIN_RADIUS_M: dict[str, float] = {
    "pelvis": 0.10, "left_hip": 0.08, "right_hip": 0.08, "spine1": 0.10, "left_knee": 0.06, "right_knee": 0.06,
    "spine2": 0.10, "left_ankle": 0.04, "right_ankle": 0.04, "spine3": 0.10, "left_foot": 0.02,
    "right_foot": 0.02, "neck": 0.05, "left_collar": 0.05, "right_collar": 0.05, "head": 0.09,
    "left_shoulder": 0.05, "right_shoulder": 0.05, "left_elbow": 0.04, "right_elbow": 0.04, "left_wrist": 0.03,
    "right_wrist": 0.03,
}
"""Joint -> skin radius, metres: a joint closer than this to an object's surface (or inside it) collides.
The feet's is small so that a foot standing on a step or a seat (its joint 2-5 cm above the tread) is contact,
not collision."""


_SKIN_CACHE: dict[tuple[torch.device, torch.dtype], torch.Tensor] = {}


def skin_radii(like: torch.Tensor) -> torch.Tensor:
    """(22,) :data:`SKIN_RADIUS_M` in joint order, on ``like``'s device and dtype.

    Cached per device and dtype, so an env step builds no tensor from host data (a CUDA graph could not
    capture that copy).
    """
    key = (like.device, like.dtype)
    if key not in _SKIN_CACHE:
        _SKIN_CACHE[key] = torch.tensor([SKIN_RADIUS_M[name] for name in JOINT_NAMES], dtype=like.dtype,
                                        device=like.device)
    return _SKIN_CACHE[key]


def penetration(joints: torch.Tensor, scene: SceneBatch, skin: torch.Tensor | None = None,
                sdf: torch.Tensor | None = None) -> torch.Tensor:
    """(N, T, J) how far each joint is inside its skin radius of the nearest object, metres (0 when clear).

    ``skin``: (J,) radii (default :func:`skin_radii`); ``sdf``: ``scene.sdf(joints)`` when the caller has it.
    """
    skin = skin_radii(joints) if skin is None else skin
    return (skin - (scene.sdf(joints) if sdf is None else sdf)).clamp(min=0.0)


def collision_cost(joints: torch.Tensor, scene: SceneBatch, skin: torch.Tensor | None = None,
                   sdf: torch.Tensor | None = None) -> torch.Tensor:
    """(N,) DART's ``cons_coll``: the penetration summed over joints, averaged over frames, metres (>= 0)."""
    return penetration(joints, scene, skin, sdf).sum(dim=-1).mean(dim=-1)


CLEARANCE_M = 0.25
"""Default margin of :func:`clearance_cost`: how far beyond its skin radius a joint should keep from objects."""


def clearance_cost(joints: torch.Tensor, scene: SceneBatch, margin: float = CLEARANCE_M,
                   skin: torch.Tensor | None = None, sdf: torch.Tensor | None = None) -> torch.Tensor:
    """(N,) how far the body's nearest joint comes inside ``margin`` beyond its skin, averaged over frames (>= 0).

    Why: :func:`collision_cost` is 0 until a joint touches, so it says nothing about an object ahead; this cost
    grows as the body closes in (0 at ``margin`` from the skin, ``margin`` at contact), a gradient that lets a
    policy learn to keep away before it collides. Meant for obstacles: on stairs and seats the feet touch on purpose.
    """
    skin = skin_radii(joints) if skin is None else skin
    nearest = ((scene.sdf(joints) if sdf is None else sdf) - skin).amin(dim=-1)  # (N, T)
    return (margin - nearest).clamp(min=0.0, max=margin).mean(dim=-1)


def foot_terrain_gap(joints: torch.Tensor, scene: SceneBatch) -> torch.Tensor:
    """(N, T) the lower foot's height above the terrain under it, metres (negative: sunk into it)."""
    feet = foot_positions(joints)  # (N, T, 2, 3)
    return (feet[..., 2] - scene.height(feet[..., :2])).amin(dim=-1)


def contact_cost(joints: torch.Tensor, scene: SceneBatch, threshold: float = CONTACT_HEIGHT_M) -> torch.Tensor:
    """(N,) DART's ``cons_cont``: mean over frames of ``max(0, |foot_terrain_gap| - threshold)``, metres (>= 0)."""
    return (foot_terrain_gap(joints, scene).abs() - threshold).clamp(min=0.0).mean(dim=-1)


SCENE_METRICS: tuple[str, ...] = ("collision", "scene_penetration_cm", "scene_penetration_max_cm")
"""The per-episode scene metrics of :func:`scene_metrics`, as the evaluation report names them."""


def scene_metrics(joints: torch.Tensor, scene: SceneBatch) -> dict[str, float]:
    """One episode's scene metrics from its (T, 22, 3) world joints and its one-row scene.

    ``collision``: 1 when any joint came deeper than its skin radius into an object at any frame, else 0 (its
    mean over episodes is the collision rate); ``scene_penetration_cm``: the deepest joint's depth per frame,
    averaged over frames; ``scene_penetration_max_cm``: the deepest depth of the episode.
    """
    depth = penetration(torch.as_tensor(joints, dtype=torch.float32)[None], scene)[0]  # (T, 22)
    deepest = depth.amax(dim=-1)
    return {"collision": float(deepest.max() > 0), "scene_penetration_cm": float(deepest.mean()) * 100.0,
            "scene_penetration_max_cm": float(deepest.max()) * 100.0}
