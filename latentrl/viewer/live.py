"""``latentrl play``: a trained policy and the motion model run live, steered from the page.

:class:`SteeredReachEnv` is ``ReachLocation`` with one env whose goal and text come from the user
instead of the sampler: a click sets the goal, shift-clicks append waypoints followed in order.
Both steered envs always hold a scene (``--scene``, the policy's training scene, or an empty one), so a
ctrl-click (cmd-click on macOS) can drop a box into it while the policy walks (:meth:`LiveController.drop_box`).
:class:`SteeredJoystickEnv` is ``Joystick`` whose heading and speed command comes from the keyboard
(arrows or WASD, through Viser's hotkey commands). :class:`LiveController` steps it with the policy
whenever fewer than one primitive of frames is waiting, and shows the frames at the motion's own
30 frames/s, so the character moves in real time as long as generation keeps ahead (its speed is shown).
"""

from __future__ import annotations

import collections
import dataclasses
import math
import threading
import time
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch

from latentrl.envs.config import observes_scene
from latentrl.envs.joystick import JoystickEnv, heading_deg, world_angle
from latentrl.envs.reach import ReachLocationEnv
from latentrl.errors import LatentRLError
from latentrl.evaluation.runner import policy_fn
from latentrl.evaluation.trained import stored_step_settings
from latentrl.motion.skeleton import FPS, PELVIS
from latentrl.optim.avoid import AvoidSettings, avoid, draws
from latentrl.scenes.scene import Box, Scene
from latentrl.scenes.spec import MAX_OBJECTS
from latentrl.viewer.guard import choice, complain, vector
from latentrl.viewer.joint_queue import joint_play_env
from latentrl.viewer.markup import plain
from latentrl.viewer.playback import TRAIL_EVERY, CameraFollower, move_cameras
from latentrl.viewer.scene import SkeletonScene
from latentrl.viewer.steered import Steered

MAX_GOAL_DISTANCE_M = 50.0
"""Clicks farther than this from the body are ignored (the env ends episodes 100 m from the goal)."""
MAX_RAY_COORD_M = 1e6
"""A click ray's origin and direction components must be finite and within this (else the click is ignored)."""
MAX_WAYPOINTS = 32
"""Waypoints a path may hold at once; shift-clicks beyond it are ignored."""
KEY_TURN_DEG = 15.0
"""Degrees one left/right key press turns the joystick heading."""
KEY_SPEED_STEP = 0.1
"""m/s one up/down key press adds to or takes from the joystick speed (held within the policy's trained range)."""
KEY_ACTIONS = {"arrowleft": "left", "A": "left", "arrowright": "right", "D": "right",
               "arrowup": "faster", "W": "faster", "arrowdown": "slower", "S": "slower", "space": "stop"}
"""Keys ``latentrl play`` takes for a joystick policy (Viser hotkey names) and what each does."""
DROP_MODIFIER = "cmd/ctrl"
"""The modifier of a click that drops a box (Viser's name: Ctrl, or Cmd on macOS)."""
DROP_BOX_SIZE = (0.6, 0.6, 1.0)
"""A dropped box's size (x, y, z), metres: a waist-high crate the body must walk around."""
DROP_CLEARANCE_M = 0.6
"""A box is not dropped with its centre closer than this to the pelvis (it would land on the body)."""
TRAIL_FRAMES = 6000
START_CAMERA = ((0.0, -4.5, 3.2), (0.0, 1.2, 0.6))
"""Camera (position, look_at) behind the start pose (the body starts at the origin facing +y)."""


class SteeredReachEnv(Steered, ReachLocationEnv):
    """``ReachLocation`` whose goal and text are set from outside (:meth:`set_goal`, :meth:`set_text`).

    Until a goal is set, the goal is the pelvis itself. Reaching the goal keeps it (no new goal is
    sampled); :attr:`last_frames` holds the (N, 8, 22, 3) world frames of the last step.
    """

    def __init__(self, num_envs: int = 1, **kwargs):
        self._user_goal: torch.Tensor | None = None
        super().__init__(num_envs, **kwargs)

    def set_goal(self, xy: Sequence[float]) -> None:
        """Put the goal at world ``xy`` on the floor (kept across resets until cleared)."""
        goal = torch.tensor([float(xy[0]), float(xy[1]), self.floor_height], device=self.device)
        self._user_goal = goal
        self._goal[:] = goal

    def clear_goal(self) -> None:
        """No goal: the next reset puts the goal at the pelvis."""
        self._user_goal = None

    def _sample_goals(self, idx: torch.Tensor) -> torch.Tensor:
        if self._user_goal is not None:
            return self._user_goal.expand(len(idx), 3).clone()
        pelvis = self.history_world(idx)[:, -1, PELVIS]
        return torch.cat((pelvis[:, :2], torch.full_like(pelvis[:, :1], self.floor_height)), dim=-1)

    def _reset_task(self, idx: torch.Tensor) -> None:
        super()._reset_task(idx)
        self._keep_text(idx)

    def _advance_task(self, reached: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return torch.zeros_like(reached), reached


class SteeredJoystickEnv(Steered, JoystickEnv):
    """``Joystick`` whose command (heading, speed) and text are set from outside (:meth:`set_command`).

    The command holds until set again (no random or timeline changes); :attr:`last_frames` holds the
    (N, 8, 22, 3) world frames of the last step.
    """

    def __init__(self, num_envs: int = 1, **kwargs):
        self._user_command = (0.0, 1.0)
        super().__init__(num_envs, **kwargs)
        self.set_command(0.0, sum(self.speed_range) / 2)

    def set_command(self, heading: float, speed: float) -> None:
        """Command world heading ``heading`` degrees (0 = +y, counter-clockwise) at ``speed`` m/s, across resets."""
        self._user_command = (float(heading), float(speed))
        self._heading[:] = world_angle(float(heading))
        self._heading[:] = torch.remainder(self._heading + math.pi, 2 * math.pi) - math.pi
        self._speed[:] = float(speed)

    @property
    def command(self) -> tuple[float, float]:
        """(heading degrees wrapped to (-180, 180], speed m/s) of env 0."""
        return float(heading_deg(self._heading)[0]), float(self._speed[0])

    def clear_goal(self) -> None:
        """Nothing to clear: the command is kept (the controller sets it on reset)."""

    def _reset_task(self, idx: torch.Tensor) -> None:
        super()._reset_task(idx)
        self._keep_text(idx)
        self._heading[idx] = world_angle(self._user_command[0])
        self._speed[idx] = self._user_command[1]

    def _advance_task(self, reached: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        self._changed = torch.zeros_like(reached)
        none = torch.zeros_like(reached)
        return none, none


def floor_point(origin: Sequence[float], direction: Sequence[float], floor: float = 0.0) -> np.ndarray | None:
    """Where a click ray meets the floor plane z = ``floor``, or None when it points up or along it."""
    o, d = np.asarray(origin, dtype=np.float64), np.asarray(direction, dtype=np.float64)
    if d[2] > -1e-6:
        return None
    t = (floor - o[2]) / d[2]
    return o + t * d if t > 0 else None


def training_scene(env_cfg: Mapping[str, Any]) -> Scene | None:
    """The fixed scene a policy was trained in (its stored ``env.scene``), or None.

    None also for random obstacles (drawn per episode) and for a scene file this machine cannot find.
    """
    from latentrl.envs.scene import resolve_scene

    if env_cfg.get("scene") is None:
        return None
    try:
        found = resolve_scene(env_cfg["scene"])
    except LatentRLError:
        return None
    return found if isinstance(found, Scene) else None


def play_env(checkpoint: Mapping[str, Any], model, text: str | None, device: str,
             task: str = "reach", scene: Scene | None = None, route: float | None = None) -> Any:
    """The env of ``latentrl play``: one steered env that steps the motion as the policy's training env.

    ``task`` 'joystick' gives a :class:`SteeredJoystickEnv` (the policy's trained speed range bounds the
    keys), 'reach_joint' a :class:`~latentrl.viewer.joint_queue.SteeredReachJointEnv` (its trained joints and
    targets), any other a :class:`SteeredReachEnv`.

    Its texts are ``text``, the training texts and the prompts the model knows; its
    :class:`~latentrl.envs.settings.StepSettings` are the checkpoint's (:func:`stored_step_settings`).
    Its scene is ``scene`` (``--scene``), else the policy's fixed training scene, else an empty one (boxes can
    be dropped into any); the policy observes it (``scene_rays``) only when it was trained with a scene, as
    ``latentrl eval --scene`` does. An empty scene steps exactly as the flat floor. ``route`` (``--route``; None:
    the policy's ``env.route``; 0: off): a reach, path or joystick policy heads along planned routes around the objects
    (:mod:`latentrl.envs.guide`), so boxes dropped in its way are walked around even by a policy that cannot see.
    """
    env_cfg = (checkpoint.get("config") or {}).get("env") or {}
    prompts = list(getattr(model.text_encoder, "prompts", None) or [])
    texts = list(dict.fromkeys([*([text] if text else []), *(env_cfg.get("texts") or []), *prompts])) or ["walk"]
    settings = stored_step_settings(checkpoint.get("config"))
    world = scene if scene is not None else (training_scene(env_cfg) or Scene())
    common = dict(motion=model, texts=texts, device=device, max_episode_steps=10**9, autoreset_mode="Disabled",
                  scene=world, observe_scene=observes_scene(env_cfg), **settings.step_kwargs())
    if observes_scene(env_cfg) and env_cfg.get("height_grid"):  # a grid is observed with the scene
        common.update(height_grid=int(env_cfg["height_grid"]),
                      height_grid_spacing=float(env_cfg.get("height_grid_spacing") or 0.25))
    if task == "reach_joint":
        return joint_play_env(env_cfg, **common)
    route = env_cfg.get("route") if route is None else (route or None)
    if task == "joystick":
        speeds = tuple((env_cfg.get("joystick") or {}).get("speed_range") or (0.7, 1.4))
        return SteeredJoystickEnv(1, speed_range=speeds, route=route, **common)
    return SteeredReachEnv(1, route=route, **common)


PLAY_SAMPLES = 16
"""Draws of the policy the play page's scene filter tries before its optimizer, unless the policy stores
``eval.avoid_samples``: a live character waits for every filtered step (docs/scenes.md, "Draws before the
optimizer")."""


class LiveController:
    """Runs a policy on a steered env and draws the result in a Viser server.

    On a :class:`SteeredReachEnv` a click on the floor sets the path to one goal and a shift-click appends
    a waypoint; reaching the goal moves it to the next waypoint. On a :class:`SteeredJoystickEnv` the keys of
    :data:`KEY_ACTIONS` (Viser hotkey commands) turn and speed up the command, and clicks are ignored.

    Args:
        server: a ``viser.ViserServer``.
        env: a one-env :class:`SteeredReachEnv` or :class:`SteeredJoystickEnv`.
        policy: an ``ActorCritic`` (``act(obs, deterministic)``).
        title: markdown shown at the top of the panel (strings from files in it must have gone through
            :func:`~latentrl.viewer.markup.plain`).
        text: the prompt to start with (one of ``env.texts``).
        deterministic: start with the policy's mean action instead of sampling it.
        seed: seed of the env (seed pose) and of action sampling.
        recorder: keeps the frames shown for ``--record`` (None: nothing kept).
        skeleton: draw the skeleton as well as the body from the start (``--skeleton``).
        avoid: the scene filter's settings (:mod:`latentrl.optim.avoid`; the policy's stored ``eval.avoid*``);
            its checkbox starts on when ``avoid.steps`` > 0. Near an object a filtered step takes up to a second on
            a CPU, so the motion may pause there; ``avoid.samples`` draws of the policy tried first shorten most of
            those steps (``latentrl play`` tries :data:`PLAY_SAMPLES` unless the policy stores its own).
    """

    def __init__(self, server: Any, env: SteeredReachEnv | SteeredJoystickEnv, policy: Any, title: str, text: str,
                 deterministic: bool = False, seed: int = 0, recorder: Any = None, skeleton: bool = False,
                 avoid: AvoidSettings | None = None):
        self.server, self.env, self.policy, self.seed = server, env, policy, seed
        avoid = avoid or AvoidSettings(steps=0)
        self.avoid = dataclasses.replace(avoid, steps=avoid.steps or AvoidSettings.steps)
        """The scene filter's settings when its checkbox is on."""
        self.avoid.check()  # a tampered stored value: one line before the page starts
        self.recorder = recorder
        """A :class:`~latentrl.viewer.record.Recorder` that keeps every frame shown (``--record``), or None."""
        self.lock = threading.Lock()
        self.stop = threading.Event()
        self.frames: collections.deque[np.ndarray] = collections.deque()
        self.trail: list[np.ndarray] = []
        self.goal: np.ndarray | None = None
        self.path: list[np.ndarray] = []
        """Waypoints still to reach, the current goal first (reach/path policies)."""
        self.joystick = isinstance(env, SteeredJoystickEnv)
        self.active = False
        self.reached_at: float | None = None
        self.goal_set_at = 0.0
        self.gen_fps = 0.0
        self.show_fps = 0.0
        self.message = self._idle_message()
        self.dropped = 0
        """Boxes dropped by hand: the last this many objects of the env's scene."""
        self.scene = SkeletonScene(server, skeleton=skeleton)
        self._show_world(self.world())
        self.scene.set_floor(np.zeros(2), 40.0)
        gui = server.gui
        gui.add_markdown(title)
        self.text = gui.add_dropdown("text", list(env.texts), initial_value=text)
        self.deterministic = gui.add_checkbox("mean action", deterministic)
        self.follow = gui.add_checkbox("follow camera", True)
        self.show_body = gui.add_checkbox("body", True)
        self.show_skeleton = gui.add_checkbox("skeleton", bool(skeleton))
        self.filtering = gui.add_checkbox("scene filter (keeps the body off objects)", avoid.steps > 0)
        self.reset_button = gui.add_button("Reset")
        self.clear_button = gui.add_button("Remove dropped boxes")
        self.status = gui.add_markdown("")
        self.text.on_update(lambda event: self._set_text(self.text.value))
        self.show_body.on_update(lambda event: self._set_visible(self.scene.set_body_visible, self.show_body))
        self.show_skeleton.on_update(lambda event: self._set_visible(self.scene.set_skeleton_visible,
                                                                     self.show_skeleton))
        self.reset_button.on_click(lambda event: self.reset())
        self.clear_button.on_click(lambda event: self.clear_boxes())
        server.scene.on_click(modifier=DROP_MODIFIER)(lambda event: self._drop_clicked(event))
        if self.joystick:
            self.keys = {}
            for key, what in KEY_ACTIONS.items():
                name = {"arrowleft": "←", "arrowright": "→", "arrowup": "↑", "arrowdown": "↓"}.get(key, key)
                handle = gui.add_command(f"{what} ({name})", hotkey=key)  # type: ignore[arg-type]
                handle.on_trigger(lambda event, key=key: self.press(key))
                self.keys[key] = handle
        else:
            server.scene.on_click()(lambda event: self._clicked(event, append=False))
            server.scene.on_click(modifier="shift")(lambda event: self._clicked(event, append=True))
        self.follower = CameraFollower(server)
        self.reset()
        self.thread = threading.Thread(target=self._run, name="latentrl-play", daemon=True)

    def start(self) -> None:
        """Start the generation loop thread."""
        self.thread.start()

    # ------------------------------------------------------------------ user input
    def _set_text(self, text: Any) -> None:
        if choice(text, self.env.texts) is None:
            complain("play", f"ignored text {str(text)[:80]!r}: not one of the texts offered")
            self.text.value = self.env.text
            return
        with self.lock:
            self.env.set_text(text)

    def _idle_message(self) -> str:
        if self.joystick:
            return "arrows or WASD: up/W faster, down/S slower, left/A and right/D turn; space stops; " \
                   "ctrl-click drops a box"
        return "click on the floor to set a goal; shift-click adds waypoints; ctrl-click drops a box"

    def _set_visible(self, setter: Any, checkbox: Any) -> None:
        """Show or hide the body or the skeleton as a checkbox says (a client may send any value)."""
        if not isinstance(checkbox.value, bool):
            complain("play", f"ignored {checkbox.label} {str(checkbox.value)[:40]!r}: expected true or false")
            return
        with self.lock:
            setter(checkbox.value)

    def world(self) -> Scene | None:
        """The env's scene as objects now (None: an env built without one, where no box can be dropped)."""
        scene = getattr(self.env, "scene", None)
        return None if scene is None or scene.random else scene.spec

    def _show_world(self, world: Scene | None) -> None:
        """Draw ``world`` on the page (dropped boxes in their colour) and in the recording."""
        self.scene.set_scene(world, self.dropped)
        if self.recorder is not None:
            self.recorder.set_scene(world if world is not None and world.objects else None)

    def _floor_click(self, event: Any) -> np.ndarray | None:
        """Where a click's ray meets the floor, or None (and one line for a malformed ray)."""
        origin = vector(event.ray_origin, 3, MAX_RAY_COORD_M)
        direction = vector(event.ray_direction, 3, MAX_RAY_COORD_M)
        if origin is None or direction is None:
            ray = f"{str(event.ray_origin)[:60]}, {str(event.ray_direction)[:60]}"
            complain("play", f"ignored a click: its ray ({ray}) is not two vectors of 3 finite numbers")
            return None
        point = floor_point(origin, direction, self.env.floor_height)
        if point is None or not np.isfinite(point).all():
            return None
        return point

    def _drop_clicked(self, event: Any) -> None:
        point = self._floor_click(event)
        if point is not None:
            self.drop_box(point[:2])

    def drop_box(self, xy: Sequence[float]) -> bool:
        """Drop a :data:`DROP_BOX_SIZE` box on the floor at ``xy`` into the env's scene; whether it was dropped.

        From the next step on the policy's scene observation (when it has one), the collision term and the
        floor snap see it. Refused (with a status message) beyond the goal distance bound, within
        :data:`DROP_CLEARANCE_M` of the pelvis, past :data:`~latentrl.scenes.spec.MAX_OBJECTS` objects, or in
        an env without a fixed scene.
        """
        with self.lock:
            world = self.world()
            if world is None:
                self.message = "box ignored: this env has no scene to drop it into"
                return False
            if not self._near(xy):
                return False
            pelvis = self.pelvis()
            if not float(np.hypot(xy[0] - pelvis[0], xy[1] - pelvis[1])) >= DROP_CLEARANCE_M:
                self.message = f"box ignored: within {DROP_CLEARANCE_M} m of the body"
                return False
            if len(world.objects) >= MAX_OBJECTS:
                self.message = f"box ignored: the scene holds {MAX_OBJECTS} objects already"
                return False
            box = Box((float(xy[0]), float(xy[1])), DROP_BOX_SIZE)
            world = Scene((*world.objects, box), world.floor_height)
            self.env.scene.replace(world)
            self.dropped += 1
            self._show_world(world)
            self.message = f"dropped a box at ({xy[0]:.2f}, {xy[1]:.2f})"
        print(f"latentrl play: box dropped at ({xy[0]:.2f}, {xy[1]:.2f})", flush=True)
        return True

    def clear_boxes(self) -> None:
        """Take the dropped boxes out of the env's scene again (the scene's own objects stay)."""
        with self.lock:
            world = self.world()
            if world is None or not self.dropped:
                return
            world = Scene(world.objects[: len(world.objects) - self.dropped], world.floor_height)
            self.env.scene.replace(world)
            self.dropped = 0
            self._show_world(world)
            self.message = "dropped boxes removed"

    def press(self, key: Any) -> None:
        """Apply one key of :data:`KEY_ACTIONS` to the joystick command; anything else is ignored with one line."""
        if not self.joystick or choice(key, tuple(KEY_ACTIONS)) is None:
            complain("play", f"ignored key {str(key)[:40]!r}: not one of {', '.join(KEY_ACTIONS)}"
                     + ("" if self.joystick else " (keys steer joystick policies)"))
            return
        what = KEY_ACTIONS[key]
        with self.lock:
            heading, speed = self.env.command
            lo, hi = self.env.speed_range
            if what == "stop":
                self.active = False
                self.message = "stopped; any arrow or WASD key walks on"
                return
            if what in ("left", "right"):
                heading += KEY_TURN_DEG if what == "left" else -KEY_TURN_DEG
                heading = (heading + 180.0) % 360.0 - 180.0
            else:
                speed = min(hi, max(lo, speed + (KEY_SPEED_STEP if what == "faster" else -KEY_SPEED_STEP)))
            self.env.set_command(heading, speed)
            self.active = True
            self.message = f"heading {heading:.0f}°, speed {speed:.1f} m/s"

    def _clicked(self, event: Any, append: bool = False) -> None:
        point = self._floor_click(event)
        if point is None:
            return
        if append:
            self.add_waypoint(point[:2])
        else:
            self.set_goal(point[:2])

    def set_goal(self, xy: Sequence[float]) -> None:
        """Send the character to ``xy`` (world metres), replacing the path; ignored beyond the distance bound.

        The bound is :data:`MAX_GOAL_DISTANCE_M` from the body.
        """
        with self.lock:
            if not self._near(xy):
                return
            self.path = [np.array([float(xy[0]), float(xy[1]), 0.0])]
            self._aim()
        print(f"latentrl play: goal ({xy[0]:.2f}, {xy[1]:.2f})", flush=True)

    def add_waypoint(self, xy: Sequence[float]) -> None:
        """Append ``xy`` to the path (a shift-click); with no goal in force it becomes the goal."""
        with self.lock:
            if not self._near(xy):
                return
            if len(self.path) >= MAX_WAYPOINTS:
                self.message = f"waypoint ignored: the path holds {MAX_WAYPOINTS} already"
                return
            self.path.append(np.array([float(xy[0]), float(xy[1]), 0.0]))
            if self.active and len(self.path) > 1:
                self.scene.set_waypoints(np.array(self.path[1:]))
            else:
                self.path = self.path[-1:]
                self._aim()
        print(f"latentrl play: waypoint ({xy[0]:.2f}, {xy[1]:.2f})", flush=True)

    def _near(self, xy: Sequence[float]) -> bool:
        pelvis = self.pelvis()
        if not float(np.hypot(xy[0] - pelvis[0], xy[1] - pelvis[1])) <= MAX_GOAL_DISTANCE_M:  # NaN too
            self.message = f"goal ignored: more than {MAX_GOAL_DISTANCE_M:.0f} m away"
            return False
        return True

    def _aim(self) -> None:
        """Make the path's first waypoint the env's goal and walk (caller holds the lock)."""
        self.goal = self.path[0]
        self.env.set_goal(self.goal[:2])
        self.active, self.reached_at, self.goal_set_at = True, None, time.perf_counter()
        self.message = "walking to the goal" if len(self.path) == 1 else f"walking a path of {len(self.path)} waypoints"
        self.scene.show_goal(self.goal)
        self.scene.set_waypoints(np.array(self.path[1:]) if len(self.path) > 1 else None)

    def reset(self) -> None:
        """Back to a fresh seed pose at the origin, no goal."""
        with self.lock:
            torch.manual_seed(self.seed)
            self.env.clear_goal()
            if self.joystick:
                self.env.set_command(0.0, sum(self.env.speed_range) / 2)
            self.env.set_text(self.text.value)
            self.obs, _ = self.env.reset(seed=self.seed)
            self.frames.clear()
            pose = self.env.history_world()[0, -1].cpu().numpy()
            self.current = pose
            self.trail = [pose[PELVIS]]
            self.goal, self.path, self.active, self.reached_at = None, [], False, None
            self.message = self._idle_message()
            self.scene.show_goal(None)
            self.scene.set_waypoints(None)
            self.scene.show_pose(pose)
            self.scene.show_trail(np.array(self.trail))
            self.follower.reset()
            move_cameras(self.server, *(np.array(v) for v in START_CAMERA))

    def pelvis(self) -> np.ndarray:
        """(3,) world position of the pelvis in the frame shown now."""
        return self.current[PELVIS]

    # ------------------------------------------------------------------ the loop
    def _action(self) -> torch.Tensor:
        """The noise of the next step: the policy's, through the scene filter when its checkbox is on."""
        with torch.no_grad():
            action = self.policy.act(self.obs, deterministic=bool(self.deterministic.value)).action
        if self.filtering.value is True and getattr(self.env, "scene", None) is not None:
            action = avoid(self.env, action, self.avoid, draws(policy_fn(self.policy, False), self.obs))
        return action

    def _generate(self) -> None:
        """One policy call and env step: 8 new frames (caller holds the lock)."""
        start = time.perf_counter()
        self.obs, _, _, _, infos = self.env.step(self._action())
        new = self.env.last_frames[0].cpu().numpy()
        took = time.perf_counter() - start
        rate = len(new) / max(took, 1e-6)
        self.gen_fps = rate if self.gen_fps == 0 else 0.8 * self.gen_fps + 0.2 * rate
        self.frames.extend(new)
        if bool(infos["diverged"][0]):
            self.message = "the motion diverged; press Reset"
            self.active = False
        else:
            self._after_step(infos)

    def _after_step(self, infos: Mapping[str, Any]) -> None:
        """A reached waypoint moves the goal to the next, the last ends the walk (reach/path policies)."""
        if not self.joystick and bool(infos["goal_reached"][0]) and len(self.path) > 1:
            self.path.pop(0)
            print(f"latentrl play: reached waypoint ({self.goal[0]:.2f}, {self.goal[1]:.2f}); "
                  f"{len(self.path)} to go", flush=True)
            self._aim()
        elif not self.joystick and bool(infos["goal_reached"][0]):
            self.active = False
            self.path = []
            self.reached_at = time.perf_counter()
            self.message = f"reached the goal in {self.reached_at - self.goal_set_at:.1f} s; click again"
            print(f"latentrl play: reached ({self.goal[0]:.2f}, {self.goal[1]:.2f}) "
                  f"in {self.reached_at - self.goal_set_at:.1f} s", flush=True)

    def _show_next(self) -> None:
        pose = self.frames.popleft()
        self.current = pose
        if self.recorder is not None:
            self.recorder.add(pose, self.env.text, self.goal)
        self.trail.append(pose[PELVIS])
        del self.trail[:-TRAIL_FRAMES]
        with self.server.atomic():
            self.scene.show_pose(pose)
            if len(self.trail) % TRAIL_EVERY == 0 or not self.frames:
                self.scene.show_trail(np.array(self.trail))
            if self.follow.value:
                self.follower.update(pose[PELVIS])
            else:
                self.follower.reset()

    def scene_line(self) -> str:
        """The status line on the scene: its objects, the dropped boxes, whether the policy sees them."""
        world = self.world()
        if world is None or not world.objects:
            return ""
        seen = "the policy sees them" if self.env.observe_scene else \
            "the policy does not see them: trained blind to scenes"
        n = len(world.objects)
        dropped = f", {self.dropped} dropped" if self.dropped else ""
        first = f", {self.avoid.samples} draws first" if self.avoid.samples else ""
        kept = f"; scene filter on ({self.avoid.steps} steps{first})" if self.filtering.value is True else ""
        return f"  \nscene: {n} object{'' if n == 1 else 's'}{dropped} ({seen}{kept})"

    def status_text(self) -> str:
        """The status panel: message, pelvis, goal, distance, scene and generation speed (markdown)."""
        p = self.pelvis()
        if self.joystick:
            heading, speed = self.env.command
            return (f"{self.message}{self.scene_line()}  \npelvis: ({p[0]:.2f}, {p[1]:.2f}) m  \n"
                    f"command: heading {heading:.0f}° (0 = +y, counter-clockwise), speed {speed:.1f} m/s  \n"
                    f"text: **{plain(self.env.text)}**  \n"
                    f"generation: {self.gen_fps:.0f} frames/s (policy + motion model)  \n"
                    f"display: {self.show_fps:.0f} frames/s")
        goal = "none" if self.goal is None else f"({self.goal[0]:.2f}, {self.goal[1]:.2f}) m"
        dist = "–" if self.goal is None else f"{np.hypot(*(self.goal[:2] - p[:2])):.2f} m"
        return (f"{self.message}{self.scene_line()}  \npelvis: ({p[0]:.2f}, {p[1]:.2f}) m  \ngoal: {goal}  \n"
                f"distance: {dist}  \n"
                f"text: **{plain(self.env.text)}**  \ngeneration: {self.gen_fps:.0f} frames/s (policy + motion model)"
                f"  \ndisplay: {self.show_fps:.0f} frames/s")

    def _run(self) -> None:
        period = 1.0 / FPS
        next_frame = time.perf_counter()
        shown, count_since = 0, time.perf_counter()
        last_status = 0.0
        while not self.stop.is_set():
            with self.lock:
                try:
                    if self.active and len(self.frames) < 8:
                        self._generate()
                    now = time.perf_counter()
                    if self.frames and now >= next_frame:
                        self._show_next()
                        shown += 1
                        next_frame = max(next_frame + period, now - period)
                    elif not self.frames:
                        next_frame = now
                    if now - count_since >= 1.0:
                        self.show_fps, shown, count_since = shown / (now - count_since), 0, now
                    if now - last_status >= 0.25:
                        text = self.status_text()
                        if text != self.status.content:  # an idle page gets no messages
                            self.status.content = text
                        last_status = now
                except Exception as exc:  # never end the thread: the page would freeze with no way back
                    self.active = False
                    self.frames.clear()
                    self.message = "generation failed; press Reset"
                    complain("play", f"live control paused: {type(exc).__name__}: {exc}")
            time.sleep(max(0.0, min(next_frame - time.perf_counter(), 0.01)))
