"""Skills, their texts and speed ranges, the transition graph, and ``LocomotionConfig``."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from latentrl.errors import ConfigError, closest

G = 9.81  # m/s^2
_PAD_S = 1.2  # simulated margin before and after each sequence so the first and last steps are whole
_REACH = 0.998  # stance hip-ankle distance kept below this fraction of thigh + shank
_SWING_TO_HELD_S = 0.35  # time for a foot to travel between the floor and a held (lifted) pose
_HELD_MIN_HEIGHT = 0.1  # m, lowest toe height of a held foot
_HELD_AFTER_S = 0.9  # an air spell longer than this holds the foot up in between (no gait swings this long)

#: The locomotion skills: the default skill set (the data of every default model up to v5).
LOCOMOTION_SKILLS: tuple[str, ...] = (
    "walk",
    "run",
    "hop_left",
    "hop_right",
    "jump_forward",
    "turn_left",
    "turn_right",
    "walk_backward",
    "sidestep_left",
    "sidestep_right",
    "stand",
)

#: Skills that change posture or use the scene: crouching, sitting on a seat, getting up, stairs, reaching,
#: waving and picking up from the floor. A config
#: selects them through ``LocomotionConfig.skills``; the default leaves them out, so older configs
#: reproduce their data bit for bit.
SCENE_SKILLS: tuple[str, ...] = (
    "crouch",
    "crouch_walk",
    "sit_down",
    "stand_up",
    "stairs_up",
    "stairs_down",
    "reach_left",
    "reach_right",
    "wave",
    "pick_up",
)

#: Every skill. Each has a synonym list in ``SYNONYMS``; the first synonym is the canonical text.
SKILLS: tuple[str, ...] = LOCOMOTION_SKILLS + SCENE_SKILLS

#: Skill -> texts a segment of that skill may carry (no text belongs to two skills).
SYNONYMS: dict[str, tuple[str, ...]] = {
    "walk": ("walk", "walk forward", "stroll", "walk slowly", "walk fast", "walk briskly"),
    "run": ("run", "jog", "run forward", "jog forward", "run fast"),
    "hop_left": ("hop on left leg", "hop on the left leg", "hop on left foot"),
    "hop_right": ("hop on right leg", "hop on the right leg", "hop on right foot"),
    "jump_forward": ("jump forward", "jump", "leap forward"),
    "turn_left": ("turn left", "walk and turn left", "turn left while walking"),
    "turn_right": ("turn right", "walk and turn right", "turn right while walking"),
    "walk_backward": ("walk backwards", "walk backward", "move backwards"),
    "sidestep_left": ("sidestep left", "side step to the left", "step sideways to the left"),
    "sidestep_right": ("sidestep right", "side step to the right", "step sideways to the right"),
    "stand": ("stand still", "stand", "stand idle"),
    "crouch": ("crouch", "crouch down"),
    "crouch_walk": ("crouch walk", "walk crouched"),
    "sit_down": ("sit down", "sit down on the seat"),
    "stand_up": ("stand up", "get up"),
    "stairs_up": ("walk up stairs", "climb the stairs"),
    "stairs_down": ("walk down stairs", "go down the stairs"),
    "reach_left": ("reach with the left hand", "reach out with the left hand"),
    "reach_right": ("reach with the right hand", "reach out with the right hand"),
    "wave": ("wave", "wave a hand"),
    "pick_up": ("pick up from the floor", "pick something up from the floor"),
}

#: Texts that only describe some speeds: text -> (min, max) speed in m/s; other texts fit any speed.
TEXT_SPEED_RANGE: dict[str, tuple[float, float]] = {
    "stroll": (0.0, 1.15),
    "walk slowly": (0.0, 1.05),
    "walk fast": (1.35, math.inf),
    "walk briskly": (1.35, math.inf),
    "jog": (0.0, 3.1),
    "jog forward": (0.0, 3.1),
    "run fast": (3.4, math.inf),
}

#: Text -> canonical skill (inverse of ``SYNONYMS``).
TEXT_TO_SKILL: dict[str, str] = {text: skill for skill, texts in SYNONYMS.items() for text in texts}

# Allowed transitions (both directions). Jumps start and end standing; running is entered from walking.
_TRANSITIONS: tuple[tuple[str, str], ...] = (
    ("stand", "walk"),
    ("stand", "walk_backward"),
    ("stand", "sidestep_left"),
    ("stand", "sidestep_right"),
    ("stand", "hop_left"),
    ("stand", "hop_right"),
    ("stand", "jump_forward"),
    ("stand", "turn_left"),
    ("stand", "turn_right"),
    ("walk", "run"),
    ("walk", "turn_left"),
    ("walk", "turn_right"),
    ("walk", "hop_left"),
    ("walk", "hop_right"),
    ("walk", "sidestep_left"),
    ("walk", "sidestep_right"),
    ("turn_left", "turn_right"),
    ("sidestep_left", "sidestep_right"),
    ("walk_backward", "sidestep_left"),
    ("walk_backward", "sidestep_right"),
    ("crouch", "crouch_walk"),
    ("stand", "stairs_up"),
    ("walk", "stairs_up"),
    ("stand", "stairs_down"),
    ("walk", "stairs_down"),
    ("stand", "reach_left"),
    ("stand", "reach_right"),
    ("stand", "wave"),
    ("stand", "pick_up"),
)
# One-way transitions: a posture is left only the way it was entered (a crouch or a seat by standing up).
_ONE_WAY: tuple[tuple[str, str], ...] = (
    ("stand", "crouch"),
    ("walk", "crouch"),
    ("stand", "sit_down"),
    ("crouch", "stand_up"),
    ("sit_down", "stand_up"),
    ("stand_up", "stand"),
    ("stand_up", "walk"),
)
#: Skill -> skills it is joined to by a transition in either direction (the undirected graph).
NEIGHBOURS: dict[str, tuple[str, ...]] = {
    s: tuple(sorted({b for a, b in _TRANSITIONS + _ONE_WAY if a == s}
                    | {a for a, b in _TRANSITIONS + _ONE_WAY if b == s}))
    for s in SKILLS
}
#: Skill -> skills it may cross-fade into (``NEIGHBOURS`` less the reverse of the one-way transitions).
FOLLOWERS: dict[str, tuple[str, ...]] = {
    s: tuple(sorted({b for a, b in _TRANSITIONS + _ONE_WAY if a == s} | {a for a, b in _TRANSITIONS if b == s}))
    for s in SKILLS
}
#: Skills a sequence does not start with: a jump starts from standing, a getting-up from a posture.
_NO_START = ("jump_forward", "stand_up")
# Stand and walk connect most skills, so their blocks are shorter to keep the frame counts balanced.
_HUB_SHARE = {"stand": 0.45, "walk": 0.6}
_CANONICAL_WEIGHT = 3.0  # the canonical text is drawn this many times as often as each other synonym


def texts_for(skill: str, speed: float) -> tuple[str, ...]:
    """Synonyms of ``skill`` that fit a segment moving at ``speed`` m/s (see ``TEXT_SPEED_RANGE``)."""

    def fits(text: str) -> bool:
        low, high = TEXT_SPEED_RANGE.get(text, (0.0, math.inf))
        return low <= speed <= high

    return tuple(t for t in SYNONYMS[skill] if fits(t))


@dataclass(frozen=True)
class LocomotionConfig:
    """Settings of the procedural locomotion dataset (defaults: about 50k frames, ~20% transitions)."""

    num_sequences: int = 120
    """Number of sequences (one ``.npz`` file each)."""
    seconds_per_sequence: float = 14.0
    """Length of each sequence in seconds, at 30 fps."""
    seed: int = 0
    """Seed; the dataset is a pure function of the config."""
    skills: tuple[str, ...] = LOCOMOTION_SKILLS
    """Skills to generate (a subset of ``SKILLS``); transitions to skills outside it are skipped. The default
    is the locomotion alone; ``SCENE_SKILLS`` add crouching and sitting."""
    skill_weights: dict[str, float] = field(default_factory=dict)
    """Skill -> relative share of the frames (default 1): the planner balances ``frames / weight`` across
    skills, so a weight of 0.5 gives a skill about half the frames of the others."""
    block_seconds: tuple[float, float] = (2.2, 3.8)
    """Range of the time a skill runs at full weight, in seconds (stand and walk blocks are shorter)."""
    transition_seconds: tuple[float, float] = (0.3, 0.6)
    """Range of the cross-fade between two skills, in seconds; labelled with both skills."""
    height_range: tuple[float, float] = (1.55, 1.90)
    """Body height range in metres; one body per sequence."""
    start_half_size: float = 3.0
    """Sequences start at a uniform point of the square [-s, s]^2 (metres) with a uniform heading."""
    steering: str = "wander"
    """Heading changes of walk, run and hop: ``wander`` (smooth sinusoids, the first default model's data)
    or ``random_hold`` (a yaw rate held 0.25-0.9 s, then switched to a random value: not predictable from
    a 2-frame history, so the diffusion noise can steer)."""
    flights: str = "high"
    """Airborne phases: ``high`` (hop apex 5-15 cm, jump 20-35 cm, the first default model's data) or ``low``
    (hop 3-7 cm, jump 5-10 cm, longer run stance: DART's floor distance <= 5 cm for hops and jumps and
    <= 3 cm for runs, in the data itself)."""
    name: str = "latentrl-procedural-locomotion"
    """Dataset name written to ``meta.json``."""

    def validate(self) -> None:
        """Raise ``ConfigError`` naming the first invalid field."""
        for skill in self.skills:
            if skill not in SKILLS:
                raise ConfigError(f"LocomotionConfig.skills: unknown skill '{skill}'{closest(skill, SKILLS)}; "
                                  f"expected some of {', '.join(SKILLS)}")
        for skill, weight in self.skill_weights.items():
            if skill not in SKILLS:
                raise ConfigError(f"LocomotionConfig.skill_weights: unknown skill '{skill}'{closest(skill, SKILLS)}")
            if not (math.isfinite(weight) and weight > 0):
                raise ConfigError(f"LocomotionConfig.skill_weights.{skill}: {weight}, expected a number > 0")
        if not self.skills:
            raise ConfigError("LocomotionConfig.skills: empty, expected at least one skill")
        if self.steering not in ("wander", "random_hold"):
            raise ConfigError(f"LocomotionConfig.steering: '{self.steering}', expected 'wander' or 'random_hold'")
        if self.flights not in ("high", "low"):
            raise ConfigError(f"LocomotionConfig.flights: '{self.flights}', expected 'high' or 'low'")
        if self.num_sequences < 1:
            raise ConfigError(f"LocomotionConfig.num_sequences: {self.num_sequences}, expected >= 1")
        if self.seconds_per_sequence < 1.0:
            raise ConfigError(f"LocomotionConfig.seconds_per_sequence: {self.seconds_per_sequence}, expected >= 1")
        for name, lo_min in (("block_seconds", 0.5), ("transition_seconds", 0.1), ("height_range", 1.0)):
            lo, hi = getattr(self, name)
            if not lo_min <= lo <= hi:
                raise ConfigError(f"LocomotionConfig.{name}: ({lo}, {hi}), expected {lo_min} <= low <= high")


