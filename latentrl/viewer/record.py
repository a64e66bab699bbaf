"""``--record FILE``: the frames a ``view`` or ``play`` page showed, drawn as a GIF or MP4 when the session ends.

The browser is not filmed: the viewer keeps each shown pose (with its text and goal) and
:func:`latentrl.render.render_video` draws them once the server has stopped, so a recording costs
nothing while the page plays and looks like ``latentrl eval``'s renders.
"""

from __future__ import annotations

import collections
import threading
from pathlib import Path

import numpy as np

from latentrl.errors import ConfigError
from latentrl.motion.skeleton import FPS

MAX_RECORD_FRAMES = 5 * 60 * FPS
"""A recording keeps the last 5 minutes shown (drawing them takes about a minute on one CPU core)."""


def check_record(path: str | Path | None) -> None:
    """Refuse ``--record`` before the server starts: a .gif or .mp4 (MP4 needs latentrl[video]) we may write."""
    if path is None:
        return
    from latentrl.preflight import check_output_file
    from latentrl.render import video_problem

    problem = video_problem(path)
    if problem:
        raise ConfigError(f"--record {problem}")
    check_output_file(path, "--record")


class Recorder:
    """Collects shown frames (thread-safe: the page's loop adds, the command writes once it has stopped).

    Args:
        path: the .gif or .mp4 to write.
        command: ``view`` or ``play``, for the lines it prints.
        max_frames: only the last this many frames are kept.
    """

    def __init__(self, path: str | Path, command: str, max_frames: int = MAX_RECORD_FRAMES):
        self.path, self.command = Path(path), command
        self.lock = threading.Lock()
        self.frames: collections.deque = collections.deque(maxlen=int(max_frames))
        self.goals: list[np.ndarray] = []
        self.scene = None
        """The :class:`~latentrl.scenes.Scene` drawn around the body (the last one the page showed), or None."""

    def set_scene(self, scene) -> None:
        """Draw ``scene`` (the page's objects now, dropped boxes included; None: none) in the recording."""
        with self.lock:
            self.scene = scene

    def add(self, joints: np.ndarray, text: str = "", goal: np.ndarray | None = None) -> None:
        """Keep one shown pose (22, 3), the text it was generated with and the goal on screen (or None)."""
        with self.lock:
            self.frames.append((np.array(joints, dtype=np.float32), str(text or "")))
            if goal is not None and (not self.goals or not np.allclose(self.goals[-1][:2], goal[:2])):
                self.goals.append(np.array(goal, dtype=np.float32)[:3])

    def write(self) -> Path | None:
        """Draw what was kept to :attr:`path` and say so; None (and a line saying why) when nothing was shown."""
        from latentrl.render import render_video

        with self.lock:
            frames, goals, scene = list(self.frames), list(self.goals), self.scene
        if not frames:
            print(f"latentrl {self.command}: nothing was played, {self.path} not written", flush=True)
            return None
        joints = np.stack([f[0] for f in frames])
        print(f"latentrl {self.command}: drawing {len(frames)} frames into {self.path} ...", flush=True)
        render_video(self.path, joints, FPS, texts=[f[1] for f in frames], title=f"latentrl {self.command}",
                     goals=np.stack(goals) if goals else None, scene=scene)
        print(f"latentrl {self.command}: wrote {self.path.resolve()} ({len(frames)} frames, "
              f"{len(frames) / FPS:.1f} s)", flush=True)
        return self.path
