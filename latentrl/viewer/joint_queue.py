"""The env of ``latentrl play`` for a ReachJoint policy: one env whose joint goals are a queue set from outside.

Why a queue: a page adds goals one click at a time while the character moves, a goal file cannot. Goals are
scored at their frames as a goal file's are (:class:`~latentrl.envs.reach_joint.ReachJointEnv`); the controller
that fills the queue from clicks is :mod:`latentrl.viewer.joint_play`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import torch

from latentrl.envs.reach_joint import JOINTS, ReachJointConfig, ReachJointEnv, goal_frame
from latentrl.errors import LatentRLError
from latentrl.viewer.steered import Steered

MAX_QUEUED = 32
"""Goals the queue holds at once (done ones are dropped to make room); clicks beyond it are ignored."""


class SteeredReachJointEnv(Steered, ReachJointEnv):
    """``ReachJoint`` with one env whose goals come from outside, a queue of up to :data:`MAX_QUEUED`.

    Until a goal is added nothing is due. Goals are scored at their frames as a goal file's are; the queue never
    ends the episode (``terminated`` stays false): the controller stops when nothing is pending. ``planar``
    joints (the feet and the policy's trained ``planar``) take 2-D targets. :attr:`last_frames` holds the
    (N, 8, 22, 3) world frames of the last step.
    """

    def __init__(self, num_envs: int = 1, *, slots: int = MAX_QUEUED, **kwargs):
        kwargs.pop("goals", None)
        super().__init__(num_envs, **kwargs)
        n, dev = self.num_envs, self.device
        self._target = torch.zeros(n, slots, 3, device=dev)
        self._joint = torch.zeros(n, slots, dtype=torch.long, device=dev)
        self._planar = torch.zeros(n, slots, dtype=torch.bool, device=dev)
        self._frame = torch.zeros(n, slots, dtype=torch.long, device=dev)
        self._gap = torch.full((n, slots), -1, dtype=torch.long, device=dev)  # frames after the goal before
        self._record = torch.full((n, slots), math.nan, device=dev)
        self._count = torch.zeros(n, dtype=torch.long, device=dev)

    # ------------------------------------------------------------------ the queue
    def planar_joint(self, joint: str) -> bool:
        """Whether ``joint``'s targets are 2-D (the feet, and the joints the policy was trained on as such)."""
        return bool(self._flat[list(JOINTS).index(joint)])

    def add_goal(self, joint: str, target: Sequence[float], seconds: float | None, append: bool = False) -> bool:
        """Queue a goal for env 0; whether it was queued (False: the queue is full of pending goals).

        ``target``: world xy (planar joints) or xyz. ``seconds``: from now, or with ``append`` after the goal
        before it (None: as soon as possible, when it becomes current). Without ``append`` the queue is replaced.
        """
        if joint not in JOINTS:
            raise LatentRLError(f"goal joint: expected one of {', '.join(JOINTS)}, got {joint!r:.40}")
        planar = self.planar_joint(joint)
        xyz = (*map(float, target[:2]), self.floor_height if planar else float(target[2]))
        if not append or int(self._count[0]) == 0:
            self._clear(0)
        elif int(self._count[0]) >= self._target.shape[1] and not self._compact():
            return False
        c, now = int(self._count[0]), int(self._now_frame()[0])
        current_done = c > 0 and not math.isnan(float(self._record[0, self._gi[0]]))
        gap = -1 if seconds is None else goal_frame(seconds)
        if gap < 0:
            frame = -1
        elif c == 0 or current_done:
            frame = now + gap
        else:  # after the goal before it: known once that one's time is (an asap one gets it when current)
            before = int(self._frame[0, c - 1])
            frame = before + gap if before >= 0 else -1
        self._target[0, c] = torch.tensor(xyz, device=self.device)
        self._joint[0, c] = list(JOINTS).index(joint)
        self._planar[0, c] = planar
        self._frame[0, c] = frame
        self._gap[0, c] = gap
        self._record[0, c] = math.nan
        self._count[0] = c + 1
        if c == 0 or current_done:
            self._gi[0] = c
            self._activate(torch.zeros(1, dtype=torch.long, device=self.device))
        return True

    def pending(self) -> int:
        """Goals of env 0 not yet due (the current one included)."""
        c, k = int(self._count[0]), int(self._gi[0])
        if c == 0:
            return 0
        return c - k - (0 if math.isnan(float(self._record[0, k])) else 1)

    def queued_goals(self) -> list[dict[str, Any]]:
        """Env 0's pending goals, the current first: joint name, target (3,), frames from now (None: not known)."""
        c, k, now = int(self._count[0]), int(self._gi[0]), int(self._now_frame()[0])
        start = k + (self.pending() < c - k)
        names = list(JOINTS)
        return [{"joint": names[int(self._joint[0, i])], "target": self._target[0, i].cpu().numpy(),
                 "frames": None if int(self._frame[0, i]) < 0 else int(self._frame[0, i]) - now}
                for i in range(start, c)]

    def scored_goals(self) -> list[tuple[str, float]]:
        """Env 0's goals already due, in order: joint name and error (metres)."""
        names = list(JOINTS)
        return [(names[int(self._joint[0, i])], float(self._record[0, i])) for i in range(int(self._count[0]))
                if not math.isnan(float(self._record[0, i]))]

    def clear_goal(self) -> None:
        """Empty the queue (``play``'s Reset)."""
        for i in range(self.num_envs):
            self._clear(i)

    def _clear(self, i: int) -> None:
        self._gi[i], self._count[i], self._goals_ok[i] = 0, 0, 0
        self._record[i] = math.nan
        self._frame[i] = 0  # never due: a step's frames come after frame 0
        self._gap[i] = -1

    def _compact(self) -> bool:
        """Drop env 0's goals already due to make room; whether a slot is free now."""
        done = int(self._gi[0]) + (0 if self.pending() == int(self._count[0]) - int(self._gi[0]) else 1)
        if done == 0:
            return False
        for table in (self._target, self._joint, self._planar, self._frame, self._gap, self._record):
            table[0] = torch.roll(table[0], -done, dims=0)
        self._goals_ok[0] -= int((self._record[0, -done:] < self.radius).sum())
        self._record[0, -done:] = math.nan
        self._count[0] -= done
        self._gi[0] = max(0, int(self._gi[0]) - done)
        return True

    def _activate(self, idx: torch.Tensor) -> None:
        """An asap goal gets its time as it becomes current; the timed goals queued after it then get theirs."""
        super()._activate(idx)
        for i in idx.tolist():
            j = int(self._gi[i]) + 1
            while j < int(self._count[i]) and int(self._frame[i, j]) < 0 <= int(self._gap[i, j]):
                self._frame[i, j] = self._frame[i, j - 1] + self._gap[i, j]
                j += 1

    # ------------------------------------------------------------------ episode
    def _reset_task(self, idx: torch.Tensor) -> None:
        for i in idx.tolist():
            self._clear(i)
        self._run_left[idx] = 0
        self._text_idx[idx] = 0
        self._keep_text(idx)

    def _advance_task(self, reached: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        ended, success = self._advance_listed()
        return torch.zeros_like(ended), success


def joint_play_env(env_cfg: Mapping[str, Any], **common) -> SteeredReachJointEnv:
    """The steered env of a ReachJoint policy: its training task settings (joints, planar, radius, speed)."""
    section = ReachJointConfig(**{k: v for k, v in (env_cfg.get("reach_joint") or {}).items() if k != "goals"})
    section.validate()
    return SteeredReachJointEnv(1, **section.kwargs(), **common)
