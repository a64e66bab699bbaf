"""Per-env motion log of a vector env, split into episodes, exported in the shared motion format.

The log is a list of events in the order they happened: a *reset* event holds the 2 seed
frames of the envs it reset, a *step* event the 8 new frames of every env. An env's episode is
its last reset event followed by every later step event, so arbitrary-length episodes cost no
bookkeeping during stepping. Everything is copied to the CPU when recorded (bounded device
memory); call :meth:`HistoryRecorder.clear` to bound host memory.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch

from latentrl.motion.canonical import features_to_world
from latentrl.motion.clip import MotionClip, primitive_layout
from latentrl.motion.representation import FUTURE_LENGTH, HISTORY_LENGTH
from latentrl.motion.skeleton import FPS


@dataclass
class _Reset:
    rows: dict[int, int]  # env index -> row in the tensors below
    joints: torch.Tensor  # (M, 2, 22, 3) world metres
    text: torch.Tensor  # (M,) text index at the reset
    features: torch.Tensor | None  # (M, 2, 276) world
    from_reset: bool


@dataclass
class _Step:
    joints: torch.Tensor  # (N, 8, 22, 3) world metres
    actions: torch.Tensor  # (N, D) as applied (clamped)
    text: torch.Tensor  # (N,) text index in force during the step
    goals: torch.Tensor  # (N, 3) goal in force during the step, world metres
    features: torch.Tensor | None  # (N, 8, 276) world


@dataclass
class _Episode:
    start: _Reset
    row: int
    steps: list[_Step] = field(default_factory=list)


class HistoryRecorder:
    """Records resets and steps of ``num_envs`` envs; exports one env's episode on demand."""

    def __init__(self, num_envs: int, action_dim: int, record_features: bool = False):
        self.num_envs = num_envs
        self.action_dim = action_dim
        self.record_features = record_features
        self._events: list[_Reset | _Step] = []

    def on_reset(
        self,
        idx: torch.Tensor,
        joints_world: torch.Tensor,
        text_idx: torch.Tensor,
        features_world: torch.Tensor | None = None,
        from_reset: bool = True,
    ) -> None:
        """Envs ``idx`` ((M,) long) start an episode with seed frames ``joints_world`` (M, 2, 22, 3)."""
        rows = {int(e): r for r, e in enumerate(idx.tolist())}
        feats = None if features_world is None else features_world.cpu()
        self._events.append(_Reset(rows, joints_world.cpu(), text_idx.cpu(), feats, from_reset))

    def on_step(
        self,
        joints_world: torch.Tensor,
        actions: torch.Tensor,
        text_idx: torch.Tensor,
        goals: torch.Tensor,
        features_world: torch.Tensor | None = None,
    ) -> None:
        """Every env produced (N, 8, 22, 3) new frames from (N, D) actions."""
        feats = None if features_world is None else features_world.cpu()
        self._events.append(_Step(joints_world.cpu(), actions.cpu(), text_idx.cpu(), goals.cpu(), feats))

    def clear(self) -> None:
        """Forget everything recorded so far."""
        self._events = []

    def episodes(self, env: int) -> list[_Episode]:
        """Every recorded episode of env ``env``, oldest first (the last may still be running)."""
        out: list[_Episode] = []
        for event in self._events:
            if isinstance(event, _Reset):
                if env in event.rows:
                    out.append(_Episode(event, event.rows[env]))
            elif out:
                out[-1].steps.append(event)
        return out

    def export_clip(self, env: int, episode: int, texts: tuple[str, ...], floor: float = 0.0) -> MotionClip:
        """Episode ``episode`` (Python indexing, -1 = latest) of env ``env`` as a :class:`MotionClip`.

        Its ``meta`` holds ``from_reset`` (whether the episode's start was recorded).
        """
        eps = self.episodes(env)
        if not -len(eps) <= episode < len(eps):
            raise IndexError(f"env {env} has {len(eps)} recorded episodes; episode {episode} does not exist")
        ep = eps[episode]
        joints = [ep.start.joints[ep.row]] + [s.joints[env] for s in ep.steps]
        step_text = [texts[int(s.text[env])] for s in ep.steps]
        actions = np.zeros((len(ep.steps), self.action_dim), np.float32)
        goals = np.zeros((len(ep.steps), 3), np.float32)
        for k, s in enumerate(ep.steps):
            actions[k] = s.actions[env].numpy()
            goals[k] = s.goals[env].numpy()
        features = None
        if self.record_features and ep.start.features is not None:
            feats = [ep.start.features[ep.row]] + [s.features[env] for s in ep.steps]
            features = torch.cat(feats).numpy().astype(np.float32)
        return MotionClip(
            torch.cat(joints).numpy().astype(np.float32),
            FPS,
            [""] * HISTORY_LENGTH + [t for t in step_text for _ in range(FUTURE_LENGTH)],
            actions=actions,
            goals=goals,
            floor=floor,
            features=features,
            primitive=primitive_layout(len(ep.steps)),
            meta={"from_reset": ep.start.from_reset},
        )


class RecordedEpisodes:
    """The env side of history recording (mixed into ``LatentMotionVectorEnv``): export and clear episodes."""

    def export_history(self, env_index: int, episode: int = -1) -> dict[str, Any]:
        """One recorded episode of one env in the shared motion format (see ``latentrl.render``).

        Returns numpy arrays: ``joints`` (T, 22, 3) world metres including the 2 seed frames,
        ``fps``, ``texts`` (T,) ('' for seed frames), ``actions`` (S, D) as clamped,
        ``primitive`` (T,) (-1 for seed frames), ``goals`` (S, 3), ``features`` (T, 276) when
        recorded, and ``from_reset`` (whether the episode's start was recorded).
        ``contacts`` (T, 2) and ``floor`` come with them (:class:`~latentrl.motion.clip.MotionClip`).
        ``save_motion_npz(path, **env.export_history(i))`` or ``env.export_clip(i).save(path)`` writes it.
        """
        return self.export_clip(env_index, episode).to_dict()

    def export_clip(self, env_index: int, episode: int = -1) -> MotionClip:
        """:meth:`export_history` as a :class:`~latentrl.motion.clip.MotionClip` (``meta["from_reset"]``)."""
        if self._history is None:
            raise ValueError("this env records no history; build it with record_history=True")
        if not 0 <= env_index < self.num_envs:
            raise IndexError(f"env_index {env_index} out of range for {self.num_envs} envs")
        return self._history.export_clip(env_index, episode, self.texts, self.floor_height)

    def clear_history(self) -> None:
        """Drop recorded steps (keeps each env's current 2 frames as the start of its episode)."""
        if self._history is not None:
            self._history.clear()
            if self._state is not None:
                idx = torch.arange(self.num_envs, device=self.device)
                self._history.on_reset(
                    idx, self.history_world(), self._text_idx, self._history_features(idx), from_reset=False
                )

    def _history_features(self, idx: torch.Tensor) -> torch.Tensor | None:
        """(M, 2, 276) world features of the current history of envs ``idx``, if they are recorded."""
        if self._history is None or not self._history.record_features:
            return None
        s = self._state
        return features_to_world(s.history[idx], s.world.index(idx), self.motion.pelvis_delta)

    def close_extras(self, **kwargs: Any) -> None:
        """Drop the recorded history."""
        self._history = None
