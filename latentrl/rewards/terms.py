"""Reward kernels: one pure tensor function per term.

The formulas are DART's (``get_reward`` in ``control/env/env_reach_location_mld.py``).

Naming rule: every kernel returns the **unweighted** term, shape ``(N,)``, float32, with DART's
sign (penalties are <= 0, bonuses >= 0). Weights live in :mod:`latentrl.rewards.compose`.
Inputs are world coordinates: metres, z up, 30 fps, so "per frame" means per 1/30 s.

Frame windows (``F`` = 8 new frames per step, ``H`` = 2 history frames):

- ``goal_progress``, ``moving_orientation``: the pelvis at the last history frame before the
  step and after it (the last new frame).
- ``foot_floor``: the ``F`` new frames.
- ``foot_skate``, ``yaw_rate``: the ``F`` transitions from the last history frame through the
  new frames, i.e. ``F + 1`` frames.
- ``jerk``: all ``H + F`` frames.
- ``skill_fidelity``: the pelvis before and after the step (speed) and the ``F`` new frames (contacts).
- ``heading_tracking``, ``speed_tracking``, ``pace_tracking`` (Joystick, TimedPath): the pelvis
  before and after the step, as ``goal_progress``; velocities are that displacement over the
  step's duration (``F / 30`` s), which averages out the sway of a gait cycle.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from latentrl.constants import CONTACT_HEIGHT_M
from latentrl.motion.contacts import contact_shares, weighted_foot_slide
from latentrl.motion.contacts import foot_positions as _foot_positions
from latentrl.motion.skeleton import LEFT_HIP, RIGHT_HIP
from latentrl.rewards import skills as S
from latentrl.scenes.contact import CLEARANCE_M, clearance_cost, collision_cost, contact_cost
from latentrl.scenes.scene import SceneBatch

__all__ = [
    "arrival_timing",
    "clearance",
    "collision",
    "foot_floor",
    "foot_joints",
    "foot_skate",
    "goal_progress",
    "heading_tracking",
    "jerk",
    "moving_orientation",
    "pace_tracking",
    "skill_fidelity",
    "speed_tracking",
    "success",
    "terrain_contact",
    "yaw_rate",
]


def _xy_distance(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    return torch.linalg.vector_norm(a[..., :2] - b[..., :2], dim=-1)


def goal_progress(pelvis_before: torch.Tensor, pelvis_after: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
    """``dist``: how much closer (xy) the pelvis got to the goal during the step.

    ``r = ||g_xy - p_before_xy|| - ||g_xy - p_after_xy||``  (metres per step)

    Args:
        pelvis_before: (N, 3) pelvis at the last history frame before the step, world.
        pelvis_after: (N, 3) pelvis at the last new frame, world.
        goal: (N, 3) goal, world (z ignored).

    Returns:
        (N,) in [-d, d] where d is the pelvis displacement; positive when approaching.
    """
    return _xy_distance(goal, pelvis_before) - _xy_distance(goal, pelvis_after)


def success(reached: torch.Tensor) -> torch.Tensor:
    """``success``: ``r = 1`` if the goal was reached during the step, else 0.

    Args:
        reached: (N,) bool; the env decides (DART: min over the new frames of the pelvis xy
            distance to the goal < 0.3 m).

    Returns:
        (N,) float in {0, 1}.
    """
    return reached.float()


def foot_floor(
    foot_height: torch.Tensor,
    floor_height: float = 0.0,
    threshold: float = CONTACT_HEIGHT_M,
    scale: torch.Tensor | None = None,
) -> torch.Tensor:
    """``foot_floor``: penalise the lower foot for leaving (or sinking into) the floor.

    ``r = -s * mean_t max(|min_f z_{t,f} - floor| - threshold, 0)``  (metres)

    ``s`` is the per-env text scale (DART multiplies by 0.1 when the text contains 'hop' or
    'run', whose feet legitimately leave the floor).

    Args:
        foot_height: (N, F, 2) world z of the two foot joints over the new frames, metres.
        floor_height: floor z, metres.
        threshold: tolerated distance, metres (DART 0.03).
        scale: (N,) multiplier, or ``None`` for 1.

    Returns:
        (N,) <= 0.
    """
    gap = ((foot_height.amin(dim=-1) - floor_height).abs() - threshold).clamp(min=0.0)
    out = -gap.mean(dim=-1)
    return out if scale is None else out * scale


def foot_skate(
    foot_positions: torch.Tensor, floor_height: float | torch.Tensor = 0.0, threshold: float = CONTACT_HEIGHT_M
) -> torch.Tensor:
    """``skate``: foot displacement weighted by how close the foot is to the floor.

    ``s_{t,f} = ||p_{t,f} - p_{t-1,f}|| * (2 - 2^clamp(max(h_{t,f}, h_{t-1,f}) / threshold, 0, 1))``
    ``r = -mean_{t,f} s_{t,f}``  (metres per frame)

    ``h`` is the height above the floor. A foot on the floor (h <= 0) counts its full
    displacement, a foot at ``threshold`` or higher (in either frame) counts nothing, with
    DART's exponential ramp between.

    Args:
        foot_positions: (N, T, 2, 3) world foot joints over T consecutive frames (DART: the last
            history frame and the 8 new frames, T = 9), metres.
        floor_height: floor z, metres, or (N, T, 2) the terrain under each foot.
        threshold: contact height, metres (DART 0.03).

    Returns:
        (N,) <= 0.
    """
    return -weighted_foot_slide(foot_positions, floor_height, threshold).mean(dim=(1, 2))


def moving_orientation(pelvis_before: torch.Tensor, pelvis_after: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
    """``orient``: does the pelvis move toward the goal?

    ``r = (cos(m, g) + 1) / 2`` with ``m = p_after - p_before`` and ``g = goal - p_before`` (xy).

    Computed per environment. DART indexes ``[0]`` and broadcasts env 0's value to every env, a
    bug we do not copy. A zero-length ``m`` or ``g`` gives cos 0, i.e. 0.5 (DART's 1e-12 clip).

    Args:
        pelvis_before: (N, 3), pelvis_after: (N, 3), goal: (N, 3), world metres.

    Returns:
        (N,) in [0, 1]; 1 = straight at the goal, 0 = straight away.
    """
    move = F.normalize(pelvis_after[:, :2] - pelvis_before[:, :2], dim=-1, eps=1e-12)
    to_goal = F.normalize(goal[:, :2] - pelvis_before[:, :2], dim=-1, eps=1e-12)
    return ((move * to_goal).sum(dim=-1) + 1.0) / 2.0


def yaw_rate(joints: torch.Tensor) -> torch.Tensor:
    """``rotation``: penalise turning of the hip axis between consecutive frames.

    ``x_t = normalize((right_hip_t - left_hip_t)_xy)``,  ``r = mean_t (x_t . x_{t-1}) - 1``

    ``1 - cos`` of the per-frame yaw change (about ``dyaw^2 / 2`` for small turns).

    Args:
        joints: (N, T, 22, 3) world joints over T consecutive frames (DART: the last history
            frame and the 8 new frames).

    Returns:
        (N,) in [-2, 0]; 0 = no yaw change.
    """
    axis = joints[:, :, RIGHT_HIP, :2] - joints[:, :, LEFT_HIP, :2]
    axis = F.normalize(axis, dim=-1, eps=1e-12)
    return (axis[:, 1:] * axis[:, :-1]).sum(dim=-1).mean(dim=-1) - 1.0


def jerk(joints: torch.Tensor) -> torch.Tensor:
    """``jerk``: the largest third finite difference of any joint (L1 over xyz).

    ``r = -max_{t,j} ||p_{t+3,j} - 3 p_{t+2,j} + 3 p_{t+1,j} - p_{t,j}||_1``  (metres per frame^3)

    Args:
        joints: (N, T, 22, 3) world joints over T >= 4 consecutive frames (DART: 2 history + 8 new).

    Returns:
        (N,) <= 0.
    """
    third = joints.diff(n=3, dim=1)  # (N, T-3, 22, 3)
    return -third.abs().sum(dim=-1).amax(dim=(1, 2))


def foot_joints(joints: torch.Tensor) -> torch.Tensor:
    """(..., 22, 3) joints -> (..., 2, 3) the left and right foot joints DART uses for contact."""
    return _foot_positions(joints)


def heading_tracking(pelvis_before: torch.Tensor, pelvis_after: torch.Tensor, heading: torch.Tensor) -> torch.Tensor:
    """``heading``: does the pelvis move in the commanded world direction?

    ``r = (cos(m, h) + 1) / 2`` with ``m = p_after - p_before`` (xy) and ``h`` the commanded heading;
    the same form as :func:`moving_orientation`, with a direction instead of a goal.

    Args:
        pelvis_before: (N, 3), pelvis_after: (N, 3), world metres.
        heading: (N, 2) commanded direction in the world xy plane (any length > 0).

    Returns:
        (N,) in [0, 1]; 1 = along the command, 0.5 = at 90 degrees, 0 = opposite (0.5 when not moving).
    """
    move = F.normalize(pelvis_after[:, :2] - pelvis_before[:, :2], dim=-1, eps=1e-12)
    return ((move * F.normalize(heading, dim=-1, eps=1e-12)).sum(dim=-1) + 1.0) / 2.0


def speed_tracking(
    pelvis_before: torch.Tensor, pelvis_after: torch.Tensor, speed: torch.Tensor, seconds: float
) -> torch.Tensor:
    """``speed``: how far the pelvis' horizontal speed is from the commanded speed.

    ``r = -| ||p_after - p_before||_xy / seconds - s |``  (m/s)

    Args:
        pelvis_before: (N, 3), pelvis_after: (N, 3), world metres.
        speed: (N,) commanded speed, m/s.
        seconds: time between the two pelvis positions (one step: 8 frames = 0.267 s).

    Returns:
        (N,) <= 0; 0 = the commanded speed, whatever the direction (:func:`heading_tracking` judges that).
    """
    return -(_xy_distance(pelvis_after, pelvis_before) / seconds - speed).abs()


def pace_tracking(
    pelvis_before: torch.Tensor,
    pelvis_after: torch.Tensor,
    goal: torch.Tensor,
    target_speed: torch.Tensor,
    seconds: float,
) -> torch.Tensor:
    """``pace``: is the pelvis approaching the goal at the speed that arrives on time?

    ``r = -| (p_after - p_before) . u / seconds - v |``  (m/s), with ``u`` the unit xy direction from
    ``p_before`` to the goal and ``v`` the target speed (TimedPath: distance left / time left).

    Args:
        pelvis_before: (N, 3), pelvis_after: (N, 3), goal: (N, 3), world metres.
        target_speed: (N,) speed toward the goal that would arrive on time, m/s.
        seconds: time between the two pelvis positions.

    Returns:
        (N,) <= 0; 0 = straight at the goal at the target speed; moving at 90 degrees gives ``-v``.
    """
    toward = F.normalize(goal[:, :2] - pelvis_before[:, :2], dim=-1, eps=1e-12)
    velocity = (pelvis_after[:, :2] - pelvis_before[:, :2]) / seconds
    return -((velocity * toward).sum(dim=-1) - target_speed).abs()


def arrival_timing(reached: torch.Tensor, arrival_error: torch.Tensor, tolerance: float) -> torch.Tensor:
    """``timing``: a bonus for reaching a waypoint on time, falling linearly to 0 at ``tolerance``.

    ``r = reached * max(0, 1 - |e| / tolerance)``, ``e`` = arrival time - goal time (seconds).

    Args:
        reached: (N,) bool, a waypoint was reached during the step.
        arrival_error: (N,) seconds, late > 0, early < 0 (ignored where not reached).
        tolerance: seconds at which the bonus reaches 0 (> 0).

    Returns:
        (N,) in [0, 1]; 1 = reached exactly on time; 0 when nothing was reached or off by >= tolerance.
    """
    score = (1.0 - arrival_error.abs() / tolerance).clamp(min=0.0)
    return torch.where(reached, score, torch.zeros_like(score))


def noise_prior(noise: torch.Tensor) -> torch.Tensor:
    """``prior``: 0 while the latent noise looks like a draw from the prior, negative beyond it.

    ``-max(0, mean(a^2) - 1)`` over the (N, D) action. The motion model was trained on noise from N(0, I),
    whose mean square is 1; a policy is free to push every dimension to the +-4 bound, where the model
    makes motion it never learned (measured: a run policy whose noise had an rms of 2.3 slid its feet at
    43 cm/s). Typical prior draws cost nothing, so the term only bites on out-of-distribution noise (the
    latent-space RL papers' "stay near the prior" penalty, in its simplest form).
    """
    return -(noise.float().pow(2).mean(dim=-1) - 1.0).clamp(min=0.0)


def skill_fidelity(
    pelvis_before: torch.Tensor,
    pelvis_after: torch.Tensor,
    feet_height: torch.Tensor,
    skill: torch.Tensor,
    step_seconds: float,
    threshold: float = S.CONTACT_HEIGHT_M,
    scale: tuple[float, ...] | None = None,
) -> torch.Tensor:
    """``skill``: minus how far the step is from passing the skill rule of its text (:mod:`latentrl.rewards.skills`).

    With ``v`` the step's horizontal pelvis speed (m/s) and the shares of the new frames with one foot alone
    on the floor (within ``threshold``):

    - walk (code 2): ``-(max(0, 0.5 - v) + max(0, v - 2.0))``, metres per second outside the walk band;
    - run (code 1): ``-max(0, 2.0 - v)``;
    - hop on left leg (code 3): ``-(max(0, 0.4 - left alone) + max(0, right alone - 0.1))``; mirrored (code 4);
    - not judged (code 0): 0.

    0 whenever the step passes the rule the evaluation judges segments by, so a policy that already does
    what its text says pays nothing; a multi-skill path policy that steps through a hop segment does.

    Args:
        pelvis_before, pelvis_after: (N, 3) pelvis before and after the step, world.
        feet_height: (N, F, 2) left and right foot joint heights above the floor over the new frames.
        skill: (N,) long, :func:`latentrl.rewards.skills.skill_code` of each env's text.
        step_seconds: the step's duration (F / 30 s).
        threshold: contact height, metres.
        scale: one multiplier per family of :data:`latentrl.rewards.skills.SKILLS` (``RewardConfig.skill_scale``),
            or None for 1 each. Python floats, so a step makes no host-to-device copy for them.

    Returns:
        (N,) <= 0.
    """
    speed = _xy_distance(pelvis_after, pelvis_before) / step_seconds
    walk_lo, walk_hi = S.WALK_SPEED_M_S
    walk = -(F.relu(walk_lo - speed) + F.relu(speed - walk_hi))
    run = -F.relu(S.RUN_MIN_SPEED_M_S - speed)
    shares = contact_shares(feet_height, threshold)
    left_only, right_only = shares["left_only"], shares["right_only"]

    def hop(stance: torch.Tensor, other: torch.Tensor) -> torch.Tensor:
        return -(F.relu(S.HOP_STANCE_MIN_SHARE - stance) + F.relu(other - S.HOP_OTHER_MAX_SHARE))

    families = [run, walk, hop(left_only, right_only), hop(right_only, left_only)]  # the order of S.SKILLS
    if scale is not None:
        families = [value * float(k) for value, k in zip(families, scale, strict=True)]
    per_code = torch.stack((torch.zeros_like(speed), *families), 1)
    return per_code.gather(1, skill.long().clamp(0, len(S.SKILLS))[:, None])[:, 0]


JOINT_ARRIVAL_SCALE_M = 0.1
"""``joint_arrival`` falls to 1/e at this error (metres): sharp enough to pay for centimetres near the target."""


def joint_progress(error_before: torch.Tensor, error_after: torch.Tensor) -> torch.Tensor:
    """``joint_dist``: how much closer the goal joint came to its target during the step, metres.

    ``r = e_before - e_after``: a potential-based shaping (the potential is ``-e``), so summed over an
    episode it is the start error minus the end error and it does not change which policy is best; the
    goal time is paid by :func:`joint_arrival`.

    Args:
        error_before: (N,) the joint's distance to its target at the last frame before the step.
        error_after: (N,) the same at the step's last frame (or at the goal-time frame when that is in the step).

    Returns:
        (N,) metres, > 0 when approaching.
    """
    return error_before - error_after


def joint_arrival(error_at_goal: torch.Tensor, scale: float = JOINT_ARRIVAL_SCALE_M) -> torch.Tensor:
    """``joint_arrival``: the terminal term at a goal's time, ``exp(-e / scale)``; 0 in other steps.

    Args:
        error_at_goal: (N,) the joint's distance to its target at the goal-time frame, metres; NaN in the
            steps that do not hold a goal time.
        scale: metres at which the bonus falls to 1/e.

    Returns:
        (N,) in [0, 1]; 1 = exactly on the target at the goal time.
    """
    at_goal = torch.isfinite(error_at_goal)
    score = torch.exp(-torch.where(at_goal, error_at_goal, 0.0).clamp(min=0.0) / scale)
    return torch.where(at_goal, score, torch.zeros_like(score))


def collision(joints: torch.Tensor, scene: SceneBatch, sdf: torch.Tensor | None = None) -> torch.Tensor:
    """``collision``: minus DART's ``cons_coll`` (:func:`latentrl.scenes.contact.collision_cost`).

    ``r = -mean_t sum_j max(0, skin_j - sdf(p_{t,j}))``  (metres)

    Args:
        joints: (N, F, 22, 3) world joints of the new frames.
        scene: the env's scenes (N rows or one).
        sdf: (N, F, 22) ``scene.sdf(joints)`` when the caller has it (the scene terms share one).

    Returns:
        (N,) <= 0; 0 while every joint keeps its skin radius from every object.
    """
    return -collision_cost(joints, scene, sdf=sdf)


def clearance(joints: torch.Tensor, scene: SceneBatch, margin: float = CLEARANCE_M,
              sdf: torch.Tensor | None = None) -> torch.Tensor:
    """``clearance``: minus :func:`latentrl.scenes.contact.clearance_cost`, a warning before ``collision``.

    ``r = -mean_t min(margin, max(0, margin - min_j (sdf(p_{t,j}) - skin_j)))``  (metres)

    Returns:
        (N,) in [-margin, 0]; 0 while every joint keeps ``margin`` beyond its skin radius from every object.
    """
    return -clearance_cost(joints, scene, margin, sdf=sdf)


def terrain_contact(joints: torch.Tensor, scene: SceneBatch, threshold: float = CONTACT_HEIGHT_M,
                    scale: torch.Tensor | None = None) -> torch.Tensor:
    """``terrain_contact``: minus DART's ``cons_cont``, the lower foot's distance to the terrain beyond ``threshold``.

    ``r = -s * mean_t max(|min_f (z_{t,f} - height(xy_{t,f}))| - threshold, 0)``  (metres): :func:`foot_floor`
    with the terrain under each foot (a tread, a seat top) in place of the flat floor.

    Args:
        joints: (N, F, 22, 3) world joints of the new frames.
        scene: the env's scenes.
        threshold: tolerated distance, metres (DART 0.03).
        scale: (N,) multiplier (the hop/run text scale of ``foot_floor``), or ``None`` for 1.

    Returns:
        (N,) <= 0.
    """
    out = -contact_cost(joints, scene, threshold)
    return out if scale is None else out * scale
