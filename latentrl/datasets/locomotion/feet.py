"""Footprints, swing arcs, held feet, pelvis drop for reach, and the pose from IK."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from latentrl.datasets.body import (
    TOE_HEIGHT_M,
    Body,
    _segment_frame,
    axis_angle_to_matrix_np,
    leg_rotations,
    matrix_to_axis_angle_np,
    rot_x,
    rot_y,
    rot_z,
    two_bone_ik,
    yaw_roll_pitch,
)
from latentrl.datasets.locomotion.config import _HELD_AFTER_S, _HELD_MIN_HEIGHT, _REACH, _SWING_TO_HELD_S
from latentrl.datasets.locomotion.skills import _runs, _smootherstep, _smoothstep
from latentrl.motion.skeleton import FPS

# --- feet -------------------------------------------------------------------------------------------------


@dataclass
class _Feet:
    """Foot targets for both legs (index 0 left, 1 right) on the padded timeline."""

    toe: np.ndarray  # (T, 2, 3) toe-base joint targets, world, metres
    yaw: np.ndarray  # (T, 2) foot heading, rad, counter-clockwise from the rest facing (+y)
    pitch: np.ndarray  # (T, 2) foot pitch about its lateral axis, rad, + lifts the toes
    grounded: np.ndarray  # (T, 2) bool: toe locked on its footprint or heel pivoting on the floor


def _rot2(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s], [s, c]])


def _footprints(contact: np.ndarray, root_xy: np.ndarray, heading: np.ndarray, ch: dict, body: Body, side: float):
    """(start, end, toe_xy, yaw) per stance: the nominal foot spot under the root at mid-stance.

    Long stances (a stop, standing) use the root 0.3 s after touch-down, about where a normal stance has its
    middle, so the last step of a stop is an ordinary step and the closing step lands beside it.
    """
    prints = []
    frames = np.arange(len(contact))
    for a, b in _runs(contact):
        ref = min((a + b - 1) / 2, a + 0.3 * FPS)  # fractional: at 4 m/s half a frame is 7 cm
        at = round(ref)
        xy = np.array([np.interp(ref, frames, root_xy[:, 0]), np.interp(ref, frames, root_xy[:, 1])])
        yaw = float(np.interp(ref, frames, heading))
        offset = np.array([side * ch["stance_width"][at], body.ankle_to_toe[1] + ch["foot_shift"][at]])
        prints.append((a, b, xy + _rot2(yaw) @ offset, yaw - side * ch["toe_out"][at]))
    return prints


def _stance_pitch(n: int, toe_land: float, heel_rise: float, lands: bool, lifts: bool) -> np.ndarray:
    """(n,) foot pitch (rad) over a stance of ``n`` frames, pivoting about the locked toe joint.

    A toe-first landing starts heel-up by ``toe_land`` and lowers the heel over at most 0.15 s; the heel
    rises to ``heel_rise`` over the last 0.3 s (at most 40% of the stance) before lift-off.
    """
    i = np.arange(n)
    pitch = np.zeros(n)
    land = min(round(0.15 * FPS), int(0.3 * n)) if lands else 0
    if land:
        pitch[:land] -= toe_land * (1.0 - _smoothstep(i[:land] / land))
    rise = min(round(0.3 * FPS), int(0.4 * n)) if lifts else 0
    if rise:
        pitch[n - rise:] -= heel_rise * _smoothstep((i[n - rise:] - (n - rise) + 1) / rise)
    return pitch


def _heel_roll(feet: _Feet, leg: int, a: int, frames: int, toe_xy: np.ndarray, yaw: float, strike: float,
               body: Body) -> None:
    """Fill the ``frames`` before touch-down ``a``: a heel-first landing rolling about the heel to flat."""
    heel = np.append(toe_xy - _rot2(yaw) @ body.heel_to_toe[:2], 0.0)
    pitch = strike * (1.0 - _smoothstep(np.arange(frames) / frames))
    feet.toe[a - frames:a, leg] = heel + rot_z(np.full(frames, yaw)) @ rot_x(pitch) @ body.heel_to_toe
    feet.yaw[a - frames:a, leg], feet.pitch[a - frames:a, leg] = yaw, pitch
    feet.grounded[a - frames:a, leg] = True


def _plant_feet(contact: np.ndarray, root_xy: np.ndarray, heading: np.ndarray, ch: dict, body: Body) -> _Feet:
    """Grounded foot targets: toes locked on their footprints, and heel-first landings rolling onto them."""
    total = len(contact)
    feet = _Feet(np.zeros((total, 2, 3)), np.zeros((total, 2)), np.zeros((total, 2)), np.zeros((total, 2), bool))
    for leg, side in ((0, -1.0), (1, 1.0)):
        prev_end = 0
        for a, b, xy, yaw in _footprints(contact[:, leg], root_xy, heading, ch, body, side):
            feet.toe[a:b, leg] = (xy[0], xy[1], TOE_HEIGHT_M)
            feet.yaw[a:b, leg], feet.grounded[a:b, leg] = yaw, True
            feet.pitch[a:b, leg] = _stance_pitch(b - a, ch["toe_land"][a], ch["heel_rise"][b - 1], a > 0, b < total)
            strike = ch["heel_strike"][a]
            roll = min(round(ch["rocker_s"][a] * FPS), int(0.3 * (a - prev_end))) if a > 0 and strike > 0.01 else 0
            if roll:
                _heel_roll(feet, leg, a, roll, xy, yaw, strike, body)
            prev_end = b
    return feet


def _hip(pelvis: np.ndarray, pelvis_rot: np.ndarray, body: Body, leg: int) -> np.ndarray:
    """(T, 3) world position of hip joint ``leg`` (0 left, 1 right) for a (T, 3) pelvis with (T, 3, 3) rotation."""
    return pelvis + pelvis_rot @ body.hip_offsets[leg]


def _held_feet(pelvis: np.ndarray, pelvis_rot: np.ndarray, heading: np.ndarray, ch: dict, body: Body):
    """(T, 2, 3) toe targets and (T,) pitch of a leg held off the floor (hip and knee flexed, toes down)."""
    alpha, kappa = ch["tuck_hip"], ch["tuck_knee"]
    ankle_fwd = body.thigh * np.sin(alpha) + body.shank * np.sin(alpha - kappa)
    ankle_down = body.thigh * np.cos(alpha) + body.shank * np.cos(alpha - kappa)
    pitch = np.full(len(heading), -0.3)
    foot = (rot_x(pitch) @ body.ankle_to_toe)  # (T, 3) in the heading frame
    toes = np.zeros((len(heading), 2, 3))
    for leg in range(2):
        hip = _hip(pelvis, pelvis_rot, body, leg)
        local = np.stack((np.zeros_like(alpha), ankle_fwd, -ankle_down), axis=-1) + foot
        toes[:, leg] = hip + (rot_z(heading) @ local[..., None])[..., 0]
    toes[..., 2] = np.maximum(toes[..., 2], _HELD_MIN_HEIGHT)  # guard for deep crouches
    return toes, pitch


def _swing_arc(tau: np.ndarray, peak: float) -> np.ndarray:
    """Unit-height lift over a swing, zero at both ends, peaking at ``tau = peak``: tau (1 - tau)^((1-p)/p)."""
    power = (1.0 - peak) / peak
    return tau * (1.0 - tau) ** power / (peak * (1.0 - peak) ** power)


def _air_spells(grounded: np.ndarray) -> list[tuple[int, int, bool, bool]]:
    """(start, end, from_floor, to_floor) per air spell of one foot.

    A spell longer than ``_HELD_AFTER_S`` is a leg held up (the free leg of a hop); it is split into a rise
    to the held pose and a descent from it, with the held pose in between.
    """
    total = len(grounded)
    spells = []
    for a, b in _runs(~grounded):
        if b - a > _HELD_AFTER_S * FPS:
            spells += [(a, (a + b) // 2, a > 0, False), ((a + b) // 2, b, False, b < total)]
        else:
            spells.append((a, b, a > 0, b < total))
    return spells


def _swing_feet(feet: _Feet, held: np.ndarray, held_pitch: np.ndarray, heading: np.ndarray,
                pelvis_z: np.ndarray, ch: dict, level: np.ndarray | None = None) -> None:
    """Fill the air frames of ``feet``: arcs from lift-off to the next landing pose, or to / from a held pose.

    Horizontally the toe eases from footprint to footprint (zero speed at both ends, travel done before the
    final descent). Vertically it adds an early-peaking clearance arc (the heel kicks up) and the pelvis'
    excursion from its straight line over the spell, so feet rise and fall with the body in flight. A swing
    between two ground ``level``s (T, 2) (stairs) lifts the foot before it moves forward when it steps up,
    and moves it over the edge before it descends when it steps down.
    """
    span = round(_SWING_TO_HELD_S * FPS)
    for leg in range(2):
        for a, b, prev, nxt in _air_spells(feet.grounded[:, leg]):
            frames = np.arange(a, b)
            if prev and nxt:
                tau = (frames - a + 1) / (b - a + 1)
            elif prev or nxt:  # to or from the held pose, which is then reached or left in ``span`` frames
                tau = np.minimum((frames - a + 1) / (span + 1), 1.0) if prev else np.maximum(
                    1.0 - (b - frames) / (span + 1), 0.0)
            else:
                tau = np.zeros(len(frames))
            start = feet.toe[a - 1, leg] if prev else held[frames, leg]
            end = feet.toe[b, leg] if nxt else held[frames, leg]
            stair = ch["stair"][(a + b) // 2]
            if level is not None and prev and nxt and abs(level[b, leg] - level[a - 1, leg]) > 0.01:
                stair = float(np.sign(level[b, leg] - level[a - 1, leg]))  # a step between two levels
            if stair > 0:  # up a step: lift first, then forward over the tread edge
                along = _smootherstep((tau - 0.12) / 0.63)[:, None]
            elif stair < 0:  # down a step: forward over the edge first, then down
                along = _smootherstep(tau / 0.7)[:, None]
            else:
                along = _smootherstep(tau / 0.88)[:, None]
            toe = start + (end - start) * along
            mid = (a + b) // 2
            lift = ch["clearance"][mid] * _swing_arc(tau, ch["swing_peak"][mid])
            if prev and nxt:
                lift += pelvis_z[frames] - (pelvis_z[a - 1] * (1 - tau) + pelvis_z[b] * tau)
            if stair > 0:
                rise = _smoothstep(tau / 0.45)
            elif stair < 0:
                rise = _smoothstep((tau - 0.4) / 0.55)
            else:
                rise = _smoothstep((tau - 0.3) / 0.7)  # towards the landing pose late in the swing
            toe[:, 2] = start[..., 2] + (end[..., 2] - start[..., 2]) * rise + lift
            feet.toe[a:b, leg] = toe
            p0 = feet.pitch[a - 1, leg] if prev else held_pitch[frames]
            p1 = feet.pitch[b, leg] if nxt else held_pitch[frames]
            feet.pitch[a:b, leg] = np.where(tau < 0.5, p0 * (1 - _smoothstep(2 * tau)), p1 * _smoothstep(2 * tau - 1))
            y0 = feet.yaw[a - 1, leg] if prev else heading[frames]
            y1 = feet.yaw[b, leg] if nxt else heading[frames]
            feet.yaw[a:b, leg] = y0 + np.angle(np.exp(1j * (y1 - y0))) * along[:, 0]


def _ankle_targets(feet: _Feet, leg: int, body: Body) -> tuple[np.ndarray, np.ndarray]:
    """(T, 3) ankle targets and (T, 3, 3) foot rotations that put the toe joint on its target."""
    foot_rot = rot_z(feet.yaw[:, leg]) @ rot_x(feet.pitch[:, leg])
    return feet.toe[:, leg] - foot_rot @ body.ankle_to_toe, foot_rot


def _smooth_cover(need: np.ndarray, radius: int = 3, sigma: float = 1.5) -> np.ndarray:
    """A smooth curve >= ``need``: dilate by ``radius`` frames, Gaussian-smooth, then clip from below."""
    padded = np.pad(need, radius, mode="edge")
    dilated = np.lib.stride_tricks.sliding_window_view(padded, 2 * radius + 1).max(axis=-1)
    x = np.arange(-3 * round(sigma), 3 * round(sigma) + 1)
    kernel = np.exp(-0.5 * (x / sigma) ** 2)
    smooth = np.convolve(np.pad(dilated, len(x) // 2, mode="edge"), kernel / kernel.sum(), mode="valid")
    return np.maximum(smooth, need)


def _reach_drop(pelvis: np.ndarray, pelvis_rot: np.ndarray, feet: _Feet, body: Body) -> np.ndarray:
    """(T,) metres to lower the pelvis so every grounded foot is within ``_REACH`` of its leg length."""
    reach = _REACH * (body.thigh + body.shank)
    need = np.zeros(len(pelvis))
    for leg in range(2):
        hip = _hip(pelvis, pelvis_rot, body, leg)
        ankle, _ = _ankle_targets(feet, leg, body)
        horizontal = np.linalg.norm((hip - ankle)[:, :2], axis=-1)
        allowed = np.sqrt(np.maximum(reach**2 - horizontal**2, 0.0))
        drop = np.where(feet.grounded[:, leg], hip[:, 2] - ankle[:, 2] - allowed, 0.0)
        need = np.maximum(need, drop)
    return _smooth_cover(np.clip(need, 0.0, 0.3))


# --- stairs -----------------------------------------------------------------------------------------------

STAIR_TOE_BACK_M = 0.07
"""A foot on a tread has its toe joint this far behind the next riser (the toes clear it, the heel is on)."""
STAIR_WIDTH_M = 1.2
"""Nominal width of a generated flight (stored for scenes; the data's walker keeps to its middle)."""


def _stairs(blocks, feet: _Feet, contact: np.ndarray,
            heading: np.ndarray) -> tuple[list[list[float]], list[tuple[int, int]], np.ndarray]:
    """Build a flight under each stair block's footprints and lift every footprint to its ground level.

    Each stance of a stair block moves (along the block's heading) onto the nearest tread, at most one
    tread further than the stance before it (the first onto tread 1; the last onto the tread of the other
    foot, so the flight ends with both feet on its end level), counted from the last footprint before the
    block: tread ``j`` is ``j`` risers up (or down) and holds the
    toe joint ``STAIR_TOE_BACK_M`` behind the next riser. The ground stays at the last tread's height
    after the flight. Every other stance stands on the level reached so far; all levels are then shifted so
    that the lowest is the floor (z = 0). Returns the flights as rows of ``latentrl.scenes.Stairs``
    (x, y of the bottom edge's midpoint, climbing direction in rad from +x, width, riser, tread, count of
    steps, base height; the top step continues as a landing), the frames each flight is walked (first
    stance to last) and the (T, 2) ground level under each stance. A stair block's label is stretched
    until both feet stand on its end level (the closing step onto the landing is part of the flight).
    Without stair blocks nothing changes and the levels are zero.
    """
    total = len(contact)
    level = np.zeros((total, 2))
    stair_blocks = [b for b in blocks if b.skill in ("stairs_up", "stairs_down")]
    if not stair_blocks:
        return [], [], level
    stances = sorted((a, b, leg) for leg in range(2) for a, b in _runs(contact[:, leg]))
    height = np.zeros(len(stances))
    current, done, flights, spans = 0.0, 0, [], []
    for blk in stair_blocks:
        lo, hi = blk.start + blk.blend_in // 2, blk.end - blk.blend_out // 2
        members = [k for k, (a, _, _) in enumerate(stances) if lo <= a < hi and k >= done]
        if not members:
            continue
        height[done:members[0]] = current
        first_a, _, first_leg = stances[members[0]]
        yaw = float(heading[first_a])
        d = np.array([-math.sin(yaw), math.cos(yaw)])
        tread, riser = blk.params["tread"], blk.params["riser"]
        if members[0] > 0:
            a0, _, leg0 = stances[members[0] - 1]
            origin = feet.toe[a0, leg0, :2].copy()
        else:
            origin = feet.toe[first_a, first_leg, :2] - tread * d
        top = 0
        for n, k in enumerate(members):  # one tread per step; a step-to (both feet on one tread) where short
            a, b, leg = stances[k]
            rel = feet.toe[a, leg, :2] - origin
            along = float(rel @ d)
            j = int(np.clip(round(along / tread), top, top + 1)) if top else 1
            if n == len(members) - 1 and n > 0:
                j = top  # the last step joins the other foot: the flight ends with both feet on its end level
            shift_xy = d * (j * tread - along)
            g = a  # the stance and the heel-first roll before it (grounded, not yet in contact) move together
            while g > 0 and feet.grounded[g - 1, leg] and not contact[g - 1, leg]:
                g -= 1
            feet.toe[g:b, leg, :2] += shift_xy
            height[k] = current + riser * j
            top = max(top, j)
        edge = origin + d * (STAIR_TOE_BACK_M - tread)  # the riser in front of tread 0
        if riser > 0:
            start, direction, base = edge + d * tread, yaw + math.pi / 2, current
        else:
            start, direction, base = edge + d * (top * tread), yaw - math.pi / 2, current + riser * top
        flights.append([start[0], start[1], math.atan2(math.sin(direction), math.cos(direction)), STAIR_WIDTH_M,
                        abs(riser), tread, top, base])
        spans.append((max(first_a - FPS, 0), max(stances[k][1] for k in members)))  # with the swing onto it
        for leg in range(2):  # the label lasts until each foot stands on the flight's end level
            after = [a for a, _, lg in stances[members[-1] + 1:] if lg == leg]
            last = [k for k in members if stances[k][2] == leg]
            if after and last and height[last[-1]] != current + riser * top:
                blk.end = max(blk.end, after[0] + 3)
        current += riser * top
        done = members[-1] + 1
    height[done:] = current
    shift = -min(float(height.min()), 0.0)
    for row in flights:
        row[7] += shift
    for k, (a, b, leg) in enumerate(stances):
        z = height[k] + shift
        feet.toe[a:b, leg, 2] += z
        level[a:b, leg] = z
        g = a - 1
        while g >= 0 and feet.grounded[g, leg] and not contact[g, leg]:  # a heel-first landing's roll
            feet.toe[g, leg, 2] += z
            level[g, leg] = z
            g -= 1
    return flights, spans, level


def _support_level(level: np.ndarray, contact: np.ndarray, sigma: float = 4.0) -> np.ndarray:
    """(T,) smooth ground height under the body: the feet's levels, eased across each swing, averaged."""
    total = len(contact)
    frames = np.arange(total)
    legs = []
    for leg in range(2):
        down = contact[:, leg]
        legs.append(np.interp(frames, frames[down], level[down, leg]) if down.any() else np.zeros(total))
    mean = 0.5 * (legs[0] + legs[1])
    x = np.arange(-3 * round(sigma), 3 * round(sigma) + 1)
    kernel = np.exp(-0.5 * (x / sigma) ** 2)
    return np.convolve(np.pad(mean, len(x) // 2, mode="edge"), kernel / kernel.sum(), mode="valid")


def _ground_under_feet(flights: list, spans: list[tuple[int, int]], level: np.ndarray, grounded: np.ndarray,
                       toe: np.ndarray) -> np.ndarray:
    """(T, 2) terrain height under each toe joint.

    A grounded foot has its stance's level; in the air over a flight (while it is walked) the step under
    the toe, elsewhere the levels of the stances before and after, eased between them.
    """
    out = level.copy()
    frames = np.arange(len(grounded))
    for leg in range(2):
        down = grounded[:, leg]
        if not down.any():
            continue
        before = np.interp(frames, frames[down], level[down, leg])  # air frames: the level of the stances
        out[~down, leg] = before[~down]
        for row, (a, b) in zip(flights, spans):  # over a flight: the tread under the toe
            h = stairs_height(np.asarray(row), toe[a:b, leg, :2])
            inside = ~down[a:b] & ~np.isnan(h)
            out[a:b][inside, leg] = h[inside]
    return out


def stairs_height(row: np.ndarray, xy: np.ndarray, landings: bool = False) -> np.ndarray:
    """(...,) ground height of a flight (a ``stairs`` row) under points (..., 2).

    Inside the flight's width and between its bottom edge and the far end of its top step the height is
    the step under the point, and before the bottom edge (up to a tread) the base; elsewhere NaN (another
    surface's business). With ``landings`` the flight is the whole ground: the base before it and the top
    step's height after it, at any distance across (what a walker of this one flight stands on).
    """
    x, y, direction, width, riser, tread, count, base = (float(v) for v in row[:8])
    d = np.array([math.cos(direction), math.sin(direction)])
    rel = np.asarray(xy, dtype=np.float64) - np.array([x, y])
    along = rel @ d
    step = np.clip(np.floor(along / tread) + 1, 0, count)
    h = base + riser * step
    if landings:
        return h
    across = rel @ np.array([-d[1], d[0]])
    inside = (np.abs(across) <= width / 2) & (along >= -tread) & (along < count * tread)
    return np.where(inside, h, np.nan)


# --- pose -------------------------------------------------------------------------------------------------


def _rest_frame(direction: np.ndarray) -> np.ndarray:
    """(3, 3) frame of a rest segment along ``direction`` with its hinge as close to +x as possible."""
    d = direction / np.linalg.norm(direction)
    hinge = np.array([1.0, 0.0, 0.0]) - d[0] * d
    return _segment_frame(d, hinge / np.linalg.norm(hinge))


def _slerp_to(a: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    """(T, 3, 3) rotations a fraction ``w`` (T,) of the way from ``a`` to ``b``."""
    rel = matrix_to_axis_angle_np(np.swapaxes(a, -1, -2) @ b)
    return a @ axis_angle_to_matrix_np(rel * w[:, None])


def _arm_ik(body: Body, local: np.ndarray, pelvis: np.ndarray, heading: np.ndarray, ch: dict,
            goals: dict | None) -> None:
    """Put each hand (wrist joint) on its target where its ``reach_*`` weight is 1, easing from the channels' arm.

    The target is ``reach_*{x,y,z}`` from the shoulder in the heading frame; the elbow points back, out and
    down. ``goals`` (if given) receives each reaching hand's (T, 3) world target.
    """
    rest = body.rest_joints
    world = {0: local[:, 0]}
    pos = {0: pelvis}
    for j, parent in ((3, 0), (6, 3), (9, 6), (13, 9), (14, 9), (16, 13), (17, 14)):
        world[j] = world[parent] @ local[:, j]
        pos[j] = pos[parent] + world[parent] @ (rest[j] - rest[parent])
    heading_rot = rot_z(heading)
    for side, (collar, shoulder, elbow, wrist), out in (("l", (13, 16, 18, 20), -1.0), ("r", (14, 17, 19, 21), 1.0)):
        w = np.clip(ch[f"reach_{side}"], 0.0, 1.0)
        active = w > 0
        if not active.any():
            continue
        offset = np.stack([ch[f"reach_{side}{a}"] for a in "xyz"], axis=-1)
        goal = pos[shoulder] + (heading_rot @ offset[..., None])[..., 0]
        if goals is not None:
            goals[side] = goal
        upper, fore = rest[elbow] - rest[shoulder], rest[wrist] - rest[elbow]
        pole = (heading_rot @ np.array([0.6 * out, -0.5, -0.6]))
        u, f, hinge = two_bone_ik(pos[shoulder][active], goal[active], pole[active], float(np.linalg.norm(upper)),
                                  float(np.linalg.norm(fore)))
        h = -hinge  # the elbow flexes forward: a positive rotation about its hinge, as in the channels' pose
        upper_world = _segment_frame(u, h) @ _rest_frame(upper).T
        fore_world = _segment_frame(f, h) @ _rest_frame(fore).T
        parent = world[collar][active]
        ik_shoulder = np.swapaxes(parent, -1, -2) @ upper_world
        ik_elbow = np.swapaxes(upper_world, -1, -2) @ fore_world
        local[active, shoulder] = _slerp_to(local[active, shoulder], ik_shoulder, w[active])
        local[active, elbow] = _slerp_to(local[active, elbow], ik_elbow, w[active])


def _local_rotations(
    body: Body, pelvis: np.ndarray, pelvis_rot: np.ndarray, ch: dict, feet: _Feet,
    heading: np.ndarray | None = None, goals: dict | None = None,
) -> np.ndarray:
    """(T, 22, 3, 3) local joint rotations: upper body from the channels, legs by IK to the foot targets.

    Hands with a ``reach_*`` weight go to their targets (``_arm_ik``, which needs the ``heading``).
    """
    total = len(pelvis)
    local = np.tile(np.eye(3), (total, 22, 1, 1))
    local[:, 0] = pelvis_rot
    for joint, share in ((3, 0.3), (6, 0.35), (9, 0.35)):
        local[:, joint] = yaw_roll_pitch(share * ch["trunk_yaw"], share * ch["trunk_roll"], share * ch["trunk_pitch"])
    thorax_yaw = ch["pelvis_yaw"] + ch["trunk_yaw"]
    thorax_roll = ch["pelvis_roll"] + ch["trunk_roll"]
    thorax_pitch = ch["pelvis_pitch"] + ch["trunk_pitch"]
    for joint in (12, 15):  # neck and head share the work of keeping the gaze level and ahead
        local[:, joint] = yaw_roll_pitch(-0.5 * thorax_yaw, -0.5 * thorax_roll, -0.4 * thorax_pitch)
    local[:, 16] = rot_y(ch["arm_abd"]) @ rot_x(ch["shoulder_l"])
    local[:, 17] = rot_y(-ch["arm_abd"]) @ rot_x(ch["shoulder_r"])
    local[:, 18] = rot_x(ch["elbow_l"])
    local[:, 19] = rot_x(ch["elbow_r"])
    pelvis_fwd = pelvis_rot[:, :, 1] * np.array([1.0, 1.0, 0.0])
    for leg, (hip_j, knee_j, ankle_j, toe_j) in enumerate(((1, 4, 7, 10), (2, 5, 8, 11))):
        ankle, foot_rot = _ankle_targets(feet, leg, body)
        hip = _hip(pelvis, pelvis_rot, body, leg)
        pole = rot_z(feet.yaw[:, leg])[:, :, 1] + pelvis_fwd  # knee over the toes
        thigh, shank, hinge = two_bone_ik(hip, ankle, pole, body.thigh, body.shank)
        local[:, hip_j], local[:, knee_j], local[:, ankle_j] = leg_rotations(pelvis_rot, thigh, shank, hinge, foot_rot)
        local[:, toe_j] = rot_x(0.8 * np.clip(-feet.pitch[:, leg], 0.0, 0.6))  # toes stay flat as the heel rises
    if heading is not None and (np.any(ch["reach_l"] > 0) or np.any(ch["reach_r"] > 0)):
        _arm_ik(body, local, pelvis, heading, ch, goals)
    return local


