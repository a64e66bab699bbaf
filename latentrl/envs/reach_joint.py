"""ReachJoint: put a named joint on a target at a given time (a footstep, the pelvis at a spot, a hand on a switch).

A goal is a joint (:data:`JOINTS`), a target in the world frame (metres, z up, the episode starts with the
pelvis at the xy origin facing +y) and a time in seconds from the episode start. Feet take 2-D targets on the
floor (the error is measured in xy); other joints take 3-D targets, or 2-D ones that ask for the xy only.
A goal's time is resolved to the frame it falls on: frame ``m`` (1-based from the episode start) is frame
``m - 8 k - 1`` (0-based) of step ``k`` and lies ``m / 30`` s after the start. The joint's error at that
frame is the goal's error; the goal succeeds when it is within ``radius``.

Joint-goal files (docs/joint_goals.md) are a JSON list of entries, each a text and goals in time order::

    [{"text": "walk", "goals": [{"joint": "pelvis", "target": [0, 2, 0.86], "time": 2.0},
                                {"joint": "left_foot", "target": [0.1, 2.6], "time": "asap"}]}]

``"asap"`` (as soon as possible) is due when a point leaving the previous goal's target at that goal's time, at
``max_speed``, would reach the target (and at least one frame after the goal becomes current): a run of asap
footsteps keeps the cadence of a walk at ``max_speed``. The first goal, or one added after the previous was
due (``latentrl play``'s queue), is timed from where its joint is when it becomes current.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import torch

from latentrl.config import is_finite_number, require
from latentrl.envs.base import LatentMotionVectorEnv
from latentrl.envs.goal import body_forward, rotate_xy
from latentrl.errors import DataError, check_fields, closest
from latentrl.motion.representation import FUTURE_LENGTH
from latentrl.motion.skeleton import FPS, PELVIS, joint_index
from latentrl.motion.text import prompt_problem
from latentrl.rewards.compose import COMMON_TERMS
from latentrl.safe_io import read_json_file

JOINTS: dict[str, int] = {"pelvis": PELVIS, "left_foot": joint_index("left_foot"),
                          "right_foot": joint_index("right_foot"), "left_hand": joint_index("left_wrist"),
                          "right_hand": joint_index("right_wrist"), "head": joint_index("head")}
"""Goal joint name -> SMPL joint index (hands are the wrists, feet DART's contact joints); the one-hot order."""
FEET = ("left_foot", "right_foot")
"""Joints whose targets lie on the floor (2-D)."""
LEFT_SLOT, RIGHT_SLOT = list(JOINTS).index("left_foot"), list(JOINTS).index("right_foot")
"""The feet's one-hot slots (indices into :data:`JOINTS`)."""
ASAP = "asap"
"""A goal time meaning as soon as possible."""
WINDOW_S = FUTURE_LENGTH / FPS
"""One step of the motion model, 8 frames (0.267 s): goals at most this far ahead are 'near'."""
MAX_FILE_BYTES = 64 << 20
MAX_ENTRIES = 1_000
MAX_GOALS = 1_000
MAX_TIME_S = 3600.0
MAX_COORD_M = 10_000.0
PATH_ACCEL = 1.0
"""m/s^2: how fast the velocity of a run of near goals turns toward its wanted speed and heading (a walk from
rest reaches 1 m/s in a second)."""
RUN_LOST_M = 0.5
"""A run of near goals ends early when a goal is missed by more than this (metres): the next goal starts afresh
from the body."""
MAX_RUN = 1_000
TIME_LEFT_CLIP_S = 10.0
"""The observation's ``time_left`` is clipped to +- this many seconds (the env's ``time_left_clip`` default)."""
_ENTRY_FIELDS = ("text", "goals")
_GOAL_FIELDS = ("joint", "target", "time")


@dataclass(frozen=True)
class JointGoal:
    """One goal: a joint of :data:`JOINTS`, a world target (2-D: xy only) and seconds from the start (None: asap)."""

    joint: str
    target: tuple[float, ...]
    time: float | None

    @property
    def planar(self) -> bool:
        """Whether only the target's xy counts."""
        return len(self.target) == 2


@dataclass(frozen=True)
class JointGoalEntry:
    """One suite entry: the text of the episode and its goals in time order."""

    text: str
    goals: tuple[JointGoal, ...]


def load_joint_goals(file: str | Path) -> list[JointGoalEntry]:
    """Read a joint-goal file; errors name the file, entry, goal and field (0-based)."""
    data = read_json_file(file, "joint-goal file", MAX_FILE_BYTES, DataError)
    return parse_joint_goals(data, str(file))


def parse_joint_goals(data: Any, source: str = "joint goals") -> list[JointGoalEntry]:
    """Validate parsed JSON into :class:`JointGoalEntry` s (module docstring: the format)."""
    if not isinstance(data, list) or not data:
        raise DataError(f'{source}: expected a non-empty list of entries like [{{"text": "walk", "goals": '
                        f'[{{"joint": "pelvis", "target": [x, y, z], "time": seconds}}]}}], got {_kind(data)}')
    if len(data) > MAX_ENTRIES:
        raise DataError(f"{source}: {len(data)} entries, more than the {MAX_ENTRIES} a file may hold")
    return [_parse_entry(item, f"{source}: entry {i}") for i, item in enumerate(data)]


def _kind(value: Any) -> str:
    return "an empty list" if value == [] else type(value).__name__


def _parse_entry(item: Any, where: str) -> JointGoalEntry:
    check_fields(item, _ENTRY_FIELDS, where)
    text, goals = item["text"], item["goals"]
    if not isinstance(text, str) or prompt_problem(text) is not None:
        raise DataError(f"{where}: field 'text' must be a prompt, "
                        f"{prompt_problem(text) if isinstance(text, str) else f'got {text!r:.80}'}")
    if not isinstance(goals, list) or not goals or len(goals) > MAX_GOALS:
        raise DataError(f"{where}: field 'goals' must be a list of 1 to {MAX_GOALS} goals, got {_kind(goals)}"
                        + (f" of {len(goals)}" if isinstance(goals, list) and goals else ""))
    parsed, last = [], 0.0
    for j, goal in enumerate(goals):
        g = _parse_goal(goal, f"{where}, goal {j}")
        if g.time is not None:
            if g.time <= last:
                raise DataError(f"{where}, goal {j}: field 'time' must be after the previous timed goal ({last:g} s), "
                                f"got {g.time:g}")
            last = g.time
        parsed.append(g)
    return JointGoalEntry(text, tuple(parsed))


def _parse_goal(goal: Any, where: str) -> JointGoal:
    check_fields(goal, _GOAL_FIELDS, where)
    joint, target, time = goal["joint"], goal["target"], goal["time"]
    if joint not in JOINTS:
        raise DataError(f"{where}: field 'joint' must be one of {', '.join(JOINTS)}, got {joint!r:.80}"
                        f"{closest(str(joint), tuple(JOINTS))}")
    sizes = (2,) if joint in FEET else (2, 3)
    ok = isinstance(target, list) and len(target) in sizes
    ok = ok and all(is_finite_number(v) and abs(v) <= MAX_COORD_M for v in target)
    if not ok:
        shape = "[x, y] (a foot's target is on the floor)" if joint in FEET else "[x, y, z] or [x, y]"
        raise DataError(f"{where}: field 'target' must be {shape}, finite numbers within +/-{MAX_COORD_M:g} m, "
                        f"got {str(target)[:80]}")
    if time != ASAP and not (is_finite_number(time) and 0 < time <= MAX_TIME_S):
        raise DataError(f"{where}: field 'time' must be seconds in (0, {MAX_TIME_S:g}] or \"{ASAP}\", got {time!r:.80}")
    return JointGoal(joint, tuple(float(v) for v in target), None if time == ASAP else float(time))


def goal_frame(seconds: float) -> int:
    """The frame (1-based from the episode start) a goal time falls on: the nearest, at least 1."""
    return max(1, round(seconds * FPS))


def joint_goal_observation(position: torch.Tensor, rotation: torch.Tensor, target: torch.Tensor,
                           one_hot: torch.Tensor, planar: torch.Tensor, time_left: torch.Tensor, dist_clip: float,
                           time_left_clip: float = TIME_LEFT_CLIP_S) -> torch.Tensor:
    """(N, 12) the goal fields of a ReachJoint observation: goal_vec, goal_dist, joint, planar, time_left.

    ``position`` (N, 3): the goal joint at the last history frame, world; ``rotation`` (N, 3, 3): the body frame
    (canonical-to-world); ``one_hot`` (N, 6) over :data:`JOINTS`; ``planar`` (N,) bool; ``time_left`` (N,) seconds.
    One function for the env and the exported ONNX graph (``latentrl.export.onnx``), so both observe alike.
    """
    vec = target - position
    vec = torch.cat((vec[:, :2], torch.where(planar[:, None], 0.0, vec[:, 2:])), dim=-1)
    dist = torch.linalg.vector_norm(vec, dim=-1, keepdim=True)
    local = (vec[:, None, :] @ rotation)[:, 0] * (dist_clip / dist.clamp(min=dist_clip))
    left = time_left.clamp(-time_left_clip, time_left_clip)
    return torch.cat((local, dist.clamp(max=dist_clip), one_hot, planar.to(local.dtype)[:, None], left[:, None]),
                     dim=1)


def joint_error(position: torch.Tensor, target: torch.Tensor, planar: torch.Tensor) -> torch.Tensor:
    """(..., 3) joint positions, (..., 3) targets, (...) bool planar -> (...) distance, metres (xy where planar)."""
    delta = position - target
    delta = torch.cat((delta[..., :2], torch.where(planar[..., None], 0.0, delta[..., 2:])), dim=-1)
    return torch.linalg.vector_norm(delta, dim=-1)


@dataclass
class ReachJointConfig:
    """``env.reach_joint``: arguments of :class:`ReachJointEnv` (random goals for training)."""

    joints: list[str] = field(default_factory=lambda: ["pelvis"])
    """Goal joints drawn from (uniformly); the observed one-hot always spans every joint of :data:`JOINTS`."""
    radius: float = 0.1
    """A goal succeeds when its joint is within this many metres at the goal time."""
    near_share: float = 0.25
    """Share of fresh goals that start a run of near goals (each within one step, 0.267 s); the rest lie
    ``far_time`` ahead."""
    near_run: list[int] = field(default_factory=lambda: [1, 1])
    """Near goals per run, uniform in [min, max]: targets along a path whose velocity starts at the body's and
    turns toward a wanted speed and heading, each due at most 8 frames after the previous (feet: runs of 1)."""
    turn_deg_s: float = 30.0
    """A run's heading turns at a rate uniform in +/- this, degrees per second."""
    step_run: list[int] = field(default_factory=lambda: [1, 1])
    """Footsteps per run when a foot goal starts a run of near goals, uniform in [min, max]: stepping stones
    alternating feet along a path, ``step_length`` apart and ``step_width`` wide, each due when a walk at the
    run's speed gets there ([1, 1]: a foot takes single near goals)."""
    step_length: list[float] = field(default_factory=lambda: [0.5, 0.7])
    """Metres along the path from one stone to the next, uniform per run of footsteps."""
    step_width: float = 0.18
    """Metres between the lines of the left and the right stones."""
    far_time: list[float] = field(default_factory=lambda: [1.0, 4.0])
    """Lead time of the other goals, uniform in [min, max] seconds."""
    distance: list[float] = field(default_factory=lambda: [0.0, 5.0])
    """Horizontal distance from the joint to a far target, uniform in [min, max] metres, capped by ``max_speed``."""
    max_speed: float = 1.2
    """A goal lies at most this many m/s x its lead time away (walking; the speed of a run of near goals at most);
    asap goals are timed at this speed."""
    angle_deg: float = 90.0
    """Far targets, and the heading a run of near goals turns to, lie within +/- this angle of the body's forward
    axis."""
    height_offset: list[float] = field(default_factory=lambda: [0.0, 0.0])
    """3-D targets sit this much (uniform in [min, max] metres) above the joint's height when drawn."""
    planar: list[str] = field(default_factory=list)
    """Joints besides the feet whose random targets are 2-D (xy only): ``[pelvis]`` is "be at that spot"."""
    goals: str | None = None
    """A joint-goal file (or suite name in tasks/joint_goals) to train on instead of random goals."""

    def validate(self) -> None:
        """Joints known, ranges ordered, radius and speed positive: one-line errors naming the field."""
        require(isinstance(self.joints, list) and len(self.joints) >= 1, "joints",
                f"must list goal joints from {list(JOINTS)}, got {self.joints!r}")
        for name in self.joints:
            require(name in JOINTS, "joints", f"unknown joint {name!r}{closest(str(name), tuple(JOINTS))}; "
                    f"expected some of {list(JOINTS)}")
        for name in self.planar:
            require(name in JOINTS, "planar", f"unknown joint {name!r}{closest(str(name), tuple(JOINTS))}; "
                    f"expected some of {list(JOINTS)}")
        require(is_finite_number(self.radius) and self.radius > 0, "radius", f"must be metres > 0, got {self.radius!r}")
        require(is_finite_number(self.near_share) and 0 <= self.near_share <= 1, "near_share",
                f"must be a share in [0, 1], got {self.near_share!r}")
        for name, low in (("far_time", 1.0 / FPS), ("distance", 0.0), ("height_offset", -10.0)):
            pair = getattr(self, name)
            require(isinstance(pair, list) and len(pair) == 2 and all(map(is_finite_number, pair))
                    and low <= pair[0] <= pair[1], name,
                    f"must be [min, max] with {low:.3g} <= min <= max, got {pair!r}")
        require(isinstance(self.near_run, list) and len(self.near_run) == 2
                and all(isinstance(v, int) and not isinstance(v, bool) for v in self.near_run)
                and 1 <= self.near_run[0] <= self.near_run[1] <= MAX_RUN, "near_run",
                f"must be [min, max] goals with 1 <= min <= max <= {MAX_RUN}, got {self.near_run!r}")
        require(isinstance(self.step_run, list) and len(self.step_run) == 2
                and all(isinstance(v, int) and not isinstance(v, bool) for v in self.step_run)
                and 1 <= self.step_run[0] <= self.step_run[1] <= MAX_RUN, "step_run",
                f"must be [min, max] footsteps with 1 <= min <= max <= {MAX_RUN}, got {self.step_run!r}")
        require(isinstance(self.step_length, list) and len(self.step_length) == 2
                and all(map(is_finite_number, self.step_length))
                and 0.05 <= self.step_length[0] <= self.step_length[1] <= 2.0, "step_length",
                f"must be [min, max] metres with 0.05 <= min <= max <= 2, got {self.step_length!r}")
        require(is_finite_number(self.step_width) and 0 <= self.step_width <= 1, "step_width",
                f"must be metres in [0, 1], got {self.step_width!r}")
        require(is_finite_number(self.turn_deg_s) and 0 <= self.turn_deg_s <= 360, "turn_deg_s",
                f"must be degrees per second in [0, 360], got {self.turn_deg_s!r}")
        require(self.far_time[1] <= MAX_TIME_S, "far_time", f"must end by {MAX_TIME_S:g} s, got {self.far_time!r}")
        require(is_finite_number(self.max_speed) and self.max_speed > 0, "max_speed",
                f"must be m/s > 0, got {self.max_speed!r}")
        require(is_finite_number(self.angle_deg) and 0 <= self.angle_deg <= 180, "angle_deg",
                f"must be degrees in [0, 180], got {self.angle_deg!r}")

    def kwargs(self) -> dict[str, Any]:
        """The constructor arguments of :class:`ReachJointEnv` (a goal file resolved)."""
        goals = None
        if self.goals:
            from latentrl.resources import task_file

            found = task_file(self.goals, "joint_goals")
            require(found is not None, "goals", f"joint-goal file not found: {self.goals}")
            goals = str(found)
        return {"joints": tuple(self.joints), "radius": self.radius, "near_share": self.near_share,
                "near_run": tuple(self.near_run), "turn_deg_s": self.turn_deg_s, "step_run": tuple(self.step_run),
                "step_length": tuple(self.step_length), "step_width": self.step_width,
                "far_time": tuple(self.far_time), "distance": tuple(self.distance), "max_speed": self.max_speed,
                "angle_deg": self.angle_deg, "height_offset": tuple(self.height_offset), "planar": tuple(self.planar),
                "goals": goals}


class ReachJointEnv(LatentMotionVectorEnv):
    """Bring a joint onto a target at a given time.

    ## Description

    The motion model is driven as in :class:`~latentrl.envs.reach.ReachLocationEnv`. The goal is a joint
    (pelvis, left/right foot, left/right hand, head), a target and a goal time (module docstring). At the
    step that holds the goal time, the joint's error at that frame is measured (``infos["joint_error_m"]``)
    and the next goal becomes current. Random goals (training) follow one another until truncation: a fresh
    goal is drawn from the body when the previous one is due, a share ``near_share`` of them starting a run
    of ``near_run`` near goals along a path (each due within one step of the previous, as the targets of a
    file lie on a path: the body must keep up with them), or, for a foot, a run of ``step_run`` footsteps
    alternating feet; the others lie ``far_time`` ahead;
    goals from a file (``goals=``) are an entry's goals in order, and the episode ends after its last.

    ## Observation Space

    ``goal_vec`` (3: target minus the joint's position at the last history frame, in the body frame of
    history frame 0, z = 0 for 2-D targets, clipped to ``obs_goal_dist_clip`` long), ``goal_dist`` (1: its
    length, clipped), ``joint`` (6: one-hot over :data:`JOINTS`), ``planar`` (1: the target is 2-D),
    ``time_left`` (1: seconds from now to the goal time, clipped to +-``time_left_clip``); then text,
    motion and scene.

    ## Rewards

    ``joint_dist`` (the joint's progress toward its target, metres per step; potential-based) and
    ``joint_arrival`` (at the goal time, ``exp(-error / 0.1 m)``), with DART's regularizers ``foot_floor``,
    ``skate``, ``rotation``, ``jerk`` and the common terms.

    ## Episode End

    - Termination: the last goal of a file entry is due (``is_success``: every goal of the entry within
      ``radius``), the pelvis is farther than ``terminate_distance`` from the target, or the motion diverged.
    - Truncation: ``max_episode_steps``.

    ## Arguments

    ``joints``, ``radius``, ``near_share``, ``near_run``, ``turn_deg_s``, ``step_run``, ``step_length``,
    ``step_width``, ``far_time``, ``distance``,
    ``max_speed``, ``angle_deg``, ``height_offset``, ``planar`` (:class:`ReachJointConfig`), ``goals`` (a
    joint-goal file or a list of :class:`JointGoalEntry`; env ``i`` runs entry ``i % E``), ``time_left_clip``
    (10 s); every other argument is :class:`~latentrl.envs.base.LatentMotionVectorEnv`'s.
    """

    goal_fields = (("goal_vec", 3), ("goal_dist", 1), ("joint", len(JOINTS)), ("planar", 1), ("time_left", 1))
    reward_terms = ("joint_dist", "joint_arrival", "foot_floor", "skate", "rotation", "jerk", *COMMON_TERMS)

    def __init__(
        self,
        num_envs: int = 1,
        *,
        joints: Sequence[str] = ("pelvis",),
        radius: float = 0.1,
        near_share: float = 0.25,
        near_run: Sequence[int] = (1, 1),
        turn_deg_s: float = 30.0,
        step_run: Sequence[int] = (1, 1),
        step_length: Sequence[float] = (0.5, 0.7),
        step_width: float = 0.18,
        far_time: Sequence[float] = (1.0, 4.0),
        distance: Sequence[float] = (0.0, 5.0),
        max_speed: float = 1.2,
        angle_deg: float = 90.0,
        height_offset: Sequence[float] = (0.0, 0.0),
        planar: Sequence[str] = (),
        goals: str | Path | Sequence[JointGoalEntry] | None = None,
        time_left_clip: float = TIME_LEFT_CLIP_S,
        **kwargs,
    ):
        section = ReachJointConfig(list(joints), radius, near_share, list(near_run), turn_deg_s, list(step_run),
                                   [float(v) for v in step_length], step_width, [float(v) for v in far_time],
                                   [float(v) for v in distance], max_speed, angle_deg,
                                   [float(v) for v in height_offset], list(planar))
        section.validate()
        require(time_left_clip > 0, "time_left_clip", f"must be > 0 seconds, got {time_left_clip}")
        if isinstance(goals, (str, Path)):
            goals = load_joint_goals(goals)
        self.entries: tuple[JointGoalEntry, ...] | None = tuple(goals) if goals is not None else None
        require(self.entries is None or len(self.entries) > 0, "goals", "give at least one entry")
        self.joints, self.radius, self.near_share = tuple(section.joints), float(radius), float(near_share)
        self.near_run, self.turn = tuple(section.near_run), math.radians(float(turn_deg_s))
        self.step_run, self.step_length = tuple(section.step_run), tuple(section.step_length)
        self.step_width = float(step_width)
        self.far_time, self.distance = tuple(section.far_time), tuple(section.distance)
        self.max_speed, self.angle_deg = float(max_speed), float(angle_deg)
        self.height_offset, self.time_left_clip = tuple(section.height_offset), float(time_left_clip)
        if self.entries is not None and "texts" not in kwargs:
            kwargs["texts"] = tuple(dict.fromkeys(e.text for e in self.entries))
        super().__init__(num_envs, **kwargs)
        n, dev = self.num_envs, self.device
        width = 1 if self.entries is None else max(len(e.goals) for e in self.entries)
        self._target = torch.zeros(n, width, 3, device=dev)
        self._joint = torch.zeros(n, width, dtype=torch.long, device=dev)  # index into JOINTS
        self._planar = torch.zeros(n, width, dtype=torch.bool, device=dev)
        self._frame = torch.zeros(n, width, dtype=torch.long, device=dev)  # goal frame from the start; -1: asap
        self._count = torch.ones(n, dtype=torch.long, device=dev)
        self._gi = torch.zeros(n, dtype=torch.long, device=dev)
        self._goals_ok = torch.zeros(n, dtype=torch.long, device=dev)
        self._rows = torch.arange(n, device=dev)
        self._joint_ids = torch.tensor(list(JOINTS.values()), device=dev)
        self._draw = torch.tensor([list(JOINTS).index(j) for j in self.joints], device=dev)
        flat = set(FEET) | set(section.planar)
        self._flat = torch.tensor([j in flat for j in JOINTS], device=dev)  # per one-hot slot: 2-D targets
        self._step_error = torch.full((n,), math.nan, device=dev)  # the goal error at its frame, this step
        self._due = torch.zeros(n, dtype=torch.bool, device=dev)
        self._record = torch.full((n, width), math.nan, device=dev)  # each goal's error at its frame
        self._future = torch.zeros(n, FUTURE_LENGTH, 22, 3, device=dev)  # the step's new frames, for _score
        # runs of near random goals: goals left after the current one, path velocity, wanted speed, heading, turn
        self._run_left = torch.zeros(n, dtype=torch.long, device=dev)
        self._run_vel = torch.zeros(n, 2, device=dev)
        self._run_speed = torch.zeros(n, device=dev)
        self._run_heading = torch.zeros(n, device=dev)
        self._run_turn = torch.zeros(n, device=dev)
        self._run_stride = torch.zeros(n, device=dev)  # a run of footsteps: metres from stone to stone
        if self.entries is not None:
            self._entry_tables()

    def _entry_tables(self) -> None:
        e, w, dev = len(self.entries), self._target.shape[1], self.device
        self._e_target = torch.zeros(e, w, 3, device=dev)
        self._e_joint = torch.zeros(e, w, dtype=torch.long, device=dev)
        self._e_planar = torch.zeros(e, w, dtype=torch.bool, device=dev)
        self._e_frame = torch.zeros(e, w, dtype=torch.long, device=dev)
        self._e_count = torch.tensor([len(x.goals) for x in self.entries], device=dev)
        self._e_text = torch.tensor([self.texts.index(x.text) for x in self.entries], device=dev)
        for i, entry in enumerate(self.entries):
            for j, g in enumerate(entry.goals):
                xyz = (*g.target, self.floor_height) if g.planar else g.target
                self._e_target[i, j] = torch.tensor(xyz, device=dev)
                self._e_joint[i, j] = list(JOINTS).index(g.joint)
                self._e_planar[i, j] = g.planar
                self._e_frame[i, j] = -1 if g.time is None else goal_frame(g.time)

    # ------------------------------------------------------------------ goals
    @property
    def goal_world(self) -> torch.Tensor:
        """(N, 3) the current goal's target, world metres (z = floor for 2-D targets)."""
        return self._target[self._rows, self._gi]

    def current_goal(self) -> dict[str, torch.Tensor]:
        """The current goal per env: ``target`` (N, 3), ``joint`` (N,) SMPL index, ``planar`` (N,), ``frame`` (N,)."""
        k = self._gi
        return {"target": self._target[self._rows, k], "joint": self._joint_ids[self._joint[self._rows, k]],
                "planar": self._planar[self._rows, k], "frame": self._frame[self._rows, k]}

    def upcoming_goals(self) -> dict[str, torch.Tensor]:
        """Every goal not yet due, per env, the current one first (N, W: the widest entry; random goals: W = 1).

        ``target`` (N, W, 3), ``joint`` (N, W) SMPL index, ``planar`` (N, W), ``offset`` (N, W): frames after the
        last history frame (1 = the next step's first frame), ``valid`` (N, W): a goal of the episode, ``estimated``
        (N, W): an asap goal not yet current, whose offset is this method's estimate of the time it will get
        (:meth:`_estimate_asap`). For planners that look ahead (``latentrl.optim.refine``); random goals after the
        current one are not drawn yet.
        """
        w = self._target.shape[1]
        cols = (self._gi[:, None] + torch.arange(w, device=self.device)).clamp(max=w - 1)
        rows = self._rows[:, None]
        frame = self._frame[rows, cols]
        target, planar = self._target[rows, cols], self._planar[rows, cols]
        joint = self._joint_ids[self._joint[rows, cols]]
        inside = self._gi[:, None] + torch.arange(w, device=self.device) < self._count[:, None]
        estimated = inside & (frame < 0)
        if bool(estimated.any()):
            frame = self._estimate_asap(frame, estimated, target, joint, planar)
        return {"target": target, "joint": joint, "planar": planar, "offset": frame - self._now_frame()[:, None],
                "valid": inside & (frame >= 0), "estimated": estimated}

    def _estimate_asap(self, frame: torch.Tensor, unknown: torch.Tensor, target: torch.Tensor, joint: torch.Tensor,
                       planar: torch.Tensor) -> torch.Tensor:
        """The frames the asap goals ``unknown`` (N, W) will get, as :meth:`_activate` will give them.

        A goal becomes current at the end of the step its predecessor is due in, and is then timed from the
        predecessor's target and time (:meth:`_chained_frame`): exact, as the predecessor's frame is.
        """
        frame = frame.clone()
        for c in range(1, frame.shape[1]):
            todo = unknown[:, c] & (frame[:, c - 1] >= 0)
            if not bool(todo.any()):
                continue
            step_end = torch.div(frame[:, c - 1] + FUTURE_LENGTH - 1, FUTURE_LENGTH, rounding_mode="floor")
            chained = self._chained_frame(frame[:, c - 1], target[:, c - 1], planar[:, c - 1], target[:, c],
                                          planar[:, c], step_end * FUTURE_LENGTH)
            frame[:, c] = torch.where(todo, chained, frame[:, c])
        return frame

    def _chained_frame(self, prev_frame: torch.Tensor, prev_target: torch.Tensor, prev_planar: torch.Tensor,
                       target: torch.Tensor, planar: torch.Tensor, now: torch.Tensor) -> torch.Tensor:
        """The frame of an asap goal after a goal due at ``prev_frame``.

        The time from the previous target at ``max_speed`` (xy when either target is 2-D), and at least one frame
        after ``now``, when the goal becomes current.
        """
        gap = joint_error(prev_target, target, prev_planar | planar)
        lead = torch.ceil(gap / self.max_speed * FPS - 1e-6).long()
        return torch.maximum(prev_frame + lead, now + 1)

    def _now_frame(self, idx: torch.Tensor | None = None) -> torch.Tensor:
        """Frames from the episode start to the last history frame (0 at reset)."""
        steps = self._ep_len if idx is None else self._ep_len[idx]
        return steps.long() * FUTURE_LENGTH

    def _joint_now(self, idx: torch.Tensor, joint: torch.Tensor) -> torch.Tensor:
        """(M, 3) world position of SMPL joint ``joint`` (M,) at the last history frame of envs ``idx``."""
        last = self.history_world(idx)[:, -1]
        return last[torch.arange(len(idx), device=self.device), joint]

    def _sample_goals(self, idx: torch.Tensor) -> None:
        """The next random goal of envs ``idx`` (slot 0): the next of a run of near goals, else a fresh one."""
        going = self._run_left[idx] > 0
        if bool(going.any()):
            on = idx[going]
            foot = (self._joint[on, 0] == LEFT_SLOT) | (self._joint[on, 0] == RIGHT_SLOT)
            if bool(foot.any()):
                self._next_step(on[foot])
            if not bool(foot.all()):
                self._next_in_run(on[~foot])
        if not bool(going.all()):
            self._fresh_goals(idx[~going])

    def _fresh_goals(self, idx: torch.Tensor) -> None:
        """A goal drawn from the body now (:class:`ReachJointConfig`): the first of a run of near goals, or far."""
        m, dev = len(idx), self.device
        pick = self._draw[torch.randint(len(self._draw), (m,), generator=self._generator, device=dev)]
        joint = self._joint_ids[pick]
        near = torch.rand(m, generator=self._generator, device=dev) < self.near_share
        lo = torch.where(near, 1, goal_frame(self.far_time[0]))
        hi = torch.where(near, FUTURE_LENGTH, goal_frame(self.far_time[1]))
        lead = self._randint(lo, hi)
        cap = (self.max_speed * lead.float() / FPS).clamp(max=self.distance[1])
        low = torch.minimum(cap, torch.full_like(cap, self.distance[0]))
        dist = low + (cap - low) * torch.rand(m, generator=self._generator, device=dev)
        history = self.history_world(idx)
        forward, _ = body_forward(history[:, -1])
        a = math.radians(self.angle_deg)
        angle = self._uniform(m, -a, a)
        start = self._joint_now(idx, joint)
        xy = start[:, :2] + rotate_xy(forward, angle) * dist[:, None]
        # a near goal starts a run along a path: the body's velocity turning toward a wanted speed and heading
        feet = (joint == JOINTS["left_foot"]) | (joint == JOINTS["right_foot"])
        length = torch.where(feet, 1, self._randint(torch.full_like(lead, self.near_run[0]),
                                                    torch.full_like(lead, self.near_run[1])))
        self._run_left[idx] = torch.where(near, length - 1, 0)
        pelvis = history[:, :, PELVIS, :2]
        velocity = (pelvis[:, -1] - pelvis[:, -2]) * FPS
        self._run_vel[idx] = velocity * (self.max_speed / velocity.norm(dim=-1, keepdim=True).clamp(min=self.max_speed))
        self._run_speed[idx] = self._uniform(m, 0.0, self.max_speed)
        self._run_heading[idx] = torch.atan2(forward[:, 1], forward[:, 0]) + angle
        self._run_turn[idx] = self._uniform(m, -self.turn, self.turn)
        xy = torch.where(near[:, None], start[:, :2] + self._run_step(idx, lead), xy)
        planar = self._flat[pick]
        z = torch.where(planar, self.floor_height, start[:, 2] + self._uniform(m, *self.height_offset))
        self._target[idx, 0] = torch.cat((xy, z[:, None]), dim=-1)
        self._joint[idx, 0] = pick
        self._planar[idx, 0] = planar
        self._frame[idx, 0] = self._now_frame(idx) + lead
        self._gi[idx] = 0
        if self.step_run[1] > 1 and bool((near & feet).any()):
            self._first_step(idx[near & feet], history[near & feet], forward[near & feet])

    def _aside(self, heading: torch.Tensor, slot: torch.Tensor) -> torch.Tensor:
        """(M, 2) where foot ``slot``'s stone lies from its path point at ``heading``: half the width to its side."""
        right = torch.stack((torch.sin(heading), -torch.cos(heading)), dim=-1)
        return right * (torch.where(slot == RIGHT_SLOT, 0.5, -0.5) * self.step_width)[:, None]

    def _first_step(self, idx: torch.Tensor, history: torch.Tensor, forward: torch.Tensor) -> None:
        """Start a run of footsteps in envs ``idx`` (their near foot goal just drawn): the first stone.

        The path starts at the pelvis, heading forward; the first stone lies half to one stride along it, due
        when the foot gets there at the run's speed (uniform in [max_speed / 2, max_speed]).
        """
        m = len(idx)
        slot = self._joint[idx, 0]
        self._run_stride[idx] = self._uniform(m, *self.step_length)
        self._run_speed[idx] = self._uniform(m, 0.5 * self.max_speed, self.max_speed)
        heading = torch.atan2(forward[:, 1], forward[:, 0])
        self._run_heading[idx] = heading
        self._run_turn[idx] = self._uniform(m, -self.turn, self.turn)
        along = self._run_stride[idx] * self._uniform(m, 0.5, 1.0)
        centre = history[:, -1, PELVIS, :2] + torch.stack((torch.cos(heading), torch.sin(heading)), -1) * along[:, None]
        stone = centre + self._aside(heading, slot)
        foot = self._joint_now(idx, self._joint_ids[slot])[:, :2]
        lead = torch.ceil((stone - foot).norm(dim=-1) / self._run_speed[idx] * FPS).long().clamp(min=1)
        self._target[idx, 0, :2] = stone
        self._frame[idx, 0] = self._now_frame(idx) + lead
        count = self._randint(torch.full_like(lead, self.step_run[0]), torch.full_like(lead, self.step_run[1]))
        self._run_left[idx] = count - 1

    def _next_step(self, idx: torch.Tensor) -> None:
        """The next footstep of a run: the other foot, one stride on along the turning path.

        Due a stride's time at the run's speed after the previous goal (and after now).
        """
        slot = self._joint[idx, 0]
        other = LEFT_SLOT + RIGHT_SLOT - slot
        stride, before, now = self._run_stride[idx], self._frame[idx, 0], self._now_frame(idx)
        gap = torch.maximum(torch.ceil(stride / self._run_speed[idx] * FPS).long().clamp(min=1), now - before + 1)
        heading = self._run_heading[idx]
        centre = self._target[idx, 0, :2] - self._aside(heading, slot)
        heading = heading + self._run_turn[idx] * gap.float() / FPS
        centre = centre + torch.stack((torch.cos(heading), torch.sin(heading)), -1) * stride[:, None]
        self._run_heading[idx] = heading
        self._target[idx, 0, :2] = centre + self._aside(heading, other)
        self._joint[idx, 0] = other
        self._frame[idx, 0] = before + gap
        self._run_left[idx] -= 1

    def _next_in_run(self, idx: torch.Tensor) -> None:
        """The next goal of a run: on the path from the previous target, due 1 to 8 frames after it and after now."""
        now, before = self._now_frame(idx), self._frame[idx, 0]
        gap = self._randint((now - before + 1).clamp(min=1), torch.full_like(now, FUTURE_LENGTH))
        self._target[idx, 0, :2] = self._target[idx, 0, :2] + self._run_step(idx, gap)
        self._frame[idx, 0] = before + gap
        self._run_left[idx] -= 1

    def _run_step(self, idx: torch.Tensor, frames: torch.Tensor) -> torch.Tensor:
        """(M, 2) how far a run's path moves in ``frames`` (M,), its velocity updated.

        The velocity turns toward the wanted speed and heading by at most :data:`PATH_ACCEL` x the time and
        stays within ``max_speed``.
        """
        dt = frames.float() / FPS
        heading = self._run_heading[idx] + self._run_turn[idx] * dt
        self._run_heading[idx] = heading
        want = torch.stack((torch.cos(heading), torch.sin(heading)), dim=-1) * self._run_speed[idx, None]
        change = want - self._run_vel[idx]
        most = (PATH_ACCEL * dt)[:, None]
        change = change * (most / change.norm(dim=-1, keepdim=True).clamp(min=1e-9)).clamp(max=1.0)
        velocity = self._run_vel[idx] + change
        velocity = velocity * (self.max_speed / velocity.norm(dim=-1, keepdim=True).clamp(min=self.max_speed))
        self._run_vel[idx] = velocity
        return velocity * dt[:, None]

    def _randint(self, low: torch.Tensor, high: torch.Tensor) -> torch.Tensor:
        """Integers uniform in [low, high] per element (long tensors of one shape)."""
        u = torch.rand(low.shape, generator=self._generator, device=self.device)
        return low + (u * (high - low + 1)).long().clamp(max=high - low)

    def _activate(self, idx: torch.Tensor) -> None:
        """Give the current goals of envs ``idx`` that are asap their time (module docstring).

        After a goal due in the step just run: from that goal's target and time (:meth:`_chained_frame`). The
        first goal, or one that became current later (a queue's goal added after the previous was due): its
        joint's distance now at ``max_speed``.
        """
        k = self._gi[idx]
        asap = self._frame[idx, k] < 0
        if not bool(asap.any()):
            return
        idx, k = idx[asap], k[asap]
        target, planar = self._target[idx, k], self._planar[idx, k]
        now = self._now_frame(idx)
        dist = joint_error(self._joint_now(idx, self._joint_ids[self._joint[idx, k]]), target, planar)
        frame = now + torch.ceil(dist / self.max_speed * FPS).long().clamp(min=1)
        before = (k - 1).clamp(min=0)
        prev_frame = self._frame[idx, before]
        chained = (k > 0) & (prev_frame > now - FUTURE_LENGTH)
        if bool(chained.any()):
            frame = torch.where(chained, self._chained_frame(prev_frame, self._target[idx, before],
                                                             self._planar[idx, before], target, planar, now), frame)
        self._frame[idx, k] = frame

    def _reset_task(self, idx: torch.Tensor) -> None:
        self._goals_ok[idx] = 0
        self._record[idx] = math.nan
        self._gi[idx] = 0
        if self.entries is None:
            self._text_idx[idx] = self._sample_texts(len(idx))
            self._count[idx] = 1
            self._run_left[idx] = 0
            self._sample_goals(idx)
            return
        e = idx % len(self.entries)
        self._text_idx[idx] = self._e_text[e]
        self._target[idx], self._joint[idx] = self._e_target[e], self._e_joint[e]
        self._planar[idx], self._frame[idx], self._count[idx] = self._e_planar[e], self._e_frame[e], self._e_count[e]
        self._activate(idx)

    def _goal_observation(self, history_world: torch.Tensor) -> torch.Tensor:
        goal = self.current_goal()
        position = history_world[self._rows, -1, goal["joint"]]
        one_hot = torch.nn.functional.one_hot(self._joint[self._rows, self._gi], len(JOINTS)).float()
        left = (goal["frame"] - self._now_frame()).float() / FPS
        return joint_goal_observation(position, self._state.world.rotation, goal["target"], one_hot, goal["planar"],
                                      left, self.obs_goal_dist_clip, self.time_left_clip)

    # ------------------------------------------------------------------ stepping
    def _reached(self, future: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """(N,) the current goal is due in this step and its joint is within ``radius`` at the goal frame."""
        self._future = future
        self._due, self._step_error = self._score(self._now_frame())
        return self._due & (self._step_error < self.radius)

    def _score(self, before_frame: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Whether the current goal falls in the step after frame ``before_frame`` and its error there (NaN if not)."""
        g = self.current_goal()
        j = g["frame"] - before_frame - 1  # 0-based frame of the step
        due = (j >= 0) & (j < FUTURE_LENGTH)
        at = self._future[self._rows, j.clamp(0, FUTURE_LENGTH - 1), g["joint"]]
        return due, torch.where(due, joint_error(at, g["target"], g["planar"]), math.nan)

    def _reward_inputs(self, before, future, goal, reached) -> dict[str, torch.Tensor]:
        """The goal joint's error before the step, at its end (or goal frame) and at the goal frame."""
        g = self.current_goal()
        e_before = joint_error(before[self._rows, -1, g["joint"]], g["target"], g["planar"])
        e_end = joint_error(future[self._rows, -1, g["joint"]], g["target"], g["planar"])
        e_after = torch.where(self._due, self._step_error, e_end)
        return {"joint_error": torch.stack((e_before, e_after, self._step_error), dim=1)}

    def goal_record(self) -> tuple[torch.Tensor, torch.Tensor]:
        """(N, W) error (metres, NaN: not due yet) and frame of every goal of the current episodes, on the CPU.

        Asap goals hold their frame once current (-1 before).
        """
        return self._record.cpu(), self._frame.cpu()

    def _advance_task(self, reached: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Goals due in this step are scored and the next becomes current; a file entry ends after its last.

        Several goals of an entry may fall in one step: each is scored at its own frame (the rewards see the
        first). ``is_success``: file entries, at their end, every goal within ``radius``; random goals, the
        goal due in this step within ``radius``.
        """
        if self.entries is None:
            self._record[self._due, 0] = self._step_error[self._due]
            self._goals_ok += reached.long()
            self._run_left[self._due & (self._step_error > RUN_LOST_M)] = 0
            if bool(self._due.any()):
                self._sample_goals(self._due.nonzero()[:, 0])
            return torch.zeros_like(reached), reached
        return self._advance_listed()

    def _advance_listed(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The goal tables' due goals scored in order, the next made current; (N,) last goal due, all succeeded."""
        before = self._now_frame() - FUTURE_LENGTH
        due, error = self._due, self._step_error
        ended = torch.zeros_like(due)
        while bool(due.any()):
            self._record[self._rows[due], self._gi[due]] = error[due]
            self._goals_ok += (due & (error < self.radius)).long()
            last = due & (self._gi + 1 >= self._count)
            ended |= last
            moved = due & ~last
            self._gi = torch.where(moved, self._gi + 1, self._gi)
            if not bool(moved.any()):
                break
            self._activate(moved.nonzero()[:, 0])
            due, error = self._score(before)
            due &= moved
        return ended, ended & (self._goals_ok == self._count)

    def _task_infos(self, infos: dict[str, Any], reached: torch.Tensor) -> None:
        """``goal_due`` (a goal's time fell in this step) and ``joint_error_m`` (its error; NaN elsewhere)."""
        infos["goal_due"] = self._due.clone()
        infos["joint_error_m"] = self._step_error.clone()
        for key in ("goal_due", "joint_error_m"):
            infos[f"_{key}"] = self._all
