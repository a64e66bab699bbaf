"""``latentrl view``: play recorded motions in the browser (play/pause, scrub, speed, episode picker, metrics)."""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np

from latentrl.motion.skeleton import PELVIS
from latentrl.viewer.guard import choice, complain, number
from latentrl.viewer.markup import plain
from latentrl.viewer.objects import scene_points
from latentrl.viewer.scene import SkeletonScene, floor_extent, frame_camera
from latentrl.viewer.sources import Clip, Source, metrics_table

SPEEDS = ("0.25", "0.5", "1", "2", "4")
TICK_S = 1.0 / 30.0
TRAIL_EVERY = 3
"""While playing, the pelvis trail is redrawn every 3rd frame (it changes slowly; fewer messages)."""


def move_cameras(server: Any, position: np.ndarray, look_at: np.ndarray) -> None:
    """Point every connected browser's camera (and the one new browsers get) at ``look_at``."""
    position, look_at = tuple(float(v) for v in position), tuple(float(v) for v in look_at)
    server.initial_camera.position = position
    server.initial_camera.look_at = look_at
    for client in server.get_clients().values():
        with client.atomic():
            client.camera.position = position
            client.camera.look_at = look_at


FOLLOW_STEP_M = 0.03
"""The camera follows the body once it has moved this far (fewer camera messages, no visible lag)."""


class CameraFollower:
    """Keeps every browser's camera looking at the body, at the angle and distance the user left it."""

    def __init__(self, server: Any):
        self.server = server
        self.target: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the followed point: the next update moves the cameras."""
        self.target = None

    def update(self, pelvis: np.ndarray, height: float = 0.8) -> None:
        """Move the cameras to follow ``pelvis`` once it moved :data:`FOLLOW_STEP_M` from the last point followed."""
        target = np.array([pelvis[0], pelvis[1], height], dtype=np.float64)
        if self.target is not None and np.linalg.norm(target - self.target) < FOLLOW_STEP_M:
            return
        self.target = target
        for client in self.server.get_clients().values():
            cam = client.camera
            offset = np.asarray(cam.position, dtype=np.float64) - np.asarray(cam.look_at, dtype=np.float64)
            with client.atomic():
                cam.look_at = tuple(float(v) for v in target)
                cam.position = tuple(float(v) for v in target + offset)


def clip_scene(clip: Clip, path: Any) -> Any:
    """The :class:`~latentrl.scenes.Scene` a clip carries, or None (and one line saying why for a bad one).

    A motion whose scene text does not read as ``latentrl.scene/1`` still plays, on the bare floor.
    """
    if clip.scene is None:
        return None
    from latentrl.errors import LatentRLError
    from latentrl.scenes.spec import scene_from_json

    try:
        return scene_from_json(clip.scene, f"{path}: scene")
    except LatentRLError as exc:
        complain("view", f"drawing no scene: {exc}")
        return None


class Player:
    """Plays the clips of a :class:`~latentrl.viewer.sources.Source` in a Viser server (a thread at 30 Hz)."""

    def __init__(self, server: Any, source: Source, recorder: Any = None, skeleton: bool = False):
        self.server, self.source = server, source
        self.recorder = recorder
        """A :class:`~latentrl.viewer.record.Recorder` that keeps every frame played (``--record``), or None."""
        self.lock = threading.Lock()
        self.scene = SkeletonScene(server, skeleton=skeleton)
        self.clip: Clip | None = None
        self.frame = 0.0
        self.playing = True
        self.follower = CameraFollower(server)
        gui = server.gui
        self.header = gui.add_markdown(f"**{source.kind}** {plain(source.title)}  \n{source.summary}")
        labels = [e.label for e in source.entries]
        self.picker = gui.add_dropdown("episode", labels, initial_value=labels[0], visible=len(labels) > 1)
        self.metrics = gui.add_markdown("")
        self.play = gui.add_button("Pause")
        self.slider = gui.add_slider("frame", 0, 1, 1, 0)
        self.speed = gui.add_dropdown("speed", SPEEDS, initial_value="1")
        self.follow = gui.add_checkbox("follow camera", False)
        self.show_body = gui.add_checkbox("body", True)
        self.show_skeleton = gui.add_checkbox("skeleton", bool(skeleton))
        self.status = gui.add_markdown("")
        self.rate = 1.0
        """Playback speed, a checked copy of the speed dropdown (a client may send any string)."""
        self.picker.on_update(self._picked)
        self.play.on_click(lambda event: self.toggle())
        self.slider.on_update(self._scrubbed)
        self.speed.on_update(self._speed_changed)
        self.show_body.on_update(lambda event: self._set_visible(self.scene.set_body_visible, self.show_body))
        self.show_skeleton.on_update(lambda event: self._set_visible(self.scene.set_skeleton_visible,
                                                                     self.show_skeleton))
        self.stop = threading.Event()
        self.select(labels[0])
        self.thread = threading.Thread(target=self._run, name="latentrl-view", daemon=True)

    def start(self) -> None:
        """Start the playback thread."""
        self.thread.start()

    def select(self, label: str) -> None:
        """Load the entry named ``label`` and show its first frame."""
        entry = next(e for e in self.source.entries if e.label == label)
        clip = entry.load()
        with self.lock:
            self.clip, self.frame, self.label = clip, 0.0, label
            self.follower.reset()
            self.metrics.content = metrics_table(entry.metrics)
            self.slider.max = max(clip.frames - 1, 1)
            world = clip_scene(clip, entry.path)
            self.scene.set_scene(world)
            if self.recorder is not None:
                self.recorder.set_scene(world)
            around = scene_points(world)
            if clip.waypoints is not None:
                around = np.concatenate((around, np.asarray(clip.waypoints, dtype=np.float32)))
            self.scene.set_floor(*floor_extent(clip.joints, around))
            self.scene.set_waypoints(clip.waypoints, clip.waypoint_joints)
            self.scene.set_targets(clip.targets, clip.keyframes())
            move_cameras(self.server, *frame_camera(clip.joints, clip.waypoints))
            self._draw()

    def toggle(self) -> None:
        """Play or pause (playing from the end starts over)."""
        with self.lock:
            self.playing = not self.playing
            if self.playing and self.clip is not None and self.frame >= self.clip.frames - 1:
                self.frame = 0.0
            self.play.label = "Pause" if self.playing else "Play"

    def _set_visible(self, setter: Any, checkbox: Any) -> None:
        """Show or hide the body or the skeleton as a checkbox says (a client may send any value)."""
        if not isinstance(checkbox.value, bool):
            complain("view", f"ignored {checkbox.label} {str(checkbox.value)[:40]!r}: expected true or false")
            return
        with self.lock:
            setter(checkbox.value)

    def _picked(self, event: Any) -> None:
        label = choice(self.picker.value, [e.label for e in self.source.entries])
        if label is None:
            complain("view", f"ignored episode {str(self.picker.value)[:80]!r}: not one of this source's entries")
            self.picker.value = self.label
            return
        if label != self.label:
            self.select(label)

    def _speed_changed(self, event: Any) -> None:
        value = choice(self.speed.value, SPEEDS)
        if value is None:
            complain("view", f"ignored speed {str(self.speed.value)[:80]!r}: expected one of {', '.join(SPEEDS)}")
            self.speed.value = f"{self.rate:g}"
            return
        self.rate = float(value)

    def _scrubbed(self, event: Any) -> None:
        """A client moved the slider: go to its frame, or put a bad value back with a one-line message.

        While playing, the next drawn frame may replace the client's value before this runs: the value is then
        dropped as a bad one is, only without the message.
        """
        if event.client is None:  # our own update from the playback thread
            return
        with self.lock:
            frame = number(self.slider.value, 0, self.clip.frames - 1)
            if frame is None:
                complain("view", f"ignored frame {str(self.slider.value)[:80]!r}: expected a number in "
                                 f"0..{self.clip.frames - 1}")
                self.slider.value = int(self.frame)
                return
            self.frame = frame
            self._draw()

    def _draw(self) -> None:
        """Show the current frame (caller holds the lock)."""
        clip = self.clip
        i = int(min(max(self.frame, 0), clip.frames - 1))
        self.scene.show_pose(clip.joints[i])
        if i % TRAIL_EVERY == 0 or not self.playing:
            self.scene.show_trail(clip.joints[: i + 1, PELVIS])
        self.scene.show_goal(None if clip.goals is None else clip.goals[i])
        self.scene.show_targets_at(i, clip.target_frames)
        self.slider.value = i
        text = clip.texts[i] or "(seed frames)"
        self.status.content = f"frame {i + 1}/{clip.frames} · {i / clip.fps:.2f} s · text: **{plain(text)}**"
        if self.follow.value:
            self.follower.update(clip.joints[i, PELVIS])
        else:
            self.follower.reset()

    def _run(self) -> None:
        last = time.perf_counter()
        while not self.stop.wait(TICK_S):
            now = time.perf_counter()
            dt, last = now - last, now
            with self.lock:
                if not self.playing or self.clip is None:
                    continue
                try:
                    self._advance(dt)
                except Exception as exc:  # never end the thread: the page would freeze with no way back
                    self.playing = False
                    self.play.label = "Play"
                    complain("view", f"playback paused: {type(exc).__name__}: {exc}")

    def _advance(self, dt: float) -> None:
        """Move ``dt`` seconds on at the chosen speed and draw (caller holds the lock)."""
        self.frame += dt * self.clip.fps * self.rate
        if not self.frame <= self.clip.frames - 1:  # loop (and recover from a non-finite frame)
            self.frame = 0.0
        with self.server.atomic():
            self._draw()
        if self.recorder is not None:
            i = int(min(max(self.frame, 0), self.clip.frames - 1))
            goal = None if self.clip.goals is None else self.clip.goals[i]
            self.recorder.add(self.clip.joints[i], self.clip.texts[i], goal)
