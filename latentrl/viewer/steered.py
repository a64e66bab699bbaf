"""What every env of ``latentrl play`` adds to its task env: a text chosen on the page, and the last step's frames.

Why a mixin: ``play`` steers reach, joystick and ReachJoint envs alike (:mod:`latentrl.viewer.live`,
:mod:`latentrl.viewer.joint_queue`); each takes its text from the page's list, keeps it across resets, and hands
the controller the frames it just made.
"""

from __future__ import annotations

import torch


class Steered:
    """Mixed in before a task env: :meth:`set_text`, :attr:`text` and :attr:`last_frames` ((N, 8, 22, 3) world)."""

    _text_choice: int | None = None
    last_frames: torch.Tensor | None = None

    def set_text(self, text: str) -> None:
        """Use ``text`` (one of :attr:`texts`) from now on, across resets."""
        self._text_choice = self.texts.index(text)
        self._text_idx[:] = self._text_choice

    @property
    def text(self) -> str:
        """The text the env steps with now."""
        return self.texts[int(self._text_idx[0])]

    def _keep_text(self, idx: torch.Tensor) -> None:
        """After a reset of envs ``idx``: the chosen text again (the task may have drawn another)."""
        if self._text_choice is not None:
            self._text_idx[idx] = self._text_choice

    def _finish_step(self, reward, terms, reached, diverged, nonfinite, future, goal):
        self.last_frames = future
        return super()._finish_step(reward, terms, reached, diverged, nonfinite, future, goal)
