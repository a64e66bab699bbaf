"""Motion-quality and task metrics as pure tensor functions (known answers in tests/evaluation).

Inputs are world joints ``(..., T, 22, 3)`` in metres, z up, floor at ``floor`` (default 0),
at ``fps`` frames per second. Units are in the function names where they could be ambiguous.

DART's definitions (``evaluation/goal_reach.py``, ``evaluation/inbetween.py``):

- foot skate: displacement of the foot joints (10, 11) between consecutive frames, weighted by
  ``2 - 2^clamp(h / 0.03, 0, 1)`` with ``h`` the higher of the two frames' foot heights (weight 1
  on the floor, 0 above 3 cm), averaged over transitions and feet, times fps -> m/s.
  Its horizontal part (``skate_xy``: the same weights on the xy displacement only) separates sliding
  from the vertical travel of a foot lifting off and touching down inside the 3 cm band, which DART's
  3D displacement also counts (most of a locked walk's skate, docs/evaluation.md).
- floor distance: mean over frames of ``|min(z_left_foot, z_right_foot)|`` -> m.
- jerk: mean L2 norm of the third finite difference of all joints (m/s^3).
- transition jerk (Table 1, FlowMDM's definition): per frame the largest joint's L1-norm third
  difference (m/frame^3) over 30-frame clips centred at a transition; PJ its peak, AUJ its area
  above or below the data's mean.

CLoSD's definitions (Tevet et al. 2025, Table 3), with a 5 mm tolerance, on the lowest joint:
penetration = mean depth below the floor beyond the tolerance, floating = mean height above the
floor beyond the tolerance, skating = mean horizontal displacement of foot joints between two
frames in which both are in contact (<= 5 mm). Our reading of the paper's text; reported in mm.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from latentrl.constants import CONTACT_HEIGHT_M
from latentrl.motion.contacts import contact_shares, foot_positions, skate_weights, weighted_foot_slide
from latentrl.motion.heading import hip_yaw_rad
from latentrl.motion.rollout import MAX_STEP_UP_M
from latentrl.motion.skeleton import FOOT_JOINTS, PELVIS

SKATE_THRESHOLD_M = CONTACT_HEIGHT_M
CLOSD_TOLERANCE_M = 0.005


def _t(x) -> torch.Tensor:
    return x if torch.is_tensor(x) else torch.as_tensor(np.asarray(x), dtype=torch.float32)


def foot_skate_weights(heights: torch.Tensor, threshold: float = SKATE_THRESHOLD_M) -> torch.Tensor:
    """(..., T, 2) foot heights -> (..., T-1, 2) contact weights in [0, 1] (1 = on the floor)."""
    return skate_weights(heights, threshold)


def foot_skate_per_transition(
    joints, floor: float = 0.0, threshold: float = SKATE_THRESHOLD_M, horizontal: bool = False
) -> torch.Tensor:
    """(..., T, 22, 3) -> (..., T-1, 2) weighted foot displacement in metres per frame (xy only if ``horizontal``)."""
    return weighted_foot_slide(foot_positions(_t(joints)), floor, threshold, horizontal=horizontal)


def foot_skate_cm_s(joints, fps: float = 30.0, floor: float = 0.0, horizontal: bool = False) -> torch.Tensor:
    """DART's skate metric in cm/s: (..., T, 22, 3) -> (...); ``horizontal``: its xy part (``skate_xy``)."""
    return foot_skate_per_transition(joints, floor, horizontal=horizontal).mean(dim=(-1, -2)) * fps * 100.0


def foot_floor_distance_cm(joints, floor: float = 0.0) -> torch.Tensor:
    """DART's floor metric in cm: mean over frames of |lower foot height| -> (...)."""
    feet_z = _t(joints)[..., list(FOOT_JOINTS), 2] - floor
    return feet_z.amin(dim=-1).abs().mean(dim=-1) * 100.0


def jerk(joints, fps: float = 30.0) -> torch.Tensor:
    """DART's jerk metric: mean L2 norm of the third derivative of every joint, m/s^3 -> (...)."""
    j = _t(joints)
    d3 = j[..., 3:, :, :] - 3 * j[..., 2:-1, :, :] + 3 * j[..., 1:-2, :, :] - j[..., :-3, :, :]
    return (d3 * fps**3).norm(dim=-1).mean(dim=(-1, -2))


#: Frames of DART's transition clip (Table 1): 30 frames centred at the split between two segments.
TRANSITION_WINDOW = 30


def transition_jerk_curve(joints) -> torch.Tensor:
    """(..., T, 22, 3) -> (..., T-3): per frame, the largest joint jerk, m/frame^3 (DART's PJ/AUJ curve).

    DART's Table 1 scores transitions with FlowMDM's jerk (Barquero et al. 2024): the third finite
    difference of each joint's position, unscaled by fps, its L1 norm over x, y, z, then the maximum over
    joints. (:func:`jerk` is the other jerk of DART's tables: mean L2 norm, times fps^3.)
    """
    j = _t(joints)
    d3 = j[..., 3:, :, :] - 3 * j[..., 2:-1, :, :] + 3 * j[..., 1:-2, :, :] - j[..., :-3, :, :]
    return d3.abs().sum(dim=-1).amax(dim=-1)


def transition_clips(joints, splits, window: int = TRANSITION_WINDOW) -> torch.Tensor:
    """(B, T, 22, 3) joints and split frames -> (N, window, 22, 3): every whole clip centred on a split.

    A split ``s`` is the first frame of the new segment; its clip is frames ``[s - window/2, s + window/2)``.
    Splits too close to either end for a whole clip are left out (none left: an empty tensor).
    """
    j = _t(joints)
    half = window // 2
    starts = [s - half for s in splits if s - half >= 0 and s - half + window <= j.shape[-3]]
    if not starts:
        return j.new_zeros(0, window, *j.shape[-2:])
    return torch.cat([j[..., a:a + window, :, :].reshape(-1, window, *j.shape[-2:]) for a in starts])


def peak_jerk(clips) -> float:
    """DART's PJ: the maximum over frames of the transition jerk curve averaged over clips (N, W, 22, 3)."""
    return float(transition_jerk_curve(clips).mean(dim=0).amax())


def area_under_jerk(clips, reference: float) -> float:
    """DART's AUJ: sum over frames of |mean transition jerk curve - ``reference``|, m/frame^3.

    ``reference`` is the data's mean jerk (FlowMDM's "GT jerk"), so data transitions score about 0 and a
    pop adds its excess jerk; clips (N, W, 22, 3) as :func:`transition_clips` cuts them.
    """
    return float((transition_jerk_curve(clips).mean(dim=0) - reference).abs().sum())


def primitive_seams(num_frames: int, history: int = 2, future: int = 8) -> list[int]:
    """First frames of the decoded primitives of a rollout (``history`` seed frames, then ``future`` per step)."""
    return list(range(history, num_frames, future))


def seam_ratios(joints, history: int = 2, future: int = 8, floor: float = 0.0,
                threshold: float = SKATE_THRESHOLD_M, fps: float = 30.0) -> dict[str, float]:
    """Pops at primitive boundaries: planted-foot step and pelvis acceleration, boundary vs inside.

    Args:
        joints: (..., T, 22, 3) a rollout's world joints, the ``history`` seed frames first.

    Returns ``step_boundary_cm`` / ``step_inside_cm`` (mean horizontal step of a foot joint within
    ``threshold`` of the floor in both frames, across a boundary / inside a primitive) and ``step_ratio``;
    ``pelvis_acc_boundary`` / ``pelvis_acc_rest`` (mean pelvis acceleration norm, m/s^2, at the last frame
    of a primitive and the first of the next / elsewhere) and ``pelvis_acc_ratio``. Data scores about 1.
    """
    j = _t(joints)
    t = j.shape[-3]
    first = torch.zeros(t, dtype=torch.bool, device=j.device)
    first[primitive_seams(t, history, future)] = True
    feet = foot_positions(j)
    h = feet[..., 2] - floor
    down = (h[..., 1:, :] < threshold) & (h[..., :-1, :] < threshold)  # (..., T-1, 2)
    step = torch.linalg.vector_norm(feet[..., 1:, :, :2] - feet[..., :-1, :, :2], dim=-1)
    seam = first[1:, None].expand_as(down)  # transition t -> t+1 enters a new primitive
    b = step[down & seam].mean() * 100.0
    i = step[down & ~seam].mean() * 100.0
    p = j[..., PELVIS, :]
    acc = torch.linalg.vector_norm(p[..., 2:, :] - 2 * p[..., 1:-1, :] + p[..., :-2, :], dim=-1) * fps**2
    at = first[1:-1] | first[2:]  # frame k (1..T-2) is a primitive's first frame or the one before it
    ab, ar = acc[..., at].mean(), acc[..., ~at].mean()
    return {"step_boundary_cm": float(b), "step_inside_cm": float(i), "step_ratio": float(b / i),
            "pelvis_acc_boundary": float(ab), "pelvis_acc_rest": float(ar), "pelvis_acc_ratio": float(ab / ar)}


def closd_penetration_mm(joints, floor: float = 0.0, tol: float = CLOSD_TOLERANCE_M) -> torch.Tensor:
    """Mean depth of the lowest joint below the floor beyond ``tol``, mm -> (...).

    ``floor`` may be a (..., T, 22) ground under each joint (:func:`terrain_floor`): the joint nearest it counts.
    """
    low = (_t(joints)[..., 2] - floor).amin(dim=-1)
    return (-low - tol).clamp(min=0).mean(dim=-1) * 1000.0


def closd_floating_mm(joints, floor: float = 0.0, tol: float = CLOSD_TOLERANCE_M) -> torch.Tensor:
    """Mean height of the lowest joint above the floor (or a (..., T, 22) ground) beyond ``tol``, mm -> (...)."""
    low = (_t(joints)[..., 2] - floor).amin(dim=-1)
    return (low - tol).clamp(min=0).mean(dim=-1) * 1000.0


def closd_skating_mm(joints, floor: float = 0.0, tol: float = CLOSD_TOLERANCE_M) -> torch.Tensor:
    """Mean horizontal foot displacement between frames where that foot is in contact in both, mm."""
    feet = _t(joints)[..., list(FOOT_JOINTS), :]
    contact = (feet[..., 2] - floor) <= tol
    both = contact[..., 1:, :] & contact[..., :-1, :]
    disp = (feet[..., 1:, :, :2] - feet[..., :-1, :, :2]).norm(dim=-1)
    return (disp * both).mean(dim=(-1, -2)) * 1000.0


def pelvis_speed_m_s(joints, fps: float = 30.0) -> torch.Tensor:
    """Mean horizontal pelvis speed, m/s -> (...)."""
    p = _t(joints)[..., PELVIS, :2]
    return (p[..., 1:, :] - p[..., :-1, :]).norm(dim=-1).mean(dim=-1) * fps


def heading_change_rad(joints) -> torch.Tensor:
    """Total signed yaw change of the hip axis (right_hip - left_hip), radians, + = counter-clockwise."""
    yaw = hip_yaw_rad(_t(joints))
    return yaw[..., -1] - yaw[..., 0]


def foot_contact_shares(joints, floor=0.0, threshold: float = 0.05) -> dict[str, torch.Tensor]:
    """Share of frames with only the left, only the right, both or no foot joint on the floor.

    A foot joint is in contact within ``threshold`` of the floor: a height, or (..., T, 2) the ground under
    each foot joint (:func:`terrain_floor`). Returns
    ``{"left_only", "right_only", "both", "none"}``, each (...).
    """
    return contact_shares(_t(joints)[..., list(FOOT_JOINTS), 2] - floor, threshold)


def single_foot_contact_fraction(joints, floor: float = 0.0, threshold: float = 0.05) -> torch.Tensor:
    """Share of frames where exactly one foot joint is within ``threshold`` of the floor -> (...)."""
    shares = foot_contact_shares(joints, floor, threshold)
    return shares["left_only"] + shares["right_only"]


def mean_ci95(values) -> dict[str, float]:
    """``{"mean", "ci95"}`` with DART's 1.96 * std / sqrt(n) (population std, as DART computes it)."""
    v = np.asarray(values, dtype=np.float64).reshape(-1)
    if v.size == 0:
        return {"mean": float("nan"), "ci95": float("nan")}
    return {"mean": float(v.mean()), "ci95": float(1.96 * v.std() / math.sqrt(v.size))}


# --------------------------------------------------------------------------- evaluation protocol
EPISODE_METRICS: dict[str, str] = {
    "skate_cm_s": "cm/s",
    "skate_xy_cm_s": "cm/s",
    "floor_cm": "cm",
    "jerk": "m/s^3",
    "penetration_mm": "mm",
    "floating_mm": "mm",
    "skating_mm": "mm",
    "pj_seam": "m/frame^3",
}
"""Motion-quality metrics of one episode (name -> unit), as :func:`episode_metrics` returns them."""


def terrain_floor(joints: torch.Tensor, terrain, floor: float = 0.0) -> torch.Tensor:
    """(T, 22) the ground under each of (T, 22, 3) world joints on ``terrain``, for the floor and contact metrics.

    ``terrain`` is anything with a batched ``height(xy)``, e.g. a one-row ``SceneBatch``. Terrain more than
    :data:`~latentrl.motion.rollout.MAX_STEP_UP_M` above the frame's lowest joint is an obstacle (a hand over
    a table, a foot inside a tall box: the scene metrics count those), not ground: such a joint is measured
    against ``floor``, as the floor snap leaves it out.
    """
    ground = terrain.height(joints[None, ..., :2])[0].to(joints.dtype)
    reach = joints[..., 2].amin(dim=-1, keepdim=True) + MAX_STEP_UP_M
    return torch.where(ground <= reach, ground, torch.full_like(ground, floor))


def episode_metrics(joints, fps: float = 30.0, floor: float = 0.0, terrain=None) -> dict[str, float]:
    """Every motion-quality metric of one whole episode (T, 22, 3) world joints, seed frames included.

    DART computes its metrics on the saved sequence, which starts with the 2 seed frames; so do we.
    ``terrain`` (a scene's ``SceneBatch`` row; None: the flat floor at ``floor``) puts each joint's ground
    under it (:func:`terrain_floor`): a foot on a tread is on the floor. Returns the :data:`EPISODE_METRICS`
    names as floats (``pj_seam`` only for an episode of 4 primitives or more: its clips need 15 frames on either
    side of a boundary).
    """
    j = _t(joints)
    ground = floor if terrain is None else terrain_floor(j, terrain, floor)
    feet = ground if terrain is None else ground[..., list(FOOT_JOINTS)]  # (T, 2) under the feet
    return {
        "skate_cm_s": float(foot_skate_cm_s(j, fps, feet)),
        "skate_xy_cm_s": float(foot_skate_cm_s(j, fps, feet, horizontal=True)),
        "floor_cm": float(foot_floor_distance_cm(j, feet)),
        "jerk": float(jerk(j, fps)),
        "penetration_mm": float(closd_penetration_mm(j, ground)),
        "floating_mm": float(closd_floating_mm(j, ground)),
        "skating_mm": float(closd_skating_mm(j, feet)),
        **({} if math.isnan(pj := seam_peak_jerk(j)) else {"pj_seam": pj}),
    }


def seam_peak_jerk(joints, history: int = 2, future: int = 8) -> float:
    """DART's PJ (Table 1) at the primitive boundaries of one rollout (T, 22, 3), m/frame^3; NaN when too short.

    The transition jerk curve averaged over the 30-frame clips centred on every boundary
    (:func:`primitive_seams`), its peak: a pop where one primitive hands over to the next shows as a spike.
    """
    j = _t(joints)
    clips = transition_clips(j[None], primitive_seams(j.shape[-3], history, future))
    return float("nan") if clips.shape[0] == 0 else peak_jerk(clips)


def final_goal_distance_m(joints, goal, last: int = 8) -> torch.Tensor:
    """DART's ``dist``: min over the last ``last`` frames of the pelvis xy distance to ``goal``, metres.

    Args:
        joints: (..., T, 22, 3) world joints, metres.
        goal: (..., 3) or (..., 2) final goal, world metres (only xy is used).
        last: frames at the end that count (DART: the 8 frames of the last primitive).

    Returns:
        (...) metres; DART's success is this < 0.3.
    """
    pelvis = _t(joints)[..., -last:, PELVIS, :2]
    g = _t(goal)[..., None, :2]
    return (pelvis - g).norm(dim=-1).amin(dim=-1)


def dart_mean_ci95(values) -> dict[str, float]:
    """DART's aggregation: average each episode (env) index over the paths, then :func:`mean_ci95`.

    ``values`` (P paths, E episodes): DART's ``goal_reach.py`` averages env index e over the 5 paths
    of a suite and reports the 95% CI over the 32 resulting means, so paths are not independent
    samples. A path with fewer episodes than the others is an error (the rows must align).
    """
    v = np.asarray(values, dtype=np.float64)
    if v.ndim != 2:
        raise ValueError(f"values must be (paths, episodes), got shape {v.shape}")
    return mean_ci95(v.mean(axis=0))


def lowest_joint_penetration_cm(joints, floor: float = 0.0) -> torch.Tensor:
    """Mean over frames of how far the lowest of all joints is below the floor, cm -> (...)."""
    low = _t(joints)[..., 2].amin(dim=-1) - floor
    return (-low).clamp(min=0).mean(dim=-1) * 100


def body_frame_velocity_m_s(joints, fps: float = 30.0) -> tuple[torch.Tensor, torch.Tensor]:
    """Mean pelvis velocity along the body's forward and rightward axes (hip axis), m/s -> two (...)."""
    j = _t(joints)
    right = j[..., :-1, 2, :2] - j[..., :-1, 1, :2]
    right = right / right.norm(dim=-1, keepdim=True).clamp(min=1e-9)
    forward = torch.stack((-right[..., 1], right[..., 0]), dim=-1)  # z x right
    v = (j[..., 1:, PELVIS, :2] - j[..., :-1, PELVIS, :2]) * fps
    return (v * forward).sum(-1).mean(-1), (v * right).sum(-1).mean(-1)
