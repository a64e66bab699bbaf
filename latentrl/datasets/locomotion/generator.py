"""One sequence from its plan, the public generator API and dataset statistics."""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from latentrl.datasets.body import (
    Body,
    make_body,
    matrix_to_axis_angle_np,
    yaw_roll_pitch,
)
from latentrl.datasets.locomotion.config import _PAD_S, SKILLS, TEXT_TO_SKILL, G, LocomotionConfig
from latentrl.datasets.locomotion.feet import (
    _Feet,
    _ground_under_feet,
    _held_feet,
    _local_rotations,
    _plant_feet,
    _reach_drop,
    _stairs,
    _support_level,
    _swing_feet,
)
from latentrl.datasets.locomotion.plan import (
    _blend_channels,
    _Block,
    _compose_contacts,
    _cycle_rate,
    _evaluate_blocks,
    _motion_ramps,
    _plan_blocks,
    _weights,
)
from latentrl.datasets.locomotion.skills import _KEYFRAMED, _block_speed
from latentrl.datasets.motion_text import make_sequence, write_meta, write_sequence
from latentrl.motion.contacts import foot_positions, weighted_foot_slide
from latentrl.motion.heading import hip_yaw_rad
from latentrl.motion.skeleton import FOOT_JOINTS, FPS

# --- one sequence -----------------------------------------------------------------------------------------


def _schedule(cfg: LocomotionConfig, rng: np.random.Generator, body: Body, counts: dict[str, float],
              total: int, pad: int) -> tuple[list[_Block], dict[str, np.ndarray], np.ndarray]:
    """Steps 1-2: skill blocks, blended (T,) channels and (T, 2) foot contacts on the padded timeline."""
    t = np.arange(total) / FPS
    blocks = _plan_blocks(cfg, rng, body, counts, total)
    weights = _weights([(b.start, a.end) for a, b in zip(blocks[:-1], blocks[1:])], total)
    phase = rng.uniform() + np.cumsum(_cycle_rate(blocks, weights)) / FPS
    for b in blocks:
        if b.skill in _KEYFRAMED:  # the posture changes once the cross-fade into its block is over
            b.params["t0"] = (b.start + b.blend_in) / FPS
        if b.skill == "jump_forward":  # jump phase 0 (start of the standing lead-in) at the blend centre
            b.phase_offset = -phase[b.start + b.blend_in // 2] if b.blend_in else 0.9 - phase[pad]
    evaluated = _evaluate_blocks(blocks, phase, t, body)
    contact, switches = _compose_contacts(blocks, [c for _, c in evaluated])
    motion_ramps = _motion_ramps(blocks, switches, total)
    for a, b, (start, end) in zip(blocks[:-1], blocks[1:], motion_ramps):  # label the whole speed change
        if b.skill in _KEYFRAMED and _block_speed(a.skill, a.params) == 0.0:
            continue  # no speed change: the labels switch where the posture starts to change (at ``t0``)
        a.end, b.start = max(a.end, end), min(b.start, start)
    ch = _blend_channels(evaluated, weights, _weights(motion_ramps, total))
    lean = -0.6 * np.arctan(ch["v_fwd"] * ch["yaw_rate"] / G)  # lean into turns
    ch["pelvis_roll"] += 0.5 * lean
    ch["trunk_roll"] += 0.5 * lean
    return blocks, ch, contact


@dataclass
class _Terrain:
    """The ground of one sequence: its stair flights and the height under each foot."""

    flights: np.ndarray  # (J, 8) rows of ``latentrl.scenes.Stairs`` (see ``feet._stairs``)
    ground: np.ndarray  # (T, 2) terrain height under the left and right toe joints, padded timeline


def _trajectories(cfg: LocomotionConfig, rng: np.random.Generator, body: Body, ch: dict, contact: np.ndarray,
                  blocks: list[_Block]) -> tuple[np.ndarray, np.ndarray, _Feet, np.ndarray, _Terrain]:
    """Steps 3-4: the pelvis, the foot targets and the ground.

    Returns (T, 3) pelvis position and (T, 3, 3) orientation (world), the foot targets, the (T,) heading
    and the terrain (stair flights built under the stair blocks' steps).
    """
    heading = rng.uniform(0, 2 * math.pi) + np.cumsum(ch["yaw_rate"]) / FPS
    c, s = np.cos(heading), np.sin(heading)
    vel = np.stack((c * ch["v_side"] - s * ch["v_fwd"], s * ch["v_side"] + c * ch["v_fwd"]), axis=-1)
    root_xy = rng.uniform(-cfg.start_half_size, cfg.start_half_size, 2) + np.cumsum(vel, axis=0) / FPS
    offset = np.stack((c * ch["sway"] - s * ch["surge"], s * ch["sway"] + c * ch["surge"]), axis=-1)
    pelvis = np.concatenate((root_xy + offset, (body.pelvis_height + ch["dz"])[:, None]), axis=-1)
    pelvis_rot = yaw_roll_pitch(heading + ch["pelvis_yaw"], ch["pelvis_roll"], ch["pelvis_pitch"])
    feet = _plant_feet(contact, root_xy, heading, ch, body)
    flights, spans, level = _stairs(blocks, feet, contact, heading)
    if flights:  # the body rides on the ground its feet stand on
        pelvis[:, 2] += _support_level(level, contact)
    pelvis[:, 2] -= _reach_drop(pelvis, pelvis_rot, feet, body)
    held, held_pitch = _held_feet(pelvis, pelvis_rot, heading, ch, body)
    _swing_feet(feet, held, held_pitch, heading, pelvis[:, 2], ch, level if flights else None)
    ground = _ground_under_feet(flights, spans, level, feet.grounded, feet.toe) if flights else level
    return pelvis, pelvis_rot, feet, heading, _Terrain(np.array(flights, dtype=np.float64).reshape(-1, 8), ground)


def _seats(blocks: list[_Block], pelvis: np.ndarray, heading: np.ndarray, ground: np.ndarray,
           visible: tuple[int, int]) -> np.ndarray:
    """(K, 4) seats of the ``sit_down`` blocks seen in the ``visible`` frames: x, y, height, facing yaw.

    The seat point is the pelvis' ground position once seated; the height is the seat top's z (its
    height above the ground it stands on, plus that ground); the yaw is the direction the sitter faces,
    in radians counter-clockwise from +x (``latentrl.scenes.Seat``'s ``yaw_deg``, in radians).
    """
    seats = []
    for b in blocks:
        if b.skill != "sit_down" or not (b.start < visible[1] and b.end > visible[0]):
            continue
        at = min(round((b.params["t0"] + b.params["duration"]) * FPS), len(pelvis) - 1)
        facing = math.atan2(math.cos(heading[at]), -math.sin(heading[at]))
        seats.append((pelvis[at, 0], pelvis[at, 1], b.params["seat"] + ground[at].mean(), facing))
    return np.array(seats, dtype=np.float32).reshape(-1, 4)


def _simulate(cfg: LocomotionConfig, index: int, counts: dict[str, float]) -> dict[str, np.ndarray]:
    """One sequence in the motion-text format (fields of ``motion_text.FIELDS``)."""
    rng = np.random.default_rng([cfg.seed, index])
    body = make_body(rng.uniform(*cfg.height_range))
    pad, frames = round(_PAD_S * FPS), round(cfg.seconds_per_sequence * FPS)
    blocks, ch, contact = _schedule(cfg, rng, body, counts, frames + 2 * pad, pad)
    pelvis, pelvis_rot, feet, heading, terrain = _trajectories(cfg, rng, body, ch, contact, blocks)
    keep = slice(pad, pad + frames)  # step 5 on the visible frames only
    goals: dict[str, np.ndarray] = {}
    local = _local_rotations(body, pelvis[keep], pelvis_rot[keep], {k: v[keep] for k, v in ch.items()},
                             _Feet(feet.toe[keep], feet.yaw[keep], feet.pitch[keep], feet.grounded[keep]),
                             heading[keep], goals)
    segments = [(max(b.start, pad) - pad, min(b.end, pad + frames) - pad, b.text) for b in blocks
                if min(b.end, pad + frames) > max(b.start, pad)]
    seq = make_sequence(body.rest_joints, matrix_to_axis_angle_np(local), pelvis[keep] - body.rest_joints[0],
                        segments)
    seats = _seats(blocks, pelvis, heading, terrain.ground, (pad, pad + frames))
    if len(seats):
        seq["seats"] = seats
    reaches = _reaches(blocks, goals, pad, frames)
    if len(reaches):
        seq["reaches"] = reaches
    if len(terrain.flights):
        seq["stairs"] = terrain.flights.astype(np.float32)
        seq["foot_floor"] = terrain.ground[keep].astype(np.float32)
    return seq


def _reaches(blocks: list[_Block], goals: dict[str, np.ndarray], pad: int, frames: int) -> np.ndarray:
    """(R, 6) hand targets held in the visible frames: x, y, z, hand (0 left, 1 right), first and last frame.

    One row per reach and pick-up block whose hold (the hand on its target) lies in the visible frames;
    the target is the world point the hand is placed on (``feet._arm_ik``) in the middle of the hold.
    """
    rows = []
    for b in blocks:
        if b.skill not in ("reach_left", "reach_right", "pick_up"):
            continue
        p = b.params
        first = round((p["t0"] + p["move"]) * FPS) - pad
        last = round((p["t0"] + p["move"] + p["hold_s"]) * FPS) - pad
        first, last = max(first, 0), min(last, frames - 1)
        side = "r" if p["hand"] else "l"
        if last - first < 2 or side not in goals:
            continue
        target = goals[side][(first + last) // 2]
        rows.append((*target, p["hand"], first, last))
    return np.array(rows, dtype=np.float32).reshape(-1, 6)


# --- public API -------------------------------------------------------------------------------------------


def generate_sequences(cfg: LocomotionConfig) -> list[dict[str, np.ndarray]]:
    """Generate every sequence in memory: a list of dicts with the motion-text fields (float32/int32/str)."""
    cfg.validate()
    counts = {s: 0.0 for s in cfg.skills}
    return [_simulate(cfg, i, counts) for i in range(cfg.num_sequences)]


def generate_dataset(cfg: LocomotionConfig, out_dir: str | Path, overwrite: bool = False) -> list[Path]:
    """Write ``seq_00000.npz``... and ``meta.json`` into ``out_dir``; returns the sequence paths.

    Refuses a folder that already holds ``.npz`` files unless ``overwrite`` (which first deletes them and
    ``meta.json``), so stale sequences of an earlier, larger run never mix into the dataset.
    """
    from latentrl.errors import DataError

    out_dir = Path(out_dir)
    old = sorted(out_dir.glob("*.npz")) if out_dir.is_dir() else []
    if old and not overwrite:
        raise DataError(f"{out_dir}: already holds {len(old)} .npz files, expected an empty folder "
                        "(or pass overwrite=True)")
    for path in old + [out_dir / "meta.json"]:
        path.unlink(missing_ok=True)
    started = time.perf_counter()
    seqs = generate_sequences(cfg)
    seconds = time.perf_counter() - started
    paths = [write_sequence(out_dir / f"seq_{i:05d}.npz", seq, check_fk=False) for i, seq in enumerate(seqs)]
    stats = dataset_statistics(seqs)
    write_meta(out_dir, {
        "name": cfg.name,
        "generator": "latentrl.datasets.locomotion",
        "licence": "MIT (procedurally generated by latentrl; contains no recorded motion)",
        "seed": cfg.seed,
        "fps": FPS,
        "config": asdict(cfg),
        "num_sequences": len(paths),
        "frames": stats["frames"],
        "transition_frames": stats["transition_frames"],
        "frames_per_skill": {k: v["frames"] for k, v in stats["skills"].items()},
        "frames_per_text": stats["texts"],
        "generation_seconds": round(seconds, 2),
    })
    return paths


def foot_skate(joints: np.ndarray, horizontal: bool = False) -> np.ndarray:
    """(T-1,) contact-weighted foot displacement per frame pair (m), DART's ``calc_skate`` before averaging.

    ``joints`` (T, 22, 3) world, z up. Each foot joint (10, 11) moves ``|d|`` between frames and is weighted by
    ``2 - 2**clamp(max(h_t, h_t-1) / 0.03, 0, 1)`` (h = its height above the floor); the two feet are averaged.
    ``horizontal`` measures only the xy displacement (sliding), leaving out lift-off and touch-down.
    """
    feet = foot_positions(torch.from_numpy(np.asarray(joints)))
    return weighted_foot_slide(feet, horizontal=horizontal).mean(dim=-1).numpy()


_STAT_KEYS = ("frames", "pure", "pairs", "speed", "skate", "skate_xy", "floor", "left_only", "right_only")
_CONTACT_SHARE_M = 0.05  # a foot joint this close to the floor counts as down (as ``bench motion``'s shares)
_STEER_WINDOW = 32  # frames: the window of ``bench motion``'s steering spread (4 primitives)


def _window_turns(yaw: np.ndarray, mask: np.ndarray, stride: int = 8) -> list[float]:
    """Yaw changes (deg) over every ``_STEER_WINDOW``-frame window (step ``stride``) inside ``mask``."""
    out = []
    for start in range(0, len(yaw) - _STEER_WINDOW, stride):
        if mask[start:start + _STEER_WINDOW + 1].all():
            out.append(math.degrees(yaw[start + _STEER_WINDOW] - yaw[start]))
    return out


def _spread_deg(turns: list[float]) -> float | None:
    """5-95 % spread of the window turns, degrees (the data's side of ``bench motion``'s steer column)."""
    if len(turns) < 20:
        return None
    lo, hi = np.percentile(turns, [5, 95])
    return round(float(hi - lo), 2)


def dataset_statistics(seqs: Sequence[dict[str, np.ndarray]]) -> dict:
    """Frames per skill and text, the transition share, and per-skill speed, skate and floor metrics.

    Speeds and metrics use frames labelled with a single skill (not transitions): ``speed_m_s`` is the mean
    horizontal pelvis speed, ``skate_cm_s`` DART's contact-weighted skate (x fps, in cm/s), ``skate_xy_cm_s``
    the same on horizontal displacement only, and ``floor_cm`` the mean |lowest foot joint height| (DART's
    floor distance, in cm); foot heights count from the ground under each foot (``foot_floor``) where a
    sequence has stairs.
    """
    acc: dict[str, dict[str, float]] = {}
    steer: dict[str, list[float]] = {}
    texts: dict[str, int] = {}
    total = transitions = 0
    for seq in seqs:
        num = len(seq["transl"])
        labels = np.zeros(num, dtype=int)
        owner = np.full(num, "", dtype=object)
        for a, b, text in zip(seq["seg_start"], seq["seg_end"], seq["seg_text"]):
            skill = TEXT_TO_SKILL.get(str(text), str(text))
            labels[a:b] += 1
            owner[a:b] = skill
            texts[str(text)] = texts.get(str(text), 0) + int(b - a)
            acc.setdefault(skill, dict.fromkeys(_STAT_KEYS, 0.0))
            acc[skill]["frames"] += int(b - a)
        total += num
        transitions += int(np.sum(labels > 1))
        joints = seq["joints"].astype(np.float64)
        if "foot_floor" in seq:  # on stairs the feet's heights count from the ground under them
            joints = joints.copy()
            joints[:, list(FOOT_JOINTS), 2] -= seq["foot_floor"].astype(np.float64)
        pure = labels == 1
        pair = pure[1:] & pure[:-1] & (owner[1:] == owner[:-1])
        speed = np.linalg.norm(np.diff(joints[:, 0, :2], axis=0), axis=-1) * FPS
        skate, skate_xy = foot_skate(joints), foot_skate(joints, horizontal=True)
        floor = np.abs(joints[:, list(FOOT_JOINTS), 2].min(axis=-1))
        yaw = hip_yaw_rad(torch.from_numpy(joints)).numpy()
        feet_down = joints[:, list(FOOT_JOINTS), 2] < _CONTACT_SHARE_M
        for skill in set(owner[pure]):
            m, mp = pure & (owner == skill), pair & (owner[1:] == skill)
            a = acc[skill]
            a["pure"] += int(m.sum())
            a["floor"] += float(floor[m].sum())
            a["pairs"] += int(mp.sum())
            a["speed"] += float(speed[mp].sum())
            a["skate"] += float(skate[mp].sum())
            a["skate_xy"] += float(skate_xy[mp].sum())
            a["left_only"] += float((feet_down[m, 0] & ~feet_down[m, 1]).sum())
            a["right_only"] += float((feet_down[m, 1] & ~feet_down[m, 0]).sum())
            steer.setdefault(skill, []).extend(_window_turns(yaw, m))
    skills = {}
    for skill, a in sorted(acc.items(), key=lambda kv: SKILLS.index(kv[0]) if kv[0] in SKILLS else 99):
        pairs, pure = max(a["pairs"], 1), max(a["pure"], 1)
        skills[skill] = {
            "frames": int(a["frames"]),
            "single_label_frames": int(a["pure"]),
            "speed_m_s": round(a["speed"] / pairs, 3),
            "skate_cm_s": round(100 * FPS * a["skate"] / pairs, 3),
            "skate_xy_cm_s": round(100 * FPS * a["skate_xy"] / pairs, 3),
            "floor_cm": round(100 * a["floor"] / pure, 3),
            "left_only": round(a["left_only"] / pure, 3),
            "right_only": round(a["right_only"] / pure, 3),
            "steer_spread_deg": _spread_deg(steer.get(skill, [])),
        }
    return {"frames": total, "transition_frames": transitions,
            "transition_fraction": round(transitions / max(total, 1), 3), "skills": skills, "texts": texts}
