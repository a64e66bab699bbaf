"""The episode video of the trainer's periodic evaluation: one rendered episode every ``eval.video_every`` runs.

A training hook asks :meth:`EpisodeRecorder.start` whether this evaluation is due, hands :attr:`sink` to its suite
runner (every evaluator's runner already takes an episode sink), and puts :meth:`EpisodeRecorder.videos` into its
:class:`~latentrl.monitor.EvalReport`. Only the first episode of the first entry is kept and drawn, small and at
10 frames/s: a video adds the drawing of one episode to the evaluation, never a second rollout.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any

from latentrl.motion.clip import MotionClip

VIDEO_STRIDE = 3
"""Every 3rd frame of the 30 frames/s motion: the video plays in real time at 10 frames/s."""


class EpisodeRecorder:
    """Counts a training process's evaluations and records one episode on every ``every``-th (0: never).

    The count starts at the first evaluation of the process, so a resumed run draws its first one too.
    """

    def __init__(self, every: int = 1, size: int = 160):
        self.every, self.size = int(every), int(size)
        self.evaluations = 0
        self.due = False
        self.clip: MotionClip | None = None
        self.title = ""

    def start(self) -> bool:
        """Begin an evaluation: forget the last clip; whether this one records an episode."""
        self.due = self.every > 0 and self.evaluations % self.every == 0
        self.evaluations += 1
        self.clip = None
        return self.due

    def sink(self, episode: Any, data: MotionClip | dict) -> None:
        """The runners' episode sink: keeps the first episode it is given (a clip, or a clip's dict)."""
        if self.due and self.clip is None:
            self.clip = data if isinstance(data, MotionClip) else MotionClip.from_dict(data)
            where = getattr(episode, "path_index", getattr(episode, "index", 0))
            self.title = f"{getattr(episode, 'suite', 'eval')} {where} ep {getattr(episode, 'episode', 0)}"
        return None

    def videos(self) -> dict:
        """``{EVAL_EPISODE: EpisodeVideo}`` of the recorded episode, or {} when none was due or recorded."""
        from latentrl.monitor import EVAL_EPISODE, EpisodeVideo
        from latentrl.render import clip_frames, gif_bytes

        if self.clip is None:
            return {}
        frames = len(range(0, self.clip.frames, VIDEO_STRIDE))
        fps = self.clip.fps / VIDEO_STRIDE
        gif = gif_bytes(clip_frames(self.clip, VIDEO_STRIDE, self.size, self.title), fps)
        self.clip = None
        return {EVAL_EPISODE: EpisodeVideo(gif, self.size, self.size, frames, fps)}


def recorder_for(eval_cfg: Any) -> EpisodeRecorder:
    """The recorder of an ``eval:`` section (``video_every``, ``video_size``; a section without them: the defaults)."""
    return EpisodeRecorder(int(getattr(eval_cfg, "video_every", 1)), int(getattr(eval_cfg, "video_size", 160)))


def takes_sink(run: Callable) -> bool:
    """Whether a suite runner accepts ``sink=`` (a task registered from outside may bring one that does not)."""
    try:
        params = inspect.signature(run).parameters.values()
    except (TypeError, ValueError):
        return False
    return any(p.name == "sink" or p.kind is inspect.Parameter.VAR_KEYWORD for p in params)
