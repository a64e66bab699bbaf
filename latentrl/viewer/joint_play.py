"""``latentrl play`` of a ReachJoint policy: clicks place joint goals at a time, and the character lands them.

:class:`JointGoalController` fills the queue of a :class:`~latentrl.viewer.joint_queue.SteeredReachJointEnv` (each
goal a joint, a target and a time) from the page: a click on the floor replaces the queue with one goal for the
joint picked in the panel, due the picked seconds from now (0: as soon as possible); a shift-click appends one due
that many seconds after the goal before it, so a few shift-clicks lay out footsteps or a timed path. Feet aim at the
clicked spot on the floor, hands and the head at the picked height above it, the pelvis at the spot (or at its own
height for a policy that learnt 3-D pelvis targets). Each goal's error at its time is printed and shown.

With ``refine`` on (the policy's stored ``eval.refine`` steps), every step's noise is refined first
(:mod:`latentrl.optim.refine`), which lands the goals to centimetres where the policy alone lands them tens of
centimetres off (docs/joint_goals.md); on a CPU that is slower than real time, so the character moves in slow
motion (the panel shows the generation speed).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import torch

from latentrl.envs.reach_joint import JOINTS
from latentrl.motion.skeleton import FPS
from latentrl.optim.refine import STARTS, RefineSettings, refine
from latentrl.viewer.guard import choice, complain
from latentrl.viewer.joint_queue import MAX_QUEUED, SteeredReachJointEnv
from latentrl.viewer.live import LiveController
from latentrl.viewer.markup import plain

MAX_SECONDS = 10.0
"""The longest time a goal may be given (the panel's slider)."""
DEFAULT_SECONDS = 2.0
HEIGHT_RANGE = (0.1, 2.2)
"""Metres above the floor a hand or head target may be put at (the panel's slider)."""
DEFAULT_HEIGHT = 1.2
DEFAULT_REFINE_STEPS = 16
"""Refinement steps when the policy stores none (the shipped pelvis policy stores 16)."""
MAX_REFINE_STEPS = 64
"""The most refinement steps the panel offers."""
HEIGHT_JOINTS = ("left_hand", "right_hand", "head")
"""Joints whose clicked target is lifted to the panel's height; the others aim at the floor point."""


class JointGoalController(LiveController):
    """:class:`~latentrl.viewer.live.LiveController` for a :class:`SteeredReachJointEnv` (module docstring).

    The panel's joint starts on the first the policy was trained on (``env.joints``). ``refinement``: the refinement
    settings (the policy's stored ones; steps 0 or None: refinement off at the start, at
    :data:`DEFAULT_REFINE_STEPS` once switched on).
    """

    def __init__(self, server: Any, env: SteeredReachJointEnv, policy: Any, title: str, text: str,
                 refinement: RefineSettings | None = None, **kwargs):
        refinement = refinement or RefineSettings(steps=0)
        self.settings = replace(refinement, steps=refinement.steps or DEFAULT_REFINE_STEPS,
                                policy_joints=tuple(env.joints))
        self.settings.check()
        self.scored = 0
        """Goals already reported (``env.scored_goals()``)."""
        super().__init__(server, env, policy, title, text, **kwargs)
        gui = server.gui
        self.joint = gui.add_dropdown("goal joint", list(JOINTS), initial_value=env.joints[0])
        self.seconds = gui.add_slider("seconds (0: as soon as possible)", 0.0, MAX_SECONDS, 0.1, DEFAULT_SECONDS)
        self.height = gui.add_slider("hand/head height (m)", *HEIGHT_RANGE, 0.05, DEFAULT_HEIGHT)
        self.refining = gui.add_checkbox("refine", refinement.steps > 0)
        self.refine_steps = gui.add_slider("refine steps (fewer: faster)", 1, MAX_REFINE_STEPS, 1,
                                           min(self.settings.steps, MAX_REFINE_STEPS))
        self.refine_from = gui.add_dropdown("refine from", list(STARTS), initial_value=refinement.start)

    def _idle_message(self) -> str:
        return ("click on the floor: a goal for the joint picked below, due in the picked seconds; shift-click: "
                "one more, that many seconds after the last; ctrl-click drops a box")

    # ------------------------------------------------------------------ goals from clicks
    def goal_target(self, joint: str, xy: Sequence[float]) -> np.ndarray:
        """(2,) or (3,) the target a click at floor ``xy`` gives ``joint`` (module docstring)."""
        if self.env.planar_joint(joint):
            return np.array([float(xy[0]), float(xy[1])])
        if joint in HEIGHT_JOINTS:
            height = float(self.height.value)
            if not (math.isfinite(height) and HEIGHT_RANGE[0] <= height <= HEIGHT_RANGE[1]):
                height = DEFAULT_HEIGHT
            return np.array([float(xy[0]), float(xy[1]), self.env.floor_height + height])
        return np.array([float(xy[0]), float(xy[1]), float(self.current[JOINTS[joint], 2])])

    def _picked(self) -> tuple[str, float | None] | None:
        """The panel's joint and seconds (None: asap), or None with one line when a client sent a bad value."""
        joint = choice(self.joint.value, tuple(JOINTS))
        seconds = self.seconds.value
        if joint is None or not isinstance(seconds, (int, float)) or not 0 <= seconds <= MAX_SECONDS:
            complain("play", f"ignored a goal: joint {str(self.joint.value)[:40]!r}, seconds "
                             f"{str(seconds)[:40]!r} (expected one of {', '.join(JOINTS)} and 0-{MAX_SECONDS:g})")
            return None
        return joint, (None if seconds == 0 else float(seconds))

    def set_goal(self, xy: Sequence[float]) -> None:
        """Replace the queue with one goal at floor ``xy`` for the panel's joint, due the panel's seconds from now."""
        self._queue(xy, append=False)

    def add_waypoint(self, xy: Sequence[float]) -> None:
        """Append a goal at ``xy``, due the panel's seconds after the goal before it (a shift-click)."""
        self._queue(xy, append=True)

    def _queue(self, xy: Sequence[float], append: bool) -> None:
        picked = self._picked()
        if picked is None:
            return
        joint, seconds = picked
        with self.lock:
            if not self._near(xy):
                return
            target = self.goal_target(joint, xy)
            if not self.env.add_goal(joint, target, seconds, append=append):
                self.message = f"goal ignored: {MAX_QUEUED} goals are pending already"
                return
            if not append:
                self.scored = 0
            self.active, self.reached_at, self.goal_set_at = True, None, time.perf_counter()
            when = "as soon as possible" if seconds is None else f"in {seconds:g} s"
            self.message = f"{self.env.pending()} goal(s) pending; the last: {joint} {when}" + \
                (" after the one before" if append and self.env.pending() > 1 and seconds is not None else "")
            self._show_goals()
        place = ", ".join(f"{v:.2f}" for v in target)
        print(f"latentrl play: {joint} goal ({place}) "
              f"{'as soon as possible' if seconds is None else f'{seconds:g} s'}"
              f"{' after the one before' if append else ' from now'}", flush=True)

    def _show_goals(self) -> None:
        """Markers on the pending goals, coloured by joint, the current one first (caller holds the lock)."""
        queued = self.env.queued_goals()
        if not queued:
            self.goal = None
            self.scene.set_waypoints(None)
            return
        self.goal = queued[0]["target"]
        self.scene.set_waypoints(np.array([g["target"] for g in queued]),
                                 np.array([JOINTS[g["joint"]] for g in queued]))

    # ------------------------------------------------------------------ the loop
    def _action(self) -> torch.Tensor:
        action = super()._action()
        if not self.refining.value or self.env.pending() == 0:
            return action
        steps = self.refine_steps.value
        if isinstance(steps, (int, float)) and not isinstance(steps, bool) and 1 <= steps <= MAX_REFINE_STEPS:
            self.settings.steps = int(steps)
        else:  # a page may send anything: keep the last good value
            complain("play", f"ignored refine steps {str(steps)[:40]!r}: expected 1-{MAX_REFINE_STEPS}")
            self.refine_steps.value = self.settings.steps
        self.settings.start = choice(self.refine_from.value, STARTS) or "policy"
        return refine(self.env, action, self.settings)

    def _after_step(self, infos: Mapping[str, Any]) -> None:
        """Print each goal that fell due in the step, with its error; stop when none is pending."""
        scored = self.env.scored_goals()
        for joint, error in scored[self.scored:]:
            within = "within" if error < self.env.radius else "beyond"
            print(f"latentrl play: {joint} goal {100 * error:.1f} cm off ({within} {100 * self.env.radius:g} cm)",
                  flush=True)
            self.message = f"{joint} goal: {100 * error:.1f} cm off; {self.env.pending()} pending"
        self.scored = len(scored)
        self._show_goals()
        if self.env.pending() == 0:
            self.active = False
            self.reached_at = time.perf_counter()
            errors = [e for _, e in scored]
            if errors:
                hit = sum(e < self.env.radius for e in errors)
                self.message = (f"{len(errors)} goal(s): mean error {100 * float(np.mean(errors)):.1f} cm, "
                                f"{hit} within {100 * self.env.radius:g} cm; click again")

    def reset(self) -> None:
        """Back to a fresh seed pose at the origin, the queue empty."""
        super().reset()
        self.scored = 0
        with self.lock:
            self._show_goals()

    def status_text(self) -> str:
        """The status panel: message, the current goal and its time, the queue, refinement and speed (markdown)."""
        p = self.pelvis()
        queued = self.env.queued_goals()
        if queued:
            g = queued[0]
            due = "time not known yet" if g["frames"] is None else f"due in {max(g['frames'], 0) / FPS:.1f} s"
            place = ", ".join(f"{v:.2f}" for v in g["target"][: 2 if self.env.planar_joint(g["joint"]) else 3])
            goal = f"{g['joint']} at ({place}) m, {due}; {len(queued)} pending"
        else:
            goal = "none"
        refined = f"on ({self.settings.steps} steps)" if self.refining.value else "off"
        return (f"{self.message}{self.scene_line()}  \npelvis: ({p[0]:.2f}, {p[1]:.2f}) m  \ngoal: {goal}  \n"
                f"text: **{plain(self.env.text)}**  \nrefinement: {refined}  \n"
                f"generation: {self.gen_fps:.0f} frames/s (policy + motion model"
                f"{' + refinement' if self.refining.value else ''})  \ndisplay: {self.show_fps:.0f} frames/s")
