"""Analytic signed distances and horizontal ray hits of the scene primitives, batched over envs.

Two primitives carry every scene object (:mod:`latentrl.scenes.scene` compiles seats and stairs into boxes):

- a **box** turned about +z by ``yaw`` (radians, counter-clockwise seen from above), given by its centre and
  half sizes;
- a vertical **cylinder**, given by its centre, radius and half height.

Shapes: a batch of N scenes holds B boxes (C cylinders) each, padded; points come as (N, P, 3). Every kernel
returns (N, P, B) (or (N, P, C)), one value per point and object, so a caller masks padding and reduces.
Distances are metres, negative inside. The formulas are the exact Euclidean distances (outside and inside),
differentiable everywhere except on the medial surfaces, where torch picks a subgradient.
"""

from __future__ import annotations

import torch

__all__ = ["box_footprint_contains", "box_sdf", "cylinder_footprint_contains", "cylinder_sdf", "ray_box_2d",
           "ray_circle_2d", "to_box_frame"]


def to_box_frame(points: torch.Tensor, center: torch.Tensor, yaw: torch.Tensor) -> torch.Tensor:
    """(N, P, 3) world points -> (N, P, B, 3) the same points in each box's frame (its centre, its yaw undone)."""
    d = points[:, :, None, :] - center[:, None, :, :]
    c, s = torch.cos(yaw)[:, None, :], torch.sin(yaw)[:, None, :]
    x = c * d[..., 0] + s * d[..., 1]
    y = -s * d[..., 0] + c * d[..., 1]
    return torch.stack((x, y, d[..., 2]), dim=-1)


def box_sdf(points: torch.Tensor, center: torch.Tensor, half: torch.Tensor, yaw: torch.Tensor) -> torch.Tensor:
    """Signed distance (N, P, B) of (N, P, 3) points to boxes: centres (N, B, 3), half sizes (N, B, 3), yaw (N, B).

    With ``q = |p_local| - half``: ``d = ||max(q, 0)|| + min(max(q_x, q_y, q_z), 0)``.
    """
    q = to_box_frame(points, center, yaw).abs() - half[:, None, :, :]
    outside = torch.linalg.vector_norm(q.clamp(min=0.0), dim=-1)
    inside = q.amax(dim=-1).clamp(max=0.0)
    return outside + inside


def cylinder_sdf(points: torch.Tensor, center: torch.Tensor, radius: torch.Tensor,
                 half_height: torch.Tensor) -> torch.Tensor:
    """Signed distance (N, P, C) to vertical cylinders: centres (N, C, 3), radii (N, C), half heights (N, C).

    With ``a = ||p_xy - c_xy|| - r`` and ``b = |p_z - c_z| - h``: ``d = ||max((a, b), 0)|| + min(max(a, b), 0)``.
    """
    d = points[:, :, None, :] - center[:, None, :, :]
    a = torch.linalg.vector_norm(d[..., :2], dim=-1) - radius[:, None, :]
    b = d[..., 2].abs() - half_height[:, None, :]
    q = torch.stack((a, b), dim=-1)
    return torch.linalg.vector_norm(q.clamp(min=0.0), dim=-1) + q.amax(dim=-1).clamp(max=0.0)


def box_footprint_contains(xy: torch.Tensor, center: torch.Tensor, half: torch.Tensor,
                           yaw: torch.Tensor) -> torch.Tensor:
    """(N, P, B) bool: the (N, P, 2) points lie inside each box's footprint seen from above (edges included)."""
    points = torch.cat((xy, torch.zeros_like(xy[..., :1])), dim=-1)
    local = to_box_frame(points, center, yaw)
    return (local[..., 0].abs() <= half[:, None, :, 0]) & (local[..., 1].abs() <= half[:, None, :, 1])


def cylinder_footprint_contains(xy: torch.Tensor, center: torch.Tensor, radius: torch.Tensor) -> torch.Tensor:
    """(N, P, C) bool: the (N, P, 2) points lie inside each cylinder's disc seen from above (edge included)."""
    return torch.linalg.vector_norm(xy[:, :, None, :] - center[:, None, :, :2], dim=-1) <= radius[:, None, :]


def ray_box_2d(origin: torch.Tensor, direction: torch.Tensor, center: torch.Tensor, half: torch.Tensor,
               yaw: torch.Tensor) -> torch.Tensor:
    """(N, R, B) distance along each ray to each box's footprint (0 from inside it, +inf when missed).

    ``origin`` (N, 2), ``direction`` (N, R, 2) unit vectors; the slab method in each box's frame.
    """
    o = torch.cat((origin, torch.zeros_like(origin[:, :1])), dim=-1)[:, None, :]  # (N, 1, 3)
    o = to_box_frame(o, center, yaw)[:, 0, :, :2]  # (N, B, 2)
    c, s = torch.cos(yaw)[:, None, :], torch.sin(yaw)[:, None, :]  # (N, 1, B)
    dx, dy = direction[..., 0:1], direction[..., 1:2]  # (N, R, 1)
    local = torch.stack((c * dx + s * dy, -s * dx + c * dy), dim=-1)  # (N, R, B, 2)
    tiny = torch.full_like(local, 1e-12)
    safe = torch.where(local.abs() < 1e-12, torch.where(local < 0, -tiny, tiny), local)
    h = half[:, None, :, :2]
    t1 = (-h - o[:, None]) / safe
    t2 = (h - o[:, None]) / safe
    near = torch.minimum(t1, t2).amax(dim=-1)
    far = torch.maximum(t1, t2).amin(dim=-1)
    hit = (far >= near) & (far >= 0)
    return torch.where(hit, near.clamp(min=0.0), torch.full_like(near, float("inf")))


def ray_circle_2d(origin: torch.Tensor, direction: torch.Tensor, center: torch.Tensor,
                  radius: torch.Tensor) -> torch.Tensor:
    """(N, R, C) distance along each ray to each disc (0 from inside it, +inf when missed).

    ``origin`` (N, 2), ``direction`` (N, R, 2) unit vectors, ``center`` (N, C, >=2), ``radius`` (N, C).
    """
    m = origin[:, None, :] - center[..., :2]  # (N, C, 2)
    b = (direction[:, :, None, :] * m[:, None]).sum(-1)  # (N, R, C)
    c = (m * m).sum(-1)[:, None, :] - radius[:, None, :] ** 2  # (N, 1, C)
    disc = b * b - c
    root = torch.sqrt(disc.clamp(min=0.0))
    t_near, t_far = -b - root, -b + root
    hit = (disc >= 0) & (t_far >= 0)
    return torch.where(hit, t_near.clamp(min=0.0), torch.full_like(t_near, float("inf")))
