"""Joystick: follow a commanded world heading and speed that change over time.

Headings are degrees counter-clockwise about +z from the direction the body faces at the start
(world +y): 0 = straight on, 90 = a left turn (world -x), -90 = a right turn (world +x).

Command timelines (evaluation) are JSON files, a list of entries::

    [{"text": "walk", "duration": 20.0,
      "commands": [{"t": 0.0, "heading_deg": 0, "speed": 1.2}, {"t": 4.0, "heading_deg": 90, "speed": 1.2}]}]

``t`` is seconds from the episode start (the start of its first step); each command holds until the
next one, the first at ``t`` 0, and the episode ends at ``duration``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch

from latentrl.config import is_finite_number, require
from latentrl.envs.base import LatentMotionVectorEnv
from latentrl.envs.goal import body_forward
from latentrl.errors import DataError, check_fields
from latentrl.motion.representation import FUTURE_LENGTH
from latentrl.motion.skeleton import FPS
from latentrl.motion.text import prompt_problem
from latentrl.rewards.compose import COMMON_TERMS
from latentrl.safe_io import read_json_file
from latentrl.scenes.route import footprint_distance

STEP_SECONDS = FUTURE_LENGTH / FPS
"""One env step: 8 frames = 0.267 s."""
MAX_SPEED_M_S = 20.0
"""Commanded speeds beyond this are refused (a sprinter runs 10 m/s)."""
MAX_DURATION_S = 3600.0
"""Longest timeline, seconds."""
MAX_COMMANDS = 10_000
"""Most commands per timeline."""
MAX_TIMELINES = 1_000
"""Most timelines per file (each is its own evaluated rollout)."""
MAX_FILE_BYTES = 16 << 20
"""Largest timeline file read."""
CARROT_SECONDS = 1.0
"""``goal_world`` (recorded as the episode's goals) is where the command leads in this many seconds."""
ROUTE_AHEAD_M = (3.0, 6.0)
"""Among objects with a route guide (``route``): the route leads to the nearest point this far along the commanded
heading from the pelvis (every 0.25 m) that keeps the route's clearance from every object, else to the nearest: far
enough for the guide to see an object in the way in time, and past it rather than into it."""

_ENTRY_FIELDS = ("text", "commands", "duration")
_COMMAND_FIELDS = ("t", "heading_deg", "speed")


@dataclass(frozen=True)
class CommandTimeline:
    """One evaluation episode: a text, commands ``(t s, heading_deg, speed m/s)`` sorted by ``t`` (first at 0)."""

    text: str
    commands: tuple[tuple[float, float, float], ...]
    duration: float

    def at(self, t: float) -> tuple[float, float, float]:
        """The command in force at ``t`` seconds."""
        current = self.commands[0]
        for command in self.commands:
            if command[0] <= t + 1e-9:
                current = command
        return current


def load_timelines(file: str | Path) -> list[CommandTimeline]:
    """Read a command-timeline file; errors name the file, entry index, command index and field (0-based)."""
    data = read_json_file(file, "command timeline file", MAX_FILE_BYTES, DataError)
    return parse_timelines(data, str(file))


def parse_timelines(data: Any, source: str = "timelines") -> list[CommandTimeline]:
    """Validate parsed JSON into :class:`CommandTimeline` s (see the module docstring for the format)."""
    if not isinstance(data, list):
        raise DataError(f'{source}: expected a list of timelines like [{{"text": "walk", "commands": '
                        f'[{{"t": 0, "heading_deg": 0, "speed": 1.2}}], "duration": 20}}], got {type(data).__name__}')
    if not data:
        raise DataError(f"{source}: holds no timelines")
    if len(data) > MAX_TIMELINES:
        raise DataError(f"{source}: {len(data)} timelines, more than the {MAX_TIMELINES} a file may hold")
    return [_parse_entry(item, f"{source}: entry {i}") for i, item in enumerate(data)]


def _parse_entry(item: Any, where: str) -> CommandTimeline:
    check_fields(item, _ENTRY_FIELDS, where)
    text, commands, duration = item["text"], item["commands"], item["duration"]
    if not isinstance(text, str) or not text.strip():
        raise DataError(f"{where}: field 'text' must be a non-empty string, got {text!r:.80}")
    if prompt_problem(text) is not None:
        raise DataError(f"{where}: field 'text': {prompt_problem(text)}")
    if not is_finite_number(duration) or not 0 < duration <= MAX_DURATION_S:
        raise DataError(f"{where}: field 'duration' must be seconds in (0, {MAX_DURATION_S:g}], got {duration!r:.80}")
    if not isinstance(commands, list) or not commands:
        raise DataError(f"{where}: field 'commands' must be a non-empty list of {{t, heading_deg, speed}}, "
                        f"got {commands!r:.80}")
    if len(commands) > MAX_COMMANDS:
        raise DataError(f"{where}: {len(commands)} commands, more than the {MAX_COMMANDS} a timeline may have")
    parsed, last = [], -1.0
    for j, command in enumerate(commands):
        here = f"{where}, command {j}"
        check_fields(command, _COMMAND_FIELDS, here)
        t, heading, speed = command["t"], command["heading_deg"], command["speed"]
        if not is_finite_number(t) or (j == 0 and t != 0) or (j > 0 and not last < t < duration):
            expected = "0 (the first command starts the episode)" if j == 0 else \
                f"seconds after the previous command ({last:g}) and before the duration ({duration:g})"
            raise DataError(f"{here}: field 't' must be {expected}, got {t!r:.80}")
        if not is_finite_number(heading) or abs(heading) > 1e6:
            raise DataError(f"{here}: field 'heading_deg' must be a finite number of degrees, got {heading!r:.80}")
        if not is_finite_number(speed) or not 0 <= speed <= MAX_SPEED_M_S:
            raise DataError(f"{here}: field 'speed' must be m/s in [0, {MAX_SPEED_M_S:g}], got {speed!r:.80}")
        parsed.append((float(t), float(heading), float(speed)))
        last = float(t)
    return CommandTimeline(text, tuple(parsed), float(duration))


def world_angle(heading_deg: torch.Tensor | float) -> torch.Tensor | float:
    """Heading in degrees (0 = +y, counter-clockwise) -> world angle from +x in radians."""
    return (heading_deg + 90.0) * (math.pi / 180.0)


def heading_deg(world_rad: torch.Tensor) -> torch.Tensor:
    """Inverse of :func:`world_angle`, wrapped to (-180, 180] degrees."""
    deg = torch.rad2deg(world_rad) - 90.0
    return deg - 360.0 * torch.ceil((deg - 180.0) / 360.0)


def command_observation(history_world: torch.Tensor, heading: torch.Tensor, speed: torch.Tensor) -> torch.Tensor:
    """(N, 3) ``[command_dir | command_speed]``, pure so that the ONNX export builds it as the env does.

    ``command_dir`` is the cos and sin of world angle ``heading`` (N,) (radians from +x) relative to the
    body's facing at the last history frame; ``command_speed`` is ``speed`` (N,) in m/s.
    """
    forward, _ = body_forward(history_world[:, -1])
    relative = heading - torch.atan2(forward[:, 1], forward[:, 0])
    return torch.stack((relative.cos(), relative.sin(), speed), dim=-1)


class JoystickEnv(LatentMotionVectorEnv):
    """Move at a commanded world heading and speed, which change at random times (or on a timeline).

    ## Description

    The motion model is driven as in :class:`~latentrl.envs.reach.ReachLocationEnv`; instead of a
    goal, each env holds a command: a world heading and a speed. In training a new command comes
    every ``heading_change_seconds`` (uniform): the heading turns by up to +-``heading_change_deg``
    and the speed is drawn from ``speed_range``. With ``commands`` (timelines, evaluation) env i
    follows timeline ``i % P`` (``command_assignment="by_env"``) with its text, and terminates at the
    timeline's duration. The episode's text is drawn from ``texts`` (or is the timeline's).

    ## Observation Space

    ``Box(-inf, inf, (3 + E + 552 + 1,), float32)``: ``command_dir`` [0:2], the cos and sin of the
    commanded heading relative to the body's facing at the last history frame (counter-clockwise
    positive, so (1, 0) = straight on, (0, 1) = to the left); ``command_speed`` [2:3] in m/s; then
    text, motion and scene as in every task.

    ## Rewards

    ``heading`` (pelvis displacement along the commanded heading, (cos + 1) / 2), ``speed``
    (-|speed - commanded speed|, m/s), and DART's ``foot_floor``, ``skate``, ``rotation``, ``jerk``.

    ## Episode End

    Training: truncation after ``max_episode_steps`` (75 = 20 s), or divergence. Timelines:
    termination at the timeline's duration (``is_success``).

    ## Arguments

    ``speed_range`` ((0.7, 1.4) m/s, DART's model walks at 0.85-1.2 m/s and runs at 3.2-4.2 m/s),
    ``heading_change_deg`` (90), ``heading_change_seconds`` ((2.0, 6.0)), ``commands`` (``None``,
    a timeline file or a list of :class:`CommandTimeline`), ``command_assignment`` ("random" or
    "by_env"); the rest are :class:`~latentrl.envs.base.LatentMotionVectorEnv`'s.
    """

    goal_fields = (("command_dir", 2), ("command_speed", 1))
    reward_terms = ("heading", "speed", "foot_floor", "skate", "rotation", "jerk", *COMMON_TERMS)

    def __init__(
        self,
        num_envs: int = 1,
        *,
        speed_range: Sequence[float] = (0.7, 1.4),
        heading_change_deg: float = 90.0,
        heading_change_seconds: Sequence[float] = (2.0, 6.0),
        commands: str | Path | Sequence[CommandTimeline] | None = None,
        command_assignment: str = "random",
        max_episode_steps: int = 75,
        **kwargs,
    ):
        lo, hi = (float(v) for v in speed_range)
        require(0 <= lo <= hi <= MAX_SPEED_M_S, "speed_range",
                f"must be (min, max) m/s with 0 <= min <= max <= {MAX_SPEED_M_S:g}, got {tuple(speed_range)}")
        require(0 <= heading_change_deg <= 180, "heading_change_deg", f"must be in [0, 180], got {heading_change_deg}")
        a, b = (float(v) for v in heading_change_seconds)
        require(0 < a <= b, "heading_change_seconds", f"must be (min, max) seconds with 0 < min <= max, "
                f"got {tuple(heading_change_seconds)}")
        require(command_assignment in ("random", "by_env"), "command_assignment",
                f"expected 'random' or 'by_env', got {command_assignment!r}")
        if isinstance(commands, (str, Path)):
            commands = load_timelines(commands)
        self.timelines: list[CommandTimeline] | None = None if commands is None else list(commands)
        require(self.timelines is None or len(self.timelines) > 0, "commands", "give at least one timeline")
        self.speed_range = (lo, hi)
        self.heading_change_deg = float(heading_change_deg)
        self.heading_change_seconds = (a, b)
        self.command_assignment = command_assignment
        super().__init__(num_envs, max_episode_steps=max_episode_steps, **kwargs)
        n, dev = self.num_envs, self.device
        self._heading = torch.zeros(n, device=dev)  # world angle from +x, radians
        self._speed = torch.zeros(n, device=dev)
        self._next_change = torch.zeros(n, device=dev)  # seconds into the episode
        self._changed = torch.zeros(n, dtype=torch.bool, device=dev)
        self._timeline = torch.zeros(n, dtype=torch.long, device=dev)
        self._setup_timelines()

    def _all_texts(self, texts: tuple[str, ...]) -> tuple[str, ...]:
        return texts + tuple(t.text for t in self.timelines or ())

    def _setup_timelines(self) -> None:
        """Padded (P, C) command times (inf beyond the last), world angles, speeds; (P,) durations and texts."""
        if self.timelines is None:
            return
        dev, width = self.device, max(len(t.commands) for t in self.timelines)
        p = len(self.timelines)
        self._tl_time = torch.full((p, width), math.inf, device=dev)
        self._tl_angle = torch.zeros(p, width, device=dev)
        self._tl_speed = torch.zeros(p, width, device=dev)
        for i, tl in enumerate(self.timelines):
            c = torch.tensor(tl.commands, device=dev)
            self._tl_time[i, : len(c)] = c[:, 0]
            self._tl_angle[i, : len(c)] = world_angle(c[:, 1])
            self._tl_speed[i, : len(c)] = c[:, 2]
        self._tl_duration = torch.tensor([t.duration for t in self.timelines], device=dev)
        self._tl_text = torch.tensor([self.texts.index(t.text) for t in self.timelines], device=dev)

    # ------------------------------------------------------------------ commands
    def _episode_seconds(self) -> torch.Tensor:
        """(N,) seconds since each episode started (steps done x 0.267 s)."""
        return self._ep_len.float() * STEP_SECONDS

    def _timeline_command(self, idx: torch.Tensor, t: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """World angle and speed of the command in force at ``t`` (M,) for envs ``idx``."""
        times = self._tl_time[self._timeline[idx]]
        k = ((times <= t[:, None] + 1e-6).sum(1) - 1).clamp(min=0)
        tl = self._timeline[idx]
        return self._tl_angle[tl, k], self._tl_speed[tl, k]

    def _draw_commands(self, idx: torch.Tensor, start: bool) -> None:
        """New random commands for envs ``idx``: turn by up to +-heading_change_deg (from the body at a start)."""
        m = len(idx)
        turn = self._uniform(m, -1.0, 1.0) * math.radians(self.heading_change_deg)
        if start:
            forward, _ = body_forward(self.history_world(idx)[:, -1])
            base = torch.atan2(forward[:, 1], forward[:, 0])
        else:
            base = self._heading[idx]
        self._heading[idx] = torch.remainder(base + turn + math.pi, 2 * math.pi) - math.pi
        self._speed[idx] = self._uniform(m, *self.speed_range)
        t = self._episode_seconds()[idx]
        self._next_change[idx] = t + self._uniform(m, *self.heading_change_seconds)

    def _reset_task(self, idx: torch.Tensor) -> None:
        if self.timelines is None:
            self._text_idx[idx] = self._sample_texts(len(idx))
            self._draw_commands(idx, start=True)
        else:
            p = len(self.timelines)
            if self.command_assignment == "by_env":
                self._timeline[idx] = idx % p
            else:
                self._timeline[idx] = torch.randint(p, (len(idx),), generator=self._generator, device=self.device)
            self._text_idx[idx] = self._tl_text[self._timeline[idx]]
            start = torch.zeros(len(idx), device=self.device)
            self._heading[idx], self._speed[idx] = self._timeline_command(idx, start)
        self._changed[idx] = False

    @property
    def command_heading_deg(self) -> torch.Tensor:
        """(N,) the commanded heading, degrees (0 = +y, counter-clockwise), wrapped to (-180, 180]."""
        return heading_deg(self._heading)

    @property
    def command_speed(self) -> torch.Tensor:
        """(N,) the commanded speed, m/s."""
        return self._speed.clone()

    def _direction(self) -> torch.Tensor:
        return torch.stack((self._heading.cos(), self._heading.sin()), dim=-1)

    # ------------------------------------------------------------------ task hooks
    @property
    def goal_world(self) -> torch.Tensor:
        """(N, 3) where the command leads in :data:`CARROT_SECONDS` from the last history frame's pelvis."""
        pelvis = self.history_world()[:, -1, 0]
        xy = pelvis[:, :2] + self._direction() * (self._speed * CARROT_SECONDS)[:, None]
        return torch.cat((xy, torch.full_like(xy[:, :1], self.floor_height)), dim=-1)

    route_target_moves = True

    @classmethod
    def routable(cls) -> bool:
        """A route guide leads a joystick too: to a point :data:`ROUTE_AHEAD_M` along the command."""
        return True

    def route_target(self, history_world: torch.Tensor) -> torch.Tensor:
        """(N, 3) where the command leads among the objects, for a route guide.

        The nearest point :data:`ROUTE_AHEAD_M` along the commanded heading from the last history frame's pelvis
        that keeps the route's clearance from every object (else the nearest of them).
        """
        near, far = ROUTE_AHEAD_M
        ahead = torch.arange(near, far + 1e-6, 0.25, device=self.device)
        xy = history_world[:, -1, 0, None, :2] + self._direction()[:, None] * ahead[:, None]  # (N, K, 2)
        pick = torch.zeros(self.num_envs, dtype=torch.long, device=self.device)
        if self.scene is not None and self.route is not None:
            clear = footprint_distance(self.scene.batch, xy, self.floor_height) >= self.route.clearance  # (N, K)
            pick = torch.where(clear.any(dim=1), clear.float().argmax(dim=1), pick)
        chosen = xy[torch.arange(self.num_envs, device=self.device), pick]
        return torch.cat((chosen, torch.full_like(chosen[:, :1], self.floor_height)), dim=-1)

    def routed_observation(self, obs: torch.Tensor, rows: torch.Tensor, seen: torch.Tensor,
                           history_world: torch.Tensor) -> torch.Tensor:
        """``obs`` whose ``rows`` observe a command toward the world points ``seen`` (N, 3), at the command's speed."""
        away = seen.to(self.device, torch.float32)[:, :2] - history_world[:, -1, 0, :2].float()
        heading = torch.atan2(away[:, 1], away[:, 0])
        a, b = self.observation_fields["command_dir"]
        out = torch.as_tensor(obs).clone()
        out[rows, a:b] = command_observation(history_world, heading, self._speed)[rows, :2].to(out.device, out.dtype)
        return out

    def _reached(self, future: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """No goal is ever reached: the command is tracked, not arrived at."""
        return torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)

    def _goal_observation(self, history_world: torch.Tensor) -> torch.Tensor:
        return command_observation(history_world, self._heading, self._speed)

    def _reward_inputs(self, before, future, goal, reached) -> dict[str, torch.Tensor]:
        return {"command": torch.cat((self._direction(), self._speed[:, None]), dim=-1)}

    def _advance_task(self, reached: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Commands due at the new episode time change; a timeline's end terminates with ``is_success``."""
        t = self._episode_seconds()
        if self.timelines is None:
            self._changed = t >= self._next_change - 1e-6
            if bool(self._changed.any()):
                self._draw_commands(self._changed.nonzero()[:, 0], start=False)
            none = torch.zeros_like(reached)
            return none, none
        idx = torch.arange(self.num_envs, device=self.device)
        heading, speed = self._timeline_command(idx, t)
        self._changed = (heading != self._heading) | (speed != self._speed)
        self._heading, self._speed = heading, speed
        done = t >= self._tl_duration[self._timeline] - 1e-6
        return done, done

    def _task_infos(self, infos: dict[str, Any], reached: torch.Tensor) -> None:
        infos["command_heading_deg"] = self.command_heading_deg
        infos["command_speed"] = self.command_speed
        infos["command_changed"] = self._changed.clone()
        for key in ("command_heading_deg", "command_speed", "command_changed"):
            infos[f"_{key}"] = self._all
