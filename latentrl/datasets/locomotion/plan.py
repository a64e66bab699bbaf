"""Planning a sequence: skill blocks, blend weights, the continuous gait phase and the contact schedule."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from latentrl.datasets.body import (
    Body,
)
from latentrl.datasets.locomotion.config import (
    _CANONICAL_WEIGHT,
    _HUB_SHARE,
    _NO_START,
    _SWING_TO_HELD_S,
    FOLLOWERS,
    SYNONYMS,
    LocomotionConfig,
    texts_for,
)
from latentrl.datasets.locomotion.skills import (
    _CHANNEL_DEFAULTS,
    _KEYFRAMED,
    _SKILL_FNS,
    _block_speed,
    _runs,
    _sample_params,
    _smoothstep,
)
from latentrl.motion.skeleton import FPS

# --- planning: skill blocks, weights, phase ---------------------------------------------------------------


@dataclass
class _Block:
    """One skill at full weight for ``core`` frames, cross-faded with its neighbours (padded timeline)."""

    skill: str
    params: dict
    text: str
    core: int  # frames at full weight
    blend_in: int  # frames of the cross-fade from the previous block
    blend_out: int  # frames of the cross-fade into the next block
    start: int = 0  # first frame with weight > 0
    end: int = 0  # one past the last frame with weight > 0
    phase_offset: float = 0.0  # added to the shared phase (jumps align their cycle with the blend)


def _choose(rng: np.random.Generator, options: Sequence[str], counts: dict[str, float],
            weights: dict[str, float] | None = None) -> str | None:
    """Draw a skill, strongly preferring those with the fewest frames (over their ``weights``) so far."""
    if not options:
        return None
    weights = weights or {}
    c = np.array([counts[s] / weights.get(s, 1.0) if s in weights else counts[s] for s in options], dtype=float)
    w = np.exp(-(c - c.min()) / (5.0 * FPS))
    return options[int(rng.choice(len(options), p=w / w.sum()))]


def _pick_text(rng: np.random.Generator, skill: str, speed: float) -> str:
    """A synonym fitting ``speed``; the canonical text (DART's evaluation prompt) is drawn 3x as often."""
    texts = texts_for(skill, speed)
    weights = np.array([_CANONICAL_WEIGHT if t == SYNONYMS[skill][0] else 1.0 for t in texts])
    return texts[int(rng.choice(len(texts), p=weights / weights.sum()))]


def _plan_blocks(
    cfg: LocomotionConfig, rng: np.random.Generator, body: Body, counts: dict[str, float], total: int
) -> list[_Block]:
    """Chain skill blocks along the transition graph until ``total`` frames are filled."""
    skills = tuple(cfg.skills)
    skill = _choose(rng, [s for s in skills if s not in _NO_START] or list(skills), counts, cfg.skill_weights)
    blocks: list[_Block] = []
    used = 0  # frames laid out up to the end of the latest block's core
    while True:
        prev = (blocks[-1].skill, blocks[-1].params) if blocks else None
        p = _sample_params(skill, rng, body, cfg.steering, cfg.flights, prev)
        blend_in = blocks[-1].blend_out if blocks else 0
        blend_out = round(rng.uniform(*cfg.transition_seconds) * FPS)
        if skill == "jump_forward":  # whole jumps between the blend centres, starting and ending in stance
            core = round((p["jumps"] - 0.04) / p["f"] * FPS) - (blend_in + blend_out) // 2
        else:
            core = round(rng.uniform(*cfg.block_seconds) * _HUB_SHARE.get(skill, 1.0) * FPS)
        if skill in _KEYFRAMED:  # the posture change and its shortest hold fit after the cross-fade
            core = max(core, round((p["duration"] + p["hold"]) * FPS))
        text = _pick_text(rng, skill, _block_speed(skill, p))
        block = _Block(skill, p, text, core, blend_in, blend_out)
        blocks.append(block)
        used += blend_in + core
        counts[skill] += blend_in + core
        nxt = _choose(rng, [s for s in FOLLOWERS[skill] if s in skills], counts, cfg.skill_weights)
        if nxt is None or total - used < blend_out + FPS:  # nothing to go to, or too little time left
            block.core += max(total - used, 0)
            block.blend_out = 0
            break
        skill = nxt
    start = 0
    for block in blocks:
        block.start, block.end = start, start + block.blend_in + block.core + block.blend_out
        start = block.end - block.blend_out
    return blocks


def _cycle_rate(blocks: Sequence[_Block], weights: np.ndarray) -> np.ndarray:
    """(T,) gait-cycle frequency (cycles/s): the weighted rate of the stepping skills.

    Standing has no gait, so it does not pull the rate of the skill it fades with (a walk slowing towards a
    stand keeps its cadence); across a pure stand the rate moves linearly to the next skill's, and a jump
    after a stand starts on its own rate, which the jump's cycle alignment relies on.
    """
    stepping = np.array([b.skill != "stand" and b.skill not in _KEYFRAMED for b in blocks])
    if not stepping.any():
        return np.ones(weights.shape[1])
    rates = np.array([b.params["f"] for b in blocks])
    wsum = weights[stepping].sum(axis=0)
    known = wsum > 1e-9
    frames = np.arange(weights.shape[1])
    rate = (rates[stepping] @ weights[stepping])[known] / wsum[known]
    return np.interp(frames, frames[known], rate)


_MOTION_CHANNELS = ("v_fwd", "v_side", "yaw_rate")


def _weights(ramps: Sequence[tuple[int, int]], total: int) -> np.ndarray:
    """(B, T) block weights; block i fades into block i+1 with a smoothstep over ``ramps[i]`` = [a, b).

    Stick-breaking (block i keeps ``prod_{j<i} rise_j * (1 - rise_i)``), so the weights sum to one even
    where two ramps overlap.
    """
    w = np.empty((len(ramps) + 1, total))
    frames = np.arange(total)
    remaining = np.ones(total)
    for i, (a, b) in enumerate(ramps):
        rise = _smoothstep((frames - a + 0.5) / max(b - a, 1))
        w[i] = remaining * (1.0 - rise)
        remaining = remaining * rise
    w[-1] = remaining
    return w


def _motion_ramps(blocks: Sequence[_Block], switches: Sequence[int], total: int) -> list[tuple[int, int]]:
    """Frames over which the root velocity fades from each block to the next.

    Stance lengths follow the contact schedule, so the speed must match the schedule that is stepping: a
    speed-up (a start from standing, walk to run) ramps after the contact switch, beginning with the first
    new step; a slow-down ramps before it, so the longer stances of the slower skill start at its speed.
    """
    ramps = []
    for a, b, switch in zip(blocks[:-1], blocks[1:], switches):
        if _block_speed(b.skill, b.params) >= _block_speed(a.skill, a.params):
            ramps.append((switch, min(switch + a.blend_out, total)))
        else:
            ramps.append((max(switch - a.blend_out, 0), switch))
    return ramps


def _evaluate_blocks(blocks: Sequence[_Block], phase: np.ndarray, t: np.ndarray, body: Body):
    """Each block's channels and (T, 2) contact schedule, evaluated on the whole timeline."""
    return [_SKILL_FNS[b.skill](phase + b.phase_offset, t, b.params, body) for b in blocks]


def _blend_channels(evaluated: Sequence[tuple[dict, np.ndarray]], weights: np.ndarray,
                    motion_weights: np.ndarray) -> dict[str, np.ndarray]:
    """Weighted sum of the blocks' channels; root-motion channels use ``motion_weights``."""
    ch = {}
    for k in _CHANNEL_DEFAULTS:
        w = motion_weights if k in _MOTION_CHANNELS else weights
        ch[k] = sum(wi * block_ch[k] for wi, (block_ch, _) in zip(w, evaluated))
    return ch


# --- contacts ---------------------------------------------------------------------------------------------


def _leading_run(mask: np.ndarray) -> int:
    """Length of the run of True values at the start of ``mask``."""
    return len(mask) if mask.all() else int(np.argmin(mask))


def _switch_frame(current: np.ndarray, incoming: np.ndarray, lo: int, hi: int) -> int:
    """Frame in the cross-fade [lo, hi) at which the contact schedule switches.

    Near the middle of the cross-fade, preferring frames where both schedules agree on which feet are down.
    """
    if hi <= lo:
        return lo
    frames = np.arange(lo, hi)
    cost = np.abs(frames - 0.5 * (lo + hi - 1)) / (hi - lo) + 0.5 * np.sum(
        current[frames] != incoming[frames], axis=-1
    )
    return int(frames[np.argmin(cost)])


def _clean_contacts(mask: np.ndarray, min_frames: int = 4) -> np.ndarray:
    """Fill interior air gaps and drop contacts shorter than ``min_frames`` (switching leftovers)."""
    mask = mask.copy()
    for a, b in _runs(~mask):
        if a > 0 and b < len(mask) and b - a < min_frames:
            mask[a:b] = True
    for a, b in _runs(mask):
        if b - a < min_frames and a > 0 and b < len(mask):
            mask[a:b] = False
    return mask


def _compose_contacts(blocks: Sequence[_Block], schedules: Sequence[np.ndarray]) -> tuple[np.ndarray, list[int]]:
    """(T, 2) bool foot contacts, each block's schedule from its switch frame on, and the switch frames.

    A foot in the air under the old schedule but down under the new one finishes its swing first (lands at
    the old schedule's touch-down), so a walk that stops ends with a closing step rather than a foot slapped
    down mid-swing; a foot the old schedule never puts down (a hop's held leg) comes down in
    ``_SWING_TO_HELD_S``.
    """
    contact = schedules[0].copy()
    switches = []
    for prev, block, incoming in zip(blocks[:-1], blocks[1:], schedules[1:]):
        switch = _switch_frame(contact, incoming, block.start, prev.end)
        switches.append(switch)
        for leg in range(2):
            new = incoming[switch:, leg].copy()
            if new[0] and not contact[switch, leg]:
                air = _leading_run(~contact[switch:, leg])
                new[: air if air <= FPS // 2 else round(_SWING_TO_HELD_S * FPS)] = False
            contact[switch:, leg] = new
    return np.stack([_clean_contacts(contact[:, leg]) for leg in range(2)], axis=-1), switches


