"""Sit and get up: walk to a seat, sit on it, hold, stand up and walk away (CLoSD's sit and get-up tasks, kinematic).

Each episode has one seat (a box ``seat_size`` wide, its top ``seat_height`` above the floor, a sitter facing
``facing``), drawn per episode (height uniform in 0.2-0.6 m, CLoSD's perturbed protocol) or taken from a seat
file. The env runs a state machine and switches the text itself (CLoSD section 4.4):

====  ==========  ============  ===========================================================================
phase name        text          ends when
====  ==========  ============  ===========================================================================
0     approach    walk          the pelvis comes within ``approach_radius`` (xy) of the sit-down spot,
                                ``approach_offset`` in front of the seat centre, the body facing within
                                ``approach_facing_deg`` of the sitter's facing (its back to the seat)
1     sit         sit down      **sit success**: for ``hold_frames`` frames in a row the pelvis is within
                                ``sit_radius`` (xy) of the seat centre and within ``height_tolerance`` of the
                                seated height (seat top + :data:`SEATED_PELVIS_ABOVE_SEAT_M`)
2     stand       stand up      the pelvis is back at ``stand_fraction`` of its standing height
3     leave       walk          **get-up success**: the pelvis at ``stand_fraction`` of its standing height and
                                at least ``leave_distance`` (xy) from the seat centre; the episode ends
====  ==========  ============  ===========================================================================

With ``settle_steps`` > 0 the sit phase begins with that many primitives of ``settle_text`` (``stand still``).

The goal (observed as ``goal_dir``/``goal_dist``, rewarded by ``dist``) is the sit-down spot in phase 0, the seat
centre in phase 1 and the leave point (``leave_distance`` in front of the seat) after. ``success`` pays 1 at
each phase's end but the stand-up; ``pelvis_height`` pulls the pelvis to the seated height in phase 1 and to the
standing height in phase 2. The prompts must be in the motion model (the default model from v6 has
``sit down`` and ``stand up``).

Seat files (``latentrl/tasks/sit/*.json``) are a JSON list of seats in the world frame (metres, z up, the episode
starts with the pelvis at the origin facing +y; ``facing_deg`` 0 = a sitter facing +x)::

    [{"center": [0.4, 2.2], "seat_height": 0.45, "facing_deg": 90}]
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
from latentrl.envs.scene import EnvScene
from latentrl.errors import DataError, check_fields
from latentrl.motion.skeleton import PELVIS
from latentrl.rewards.compose import COMMON_TERMS
from latentrl.safe_io import read_json_file
from latentrl.scenes.scene import Scene, SceneBatch

SEATED_PELVIS_ABOVE_SEAT_M = 0.09
"""The pelvis joint's height above the seat top when seated (the procedural data's, ``datasets.locomotion``)."""
PHASES = ("approach", "sit", "stand", "leave")
MAX_SEATS = 1_000
MAX_FILE_BYTES = 1 << 20
MAX_COORD_M = 100.0
_SEAT_FIELDS = ("center", "seat_height", "facing_deg")


@dataclass(frozen=True)
class SeatSpec:
    """One seat of a seat file: centre (x, y), top height above the floor, the facing of a sitter (degrees)."""

    center: tuple[float, float]
    seat_height: float
    facing_deg: float


def load_seats(file: str | Path) -> list[SeatSpec]:
    """Read a seat file; errors name the file, the seat index and the field."""
    return parse_seats(read_json_file(file, "seat file", MAX_FILE_BYTES, DataError), str(file))


def parse_seats(data: Any, source: str = "seats") -> list[SeatSpec]:
    """Check parsed JSON (module docstring: the format) into :class:`SeatSpec` s; one-line :class:`DataError`."""
    if not isinstance(data, list) or not data or len(data) > MAX_SEATS:
        raise DataError(f'{source}: expected a list of 1 to {MAX_SEATS} seats like [{{"center": [x, y], '
                        f'"seat_height": 0.45, "facing_deg": 90}}], got {type(data).__name__}'
                        + (f" of {len(data)}" if isinstance(data, list) else ""))
    seats = []
    for i, item in enumerate(data):
        where = f"{source}: seat {i}"
        check_fields(item, _SEAT_FIELDS, where)
        c, h, f = item["center"], item["seat_height"], item["facing_deg"]
        if not (isinstance(c, list) and len(c) == 2 and all(is_finite_number(v) and abs(v) <= MAX_COORD_M
                                                            for v in c)):
            raise DataError(f"{where}: field 'center' must be [x, y] within +/-{MAX_COORD_M:g} m, got {str(c)[:60]}")
        if not (is_finite_number(h) and 0.05 <= h <= 1.5):
            raise DataError(f"{where}: field 'seat_height' must be metres in [0.05, 1.5], got {h!r:.40}")
        if not (is_finite_number(f) and -360 <= f <= 360):
            raise DataError(f"{where}: field 'facing_deg' must be degrees in [-360, 360], got {f!r:.40}")
        seats.append(SeatSpec((float(c[0]), float(c[1])), float(h), float(f)))
    return seats


def _pair(value: Sequence[float], name: str, low: float, high: float) -> tuple[float, float]:
    ok = isinstance(value, (list, tuple)) and len(value) == 2 and all(is_finite_number(v) for v in value)
    require(ok and low <= value[0] <= value[1] <= high, name,
            f"must be [min, max] with {low:g} <= min <= max <= {high:g}, got {value}")
    return float(value[0]), float(value[1])


@dataclass
class SitConfig:
    """``env.options`` of the sit task: the seat draw, the success definitions and the prompts (module docstring)."""

    seat_height: list[float] = field(default_factory=lambda: [0.2, 0.6])
    """Seat top above the floor, metres, uniform in [min, max] (CLoSD's perturbed protocol: 0.2-0.6)."""
    seat_distance: list[float] = field(default_factory=lambda: [1.5, 3.0])
    """Seat centre from the start pelvis, metres."""
    seat_angle_deg: float = 60.0
    """Seat centre within +/- this of the start forward axis; the sitter's facing is uniform over 360 degrees."""
    seat_size: list[float] = field(default_factory=lambda: [0.5, 0.5])
    """Seat footprint (depth along the facing, width), metres."""
    approach_offset: float = 0.4
    """The sit-down spot lies this far in front of the seat centre, metres."""
    approach_radius: float = 0.3
    approach_facing_deg: float | None = 45.0
    """The approach also needs the body's forward axis within this of the sitter's facing, degrees (None: any).
    Why: a sit down lowers the pelvis back over planted feet (about a thigh length), so a body that arrives
    facing the seat sits down beside it, not on it."""
    sit_radius: float = 0.3
    height_tolerance: float = 0.05
    hold_frames: int = 15
    leave_distance: float = 0.6
    stand_fraction: float = 0.9
    walk_text: str = "walk"
    sit_text: str = "sit down"
    stand_text: str = "stand up"
    settle_steps: int = 0
    """Primitives of ``settle_text`` between the approach and ``sit_text`` (0: none). Why: the procedural data
    enters a sit only from standing still, so a sit down straight out of a walk asks for a transition it never saw."""
    settle_text: str = "stand still"

    def validate(self) -> None:
        """Ranges ordered and positive; one-line ConfigError naming the field."""
        _pair(self.seat_height, "seat_height", 0.05, 1.5)
        _pair(self.seat_distance, "seat_distance", 0.0, 100.0)
        _pair(self.seat_size, "seat_size", 0.05, 5.0)
        require(is_finite_number(self.seat_angle_deg) and 0 <= self.seat_angle_deg <= 180, "seat_angle_deg",
                f"must be degrees in [0, 180], got {self.seat_angle_deg}")
        facing = self.approach_facing_deg
        require(facing is None or (is_finite_number(facing) and 0 < facing <= 180), "approach_facing_deg",
                f"must be degrees in (0, 180] or null (any facing), got {facing!r}")
        for name in ("approach_offset", "approach_radius", "sit_radius", "height_tolerance", "leave_distance"):
            v = getattr(self, name)
            require(is_finite_number(v) and 0 < v <= 10, name, f"must be metres in (0, 10], got {v!r}")
        require(isinstance(self.hold_frames, int) and not isinstance(self.hold_frames, bool)
                and 1 <= self.hold_frames <= 3000, "hold_frames", f"must be an integer in [1, 3000], got "
                f"{self.hold_frames!r}")
        require(is_finite_number(self.stand_fraction) and 0 < self.stand_fraction <= 1, "stand_fraction",
                f"must be in (0, 1], got {self.stand_fraction!r}")
        require(isinstance(self.settle_steps, int) and not isinstance(self.settle_steps, bool)
                and 0 <= self.settle_steps <= 64, "settle_steps", f"must be an integer in [0, 64], got "
                f"{self.settle_steps!r}")
        for name in ("walk_text", "sit_text", "stand_text", "settle_text"):
            require(isinstance(getattr(self, name), str) and getattr(self, name).strip(), name, "must be a prompt")

    def kwargs(self) -> dict[str, Any]:
        """The constructor arguments of :class:`SitEnv`."""
        return {"seat_height": tuple(self.seat_height), "seat_distance": tuple(self.seat_distance),
                "seat_angle_deg": self.seat_angle_deg, "seat_size": tuple(self.seat_size),
                "approach_offset": self.approach_offset, "approach_radius": self.approach_radius,
                "approach_facing_deg": self.approach_facing_deg,
                "sit_radius": self.sit_radius, "height_tolerance": self.height_tolerance,
                "hold_frames": self.hold_frames, "leave_distance": self.leave_distance,
                "stand_fraction": self.stand_fraction, "walk_text": self.walk_text, "sit_text": self.sit_text,
                "stand_text": self.stand_text, "settle_steps": self.settle_steps, "settle_text": self.settle_text}


class SeatScene(EnvScene):
    """One seat per env, placed by the task at each reset (an :class:`EnvScene` whose rows the env writes)."""

    def __init__(self, num_envs: int, device: torch.device, floor_height: float):
        super().__init__(Scene(()), num_envs, device, floor_height)
        self.batch = SceneBatch.empty(num_envs, boxes=1, device=device)
        self.batch.floor_height[:] = self.floor_height

    @property
    def random(self) -> bool:
        """Each env has its own row (so :meth:`row` and :meth:`scene_of` read it)."""
        return True

    def reset(self, idx, history_world, goal, generator) -> None:
        """Nothing: the task writes the seat rows itself (:meth:`place`)."""

    def clear_goals(self, goal: torch.Tensor) -> None:
        """Nothing: the seat stays."""

    def place(self, idx: torch.Tensor, seat: torch.Tensor, size: tuple[float, float]) -> None:
        """Envs ``idx`` get seats (M, 4): centre x, y, top height above the floor, facing (radians)."""
        b = self.batch
        b.box_center[idx, 0] = torch.stack((seat[:, 0], seat[:, 1], self.floor_height + seat[:, 2] / 2), dim=-1)
        b.box_half[idx, 0] = torch.stack((torch.full_like(seat[:, 0], size[0] / 2),
                                          torch.full_like(seat[:, 0], size[1] / 2), seat[:, 2] / 2), dim=-1)
        b.box_yaw[idx, 0] = seat[:, 3]
        b.box_mask[idx, 0] = True


class SitEnv(LatentMotionVectorEnv):
    """Walk to a seat, sit on it and hold, stand up and walk away (module docstring: phases and successes).

    Observation goal fields: ``goal_dir`` (3) and ``goal_dist`` (1) toward the phase's goal, ``seat_facing`` (2:
    the sitter's facing in the body frame, forward and left parts), ``seat_height`` (1: the seat top above the
    floor), ``pelvis_target`` (1: the phase's pelvis height target minus the pelvis height, 0 where none),
    ``hold`` (1: the share of ``hold_frames`` held so far) and ``phase`` (4, one-hot). The seat is the env's
    scene, so ``scene_rays`` (and an optional ``height_grid``) follow. Infos: ``phase``, ``sit_success`` and
    ``getup_success`` (the step's events) and ``is_success`` (= get-up success).

    Args: ``seats`` (a seat file or :class:`SeatSpec` list: env i gets seat ``i % len(seats)``; None: drawn per
    episode) and the :class:`SitConfig` fields; every other argument is ``LatentMotionVectorEnv``'s (``scene``
    is the task's own and may not be given; ``compile`` is not supported).
    """

    goal_fields = (("goal_dir", 3), ("goal_dist", 1), ("seat_facing", 2), ("seat_height", 1), ("pelvis_target", 1),
                   ("hold", 1), ("phase", 4))
    task_group = ("seat_facing", "seat_height", "pelvis_target", "hold", "phase")
    reward_terms = ("dist", "success", "pelvis_height", "foot_floor", "skate", "rotation", "jerk", *COMMON_TERMS)

    def __init__(self, num_envs: int = 1, *, seats: str | Path | Sequence[SeatSpec] | None = None,
                 seat_height: Sequence[float] = (0.2, 0.6), seat_distance: Sequence[float] = (1.5, 3.0),
                 seat_angle_deg: float = 60.0, seat_size: Sequence[float] = (0.5, 0.5), approach_offset: float = 0.4,
                 approach_radius: float = 0.3, approach_facing_deg: float | None = 45.0, sit_radius: float = 0.3,
                 height_tolerance: float = 0.05,
                 hold_frames: int = 15, leave_distance: float = 0.6, stand_fraction: float = 0.9,
                 walk_text: str = "walk", sit_text: str = "sit down", stand_text: str = "stand up",
                 settle_steps: int = 0, settle_text: str = "stand still", **kwargs):
        cfg = SitConfig(list(seat_height), list(seat_distance), seat_angle_deg, list(seat_size), approach_offset,
                        approach_radius, approach_facing_deg, sit_radius, height_tolerance, hold_frames,
                        leave_distance, stand_fraction, walk_text, sit_text, stand_text, settle_steps, settle_text)
        cfg.validate()
        require(kwargs.get("scene") is None, "scene", "the sit task places its own seat; leave env.scene unset")
        require(not kwargs.get("compile", False), "compile", "the sit task runs eagerly (its phase logic)")
        self.cfg = cfg
        self.seats = load_seats(seats) if isinstance(seats, (str, Path)) else (list(seats) if seats else None)
        kwargs.setdefault("texts", (walk_text,))
        super().__init__(num_envs, scene=Scene(()), **kwargs)
        self.scene = SeatScene(self.num_envs, self.device, self.floor_height)  # one seat row per env
        n, dev = self.num_envs, self.device
        self._seat = torch.zeros(n, 4, device=dev)
        self._goal = torch.zeros(n, 3, device=dev)
        self._phase = torch.zeros(n, dtype=torch.long, device=dev)
        self._hold = torch.zeros(n, dtype=torch.long, device=dev)
        self._stand_z = torch.ones(n, device=dev)
        self._settle = torch.zeros(n, dtype=torch.long, device=dev)  # settle primitives left before the sit text
        self._events: dict[str, torch.Tensor] = {}
        rows = {t: self.text_table.texts.index(t) for t in self._all_texts(())}
        self._settle_text = torch.tensor(rows.get(settle_text, rows[sit_text]), device=dev)  # unused at 0 steps
        self._phase_text = torch.tensor([rows[walk_text], rows[sit_text], rows[stand_text], rows[walk_text]],
                                        device=dev)

    def _all_texts(self, texts: tuple[str, ...]) -> tuple[str, ...]:
        settle = (self.cfg.settle_text,) if self.cfg.settle_steps else ()
        return (*texts, self.cfg.walk_text, self.cfg.sit_text, self.cfg.stand_text, *settle)

    # ------------------------------------------------------------------ geometry
    @property
    def goal_world(self) -> torch.Tensor:
        """(N, 3) the phase's goal: the sit-down spot, the seat centre, then the leave point (z = the floor)."""
        return self._goal

    @property
    def seat(self) -> torch.Tensor:
        """(N, 4) each env's seat: centre x, y, top height above the floor, sitter's facing (radians)."""
        return self._seat

    @property
    def phase(self) -> torch.Tensor:
        """(N,) long: 0 approach, 1 sit, 2 stand, 3 leave (:data:`PHASES`)."""
        return self._phase

    def plan_texts(self, idx: torch.Tensor, primitives: int) -> torch.Tensor:
        """(S, M) the text rows of the next ``primitives`` steps of envs ``idx`` if each stays in its phase.

        In the sit phase: its settle steps left, then the sit text (what a planner of a phase predicts with).
        """
        k = torch.arange(primitives, device=self.device)[:, None]
        own = self._phase_text[self._phase[idx]][None, :].expand(primitives, -1)
        return torch.where(k < self._settle[idx][None, :], self._settle_text, own)

    @property
    def got_up(self) -> torch.Tensor:
        """(N,) bool: the last step ended the env's episode with the get-up success.

        Without autoreset an env stays there until reset.
        """
        left = self._events.get("left")
        return left if left is not None else torch.zeros_like(self._phase, dtype=torch.bool)

    def upright_height(self) -> torch.Tensor:
        """(N,) the world z the pelvis must reach to count as standing (``stand_fraction`` of its start height)."""
        return self.floor_height + self.cfg.stand_fraction * self._stand_z

    def seated_height(self) -> torch.Tensor:
        """(N,) the world z of a seated pelvis: each seat's top plus :data:`SEATED_PELVIS_ABOVE_SEAT_M`."""
        return self.floor_height + self._seat[:, 2] + SEATED_PELVIS_ABOVE_SEAT_M

    def facing(self) -> torch.Tensor:
        """(N, 2) the sitter's facing, an xy unit vector (the way a body seated on the seat looks)."""
        return torch.stack((torch.cos(self._seat[:, 3]), torch.sin(self._seat[:, 3])), dim=-1)

    def _facing_seat(self, future: torch.Tensor) -> torch.Tensor:
        """(N, F) each frame faces within ``approach_facing_deg`` of the sitter's facing (all True when None)."""
        limit = self.cfg.approach_facing_deg
        if limit is None:
            return torch.ones(future.shape[:2], dtype=torch.bool, device=future.device)
        n, f = future.shape[:2]
        forward, _ = body_forward(future.reshape(n * f, *future.shape[2:]))
        cos = (forward[:, :2].reshape(n, f, 2) * self.facing()[:, None, :]).sum(dim=-1)
        return cos >= math.cos(math.radians(limit))

    def _point_in_front(self, distance: float) -> torch.Tensor:
        xy = self._seat[:, :2] + self.facing() * distance
        return torch.cat((xy, torch.full_like(xy[:, :1], self.floor_height)), dim=-1)

    def _pelvis_target(self) -> torch.Tensor:
        """(N,) the pelvis z the phase asks for: seated in phase 1, standing in phase 2, NaN otherwise."""
        nan = torch.full_like(self._stand_z, float("nan"))
        target = torch.where(self._phase == 1, self.seated_height(), nan)
        return torch.where(self._phase == 2, self.floor_height + self._stand_z, target)

    # ------------------------------------------------------------------ task hooks
    def _draw_seats(self, idx: torch.Tensor) -> torch.Tensor:
        if self.seats is not None:
            table = torch.tensor([[*s.center, s.seat_height, math.radians(s.facing_deg)] for s in self.seats],
                                 device=self.device)
            return table[idx % len(self.seats)]
        forward, pelvis = body_forward(self.history_world(idx)[:, -1])
        a = math.radians(self.cfg.seat_angle_deg)
        xy = pelvis[:, :2] + rotate_xy(forward, self._uniform(len(idx), -a, a)) * \
            self._uniform(len(idx), *self.cfg.seat_distance)[:, None]
        height = self._uniform(len(idx), *self.cfg.seat_height)
        facing = self._uniform(len(idx), -math.pi, math.pi)
        return torch.cat((xy, height[:, None], facing[:, None]), dim=-1)

    def _reset_task(self, idx: torch.Tensor) -> None:
        self._seat[idx] = self._draw_seats(idx)
        self.scene.place(idx, self._seat[idx], tuple(self.cfg.seat_size))
        self._phase[idx] = 0
        self._hold[idx] = 0
        self._settle[idx] = 0
        self._stand_z[idx] = self.history_world(idx)[:, -1, PELVIS, 2] - self.floor_height
        self._text_idx[idx] = self._phase_text[0]
        self._goal[idx] = self._point_in_front(self.cfg.approach_offset)[idx]

    def _goal_observation(self, history_world: torch.Tensor) -> torch.Tensor:
        forward, pelvis = body_forward(history_world[:, -1])
        f = self.facing()
        facing = torch.stack((f[:, 0] * forward[:, 0] + f[:, 1] * forward[:, 1],
                              -f[:, 0] * forward[:, 1] + f[:, 1] * forward[:, 0]), dim=-1)
        target = torch.nan_to_num(self._pelvis_target() - pelvis[:, 2], nan=0.0)
        hold = (self._hold.float() / self.cfg.hold_frames).clamp(max=1.0)
        phase = torch.nn.functional.one_hot(self._phase, 4).float()
        return torch.cat((self._goal_features(history_world, self._goal), facing, self._seat[:, 2:3],
                          target[:, None], hold[:, None], phase), dim=1)

    def _reached(self, future: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """(N,) the phase ended with a success this step (approach, sit or get-up); notes every event."""
        cfg = self.cfg
        pelvis = future[:, :, PELVIS]  # (N, F, 3)
        from_seat = torch.linalg.vector_norm(pelvis[..., :2] - self._seat[:, None, :2], dim=-1)
        to_goal = torch.linalg.vector_norm(pelvis[..., :2] - goal[:, None, :2], dim=-1)
        height = pelvis[..., 2] - self.floor_height
        seated = (from_seat < cfg.sit_radius) & ((pelvis[..., 2] - self.seated_height()[:, None]).abs()
                                                 <= cfg.height_tolerance)
        hold, held = self._hold.clone(), torch.zeros_like(seated[:, 0])
        for t in range(seated.shape[1]):  # consecutive seated frames, carried over from the last step
            hold = torch.where(seated[:, t], hold + 1, torch.zeros_like(hold))
            held |= hold >= cfg.hold_frames
        upright = height >= cfg.stand_fraction * self._stand_z[:, None]
        phase = self._phase
        self._events = {
            "approached": (phase == 0) & ((to_goal < cfg.approach_radius) & self._facing_seat(future)).any(dim=1),
            "sat": (phase == 1) & held,
            "stood": (phase == 2) & upright[:, -1],
            "left": (phase == 3) & (upright & (from_seat >= cfg.leave_distance)).any(dim=1),
            "hold": torch.where(phase == 1, hold, torch.zeros_like(hold)),
        }
        return self._events["approached"] | self._events["sat"] | self._events["left"]

    def _reward_inputs(self, before, future, goal, reached) -> dict[str, torch.Tensor]:
        return {"pelvis_target": self._pelvis_target()}

    def _advance_task(self, reached: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Move each env to its next phase (new goal and text); the get-up ends the episode with success."""
        e = self._events
        self._hold = torch.where(e["sat"], torch.zeros_like(self._hold), e["hold"])
        nxt = self._phase + (e["approached"] | e["sat"] | e["stood"]).long()
        leave = self._point_in_front(self.cfg.leave_distance)
        self._goal = torch.where((nxt == 1)[:, None], torch.cat((self._seat[:, :2], self._goal[:, 2:]), dim=1),
                                 self._goal)
        self._goal = torch.where((nxt >= 2)[:, None], leave, self._goal)
        entering = (nxt == 1) & (self._phase == 0)
        left = torch.where(nxt == 1, (self._settle - 1).clamp(min=0), torch.zeros_like(self._settle))
        self._settle = torch.where(entering, torch.full_like(self._settle, self.cfg.settle_steps), left)
        self._phase = nxt
        text = torch.where((nxt == 1) & (self._settle > 0), self._settle_text, self._phase_text[nxt])
        self._text_idx = torch.where(e["left"], self._text_idx, text)
        return e["left"], e["left"]

    def _task_infos(self, infos: dict[str, Any], reached: torch.Tensor) -> None:
        infos["phase"], infos["_phase"] = self._phase.clone(), self._all
        infos["sit_success"], infos["_sit_success"] = self._events["sat"], self._all
        infos["getup_success"], infos["_getup_success"] = self._events["left"], self._all

    def set_rng_state(self, state) -> None:
        """Restore the episode tensors, then the seat rows of the scene from the restored seats."""
        super().set_rng_state(state)
        self.scene.place(torch.arange(self.num_envs, device=self.device), self._seat, tuple(self.cfg.seat_size))
