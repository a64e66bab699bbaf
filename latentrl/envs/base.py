"""The torch-native Gymnasium vector env over a frozen motion model: the action is the latent noise.

One :meth:`LatentMotionVectorEnv.step` runs :meth:`MotionModel.rollout_step` **once** for all
``num_envs`` environments (10 DDIM steps with classifier-free guidance and one VAE decode,
producing 8 frames = 0.267 s per env). All state lives on ``device``; observations, rewards and
masks come back as torch tensors; no Python loop runs over environments.

Tasks (:mod:`latentrl.envs.reach`, :mod:`latentrl.envs.path`) supply the goal: they sample it
at reset, observe it, and react when it is reached. This module owns everything else: motion
stepping, observation assembly, rewards, episode counters, autoreset, partial resets, seeding,
infos and history recording.

Frames: "world" is metres, z up, floor at ``floor_height`` (0), the start pelvis at the xy
origin facing +y. "Canonical" is the frame of the current history's first frame (DART).
"""

from __future__ import annotations

from collections import OrderedDict
from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from latentrl.config import require
from latentrl.constants import (
    ACTION_BOUND,
    GUIDANCE_SCALE,
    OBS_GOAL_ANGLE_CLIP_DEG,
    OBS_GOAL_DIST_CLIP_M,
    SUCCESS_RADIUS_M,
    TERMINATE_DISTANCE_M,
)
from latentrl.envs.compiled import compile_step_core
from latentrl.envs.divergence import diverged as diverged_envs
from latentrl.envs.divergence import feature_range, keep_finite
from latentrl.envs.episode_state import autoreset_mode as autoreset_mode_of
from latentrl.envs.episode_state import (
    check_reset,
    mask_to_index,
    prepare_actions,
    replace_rows,
    restore,
    snapshot,
    step_infos,
)
from latentrl.envs.goal import goal_features
from latentrl.envs.guide import RouteGuide
from latentrl.envs.history import HistoryRecorder, RecordedEpisodes
from latentrl.envs.observation import ObservationLayout, observe
from latentrl.envs.scene import HEIGHT_GRID_SPACING_M, env_scene, grid_offsets, height_grid_problem
from latentrl.envs.settings import StepSettings
from latentrl.envs.task_hooks import TaskHooks
from latentrl.envs.texts import TextTable
from latentrl.errors import ConfigError
from latentrl.motion.canonical import features_to_world, world_to_canonical
from latentrl.motion.prior import MotionPrior, load_prior
from latentrl.motion.representation import joints_of
from latentrl.motion.rollout import LOCK_MIN_WEIGHT, RolloutState
from latentrl.motion.skeleton import PELVIS
from latentrl.rewards.compose import COMMON_TERMS, DART_TERMS, SCENE_TERMS, RewardComposer, RewardConfig, RewardInputs
from latentrl.scenes.route import RouteSettings


class LatentMotionVectorEnv(TaskHooks, RecordedEpisodes, VectorEnv):
    """Batched envs whose action is the initial DDIM noise of a frozen motion model.

    Subclasses implement the goal: :meth:`_reset_task`, :attr:`goal_world`,
    :meth:`_goal_observation` and :meth:`_advance_task`, and name its fields in :attr:`goal_fields`.
    See ``docs/envs.md`` for every argument, observation field, reward term and info key.

    Args (each in docs/envs.md's table, with its default):
        num_envs: N, environments stepped together.
        motion: ``"default"`` (the embedded model), a model path, or a loaded
            :class:`~latentrl.motion.MotionPrior` (moved to ``device`` in place).
        texts, text_weights: prompts an episode's text is drawn from, and their weights (None: uniform).
        device: where state, model and outputs live.
        max_episode_steps: steps (primitives of 8 frames) before truncation (DART 32).
        autoreset_mode: ``SAME_STEP`` (default) or ``DISABLED`` (reset with ``reset_mask``).
        guidance_scale, action_bound, foot_lock, foot_lock_min_weight, amp: how the motion is stepped
            (:class:`~latentrl.envs.settings.StepSettings`: guidance, the clamp of actions, the foot lock and
            the autocast dtype of the sampler, which sets the model's ``amp_dtype``).
        nonfinite_actions: ``"error"`` raises :class:`~latentrl.errors.NonFiniteError` naming the
            envs; ``"zero"`` replaces those rows with 0 and reports ``infos["nonfinite_action"]``.
        obs_goal_angle_clip_deg, obs_goal_dist_clip: clips of the goal observation (DART 60 degrees, 5 m).
        floor_height: world z of the floor, metres (rewards and the ``scene`` observation).
        success_threshold: a goal is reached when the pelvis comes closer (xy) during a step (DART 0.3 m).
        terminate_distance: terminate when the pelvis is farther (xy) from the goal (DART 100 m).
        divergence_limit: terminate envs whose motion is non-finite, beyond this many metres, sunk under
            the floor or out of the data's range (:mod:`latentrl.envs.divergence`); they keep their state, reward 0.
        random_initial_steps: start the counters of a full reset uniformly in ``[0, max_episode_steps)``.
        reward_weights, reward_config: per-term weight overrides and :class:`~latentrl.rewards.RewardConfig`.
        record_history, record_features: keep every step (and its 276-D world features) for
            :meth:`export_history` (one device-to-host copy per step; clear it to bound memory).
        render_mode: only ``None``; render exported histories with :mod:`latentrl.render`.
        compile: run each step's tensor maths (:meth:`_motion_core`) as one ``torch.compile(fullgraph=True)``
            graph, on CUDA captured as a CUDA graph (:mod:`latentrl.envs.compiled`); the first step compiles.
        scene, terminate_on_collision: objects in the world (:mod:`latentrl.envs.scene`: a scene file, a
            :class:`~latentrl.scenes.Scene`, random obstacles or random mazes, the last for the path task only;
            None: the flat floor alone) and whether a joint
            inside its skin radius of one ends the episode. A scene adds the ``scene_rays`` observation group
            (unless ``observe_scene`` is False: a policy trained without a scene, evaluated among objects) and the
            ``collision`` and ``terrain_contact`` reward terms (docs/scenes.md).
        height_grid, height_grid_spacing: with a scene, also observe the terrain on a ``height_grid`` x
            ``height_grid`` grid of samples ``height_grid_spacing`` metres apart around the pelvis, in the body
            frame (the ``scene_height_grid`` group; 0: none, the default).
        route: with a scene, the clearance (metres) of the routes a :class:`~latentrl.envs.guide.RouteGuide`
            plans to each goal; where an object stands in the way, ``goal_dir`` / ``goal_dist`` show the farthest
            route point in clear sight instead of the goal (tasks that are ``routable()``: reach, path, timed and
            joystick; None: off, the default).
    """

    metadata: dict[str, Any] = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}
    goal_fields: tuple[tuple[str, int], ...] = (("goal_dir", 3), ("goal_dist", 1))
    """Named fields of the ``goal`` observation group, in order; tasks may extend."""
    task_group: tuple[str, ...] = ()
    """The tail of ``goal_fields`` observed as a ``task`` group of its own (:class:`ObservationLayout`)."""
    reward_terms: tuple[str, ...] = (*DART_TERMS, *COMMON_TERMS)
    """The reward terms this task computes and reports (``infos["reward/<name>"]``)."""
    walks_courses: bool = False
    """The task takes its goals from a course's route, so it accepts course pools (``{random_mazes: ...}``,
    ``{random_stairs: ...}``) as scenes."""

    def __init__(
        self,
        num_envs: int = 1,
        *,
        motion: str | MotionPrior = "default",
        texts: Sequence[str] = ("walk",),
        text_weights: Sequence[float] | None = None,
        device: str | torch.device = "cpu",
        max_episode_steps: int = 32,
        autoreset_mode: AutoresetMode | str = AutoresetMode.SAME_STEP,
        action_bound: float = ACTION_BOUND,
        guidance_scale: float = GUIDANCE_SCALE,
        nonfinite_actions: str = "error",
        obs_goal_angle_clip_deg: float = OBS_GOAL_ANGLE_CLIP_DEG,
        obs_goal_dist_clip: float = OBS_GOAL_DIST_CLIP_M,
        floor_height: float = 0.0,
        success_threshold: float = SUCCESS_RADIUS_M,
        terminate_distance: float = TERMINATE_DISTANCE_M,
        divergence_limit: float = 1e3,
        random_initial_steps: bool = False,
        reward_weights: Mapping[str, float] | None = None,
        reward_config: RewardConfig | None = None,
        record_history: bool = False,
        record_features: bool = False,
        render_mode: str | None = None,
        compile: bool = False,
        foot_lock: bool = False,
        foot_lock_min_weight: float = LOCK_MIN_WEIGHT,
        amp: str | None = None,
        scene: Any = None,
        terminate_on_collision: bool = False,
        observe_scene: bool = True,
        height_grid: int = 0,
        height_grid_spacing: float = HEIGHT_GRID_SPACING_M,
        route: float | None = None,
    ):
        require(int(num_envs) >= 1, "num_envs", f"must be >= 1, got {num_envs}")
        require(int(max_episode_steps) >= 1, "max_episode_steps", f"must be >= 1, got {max_episode_steps}")
        require(nonfinite_actions in ("error", "zero"), "nonfinite_actions",
                f"expected 'error' or 'zero', got {nonfinite_actions!r}")
        # how this env steps the motion; the attributes of the same names are copies for the step's hot path
        self.step_settings = StepSettings(float(guidance_scale), float(action_bound), bool(foot_lock),
                                          float(foot_lock_min_weight), amp)
        self.step_settings.validate()
        require(render_mode is None, "render_mode", "these envs do not render; export_history() + latentrl.render")
        for name, value in (
            ("obs_goal_dist_clip", obs_goal_dist_clip),
            ("success_threshold", success_threshold),
            ("terminate_distance", terminate_distance),
            ("divergence_limit", divergence_limit),
        ):
            require(value > 0, name, f"must be > 0, got {value}")
        self.num_envs = int(num_envs)
        self.device = torch.device(device)
        self.motion = load_prior(motion, self.device)
        self.step_settings.set_autocast(self.motion)
        self.guidance_scale, self.action_bound, self.foot_lock, self.foot_lock_min_weight, self.amp = (
            self.step_settings.guidance_scale, self.step_settings.action_bound, self.step_settings.foot_lock,
            self.step_settings.foot_lock_min_weight, self.step_settings.amp)
        self.max_episode_steps = int(max_episode_steps)
        self.autoreset_mode = autoreset_mode_of(autoreset_mode)
        self.nonfinite_actions = nonfinite_actions
        self.obs_goal_angle_clip_deg = float(obs_goal_angle_clip_deg)
        self.obs_goal_dist_clip = float(obs_goal_dist_clip)
        self.floor_height = float(floor_height)
        self.success_threshold, self.terminate_distance = float(success_threshold), float(terminate_distance)
        self.divergence_limit = float(divergence_limit)
        self.random_initial_steps = bool(random_initial_steps)
        self.render_mode = None
        self.compiled = bool(compile)
        if self.compiled:
            self.motion.prepare_compile()  # no cache fill inside the graph (it would recompile it)
        self._core = compile_step_core(self._motion_core, self.device) if self.compiled else self._motion_core
        self.scene = env_scene(scene, self.num_envs, self.device, self.floor_height)
        if self.scene is not None and self.scene.courses:
            require(type(self).walks_courses, "scene", f"{self.scene.spec.kind}: the env walks each course's route, "
                    f"which only the path task does (got {type(self).__name__})")
        self.terminate_on_collision = bool(terminate_on_collision)
        self.observe_scene = self.scene is not None and bool(observe_scene)
        require(self.scene is not None or not self.terminate_on_collision, "terminate_on_collision",
                "needs a scene")
        problem = height_grid_problem(height_grid, height_grid_spacing)
        if problem is not None:
            raise ConfigError(problem)
        require(self.scene is not None or not height_grid, "height_grid", "needs a scene")
        self.height_grid = int(height_grid) if self.observe_scene else 0
        self.height_grid_spacing = float(height_grid_spacing)
        self._grid_offsets = grid_offsets(self.height_grid, self.height_grid_spacing, self.device) \
            if self.height_grid else None
        self.rewards = RewardComposer(reward_config, reward_weights,
                                      terms=self.reward_terms + (SCENE_TERMS if self.scene is not None else ()))
        if isinstance(texts, str):
            texts = (texts,)
        self.text_table = TextTable(self.motion, self.rewards, tuple(texts), text_weights,
                                    self._all_texts(tuple(texts)), self.device)
        self.texts: tuple[str, ...] = self.text_table.texts
        self._feature_range = feature_range(self.motion)  # None: the prior declares no mean/std
        self._setup_spaces()
        require(route is None or self.scene is not None, "route", "needs a scene")
        self.route = None if route is None else RouteSettings(clearance=float(route))
        self.guide = RouteGuide(self, self.route) if self.route is not None else None
        """The :class:`~latentrl.envs.guide.RouteGuide` that rewrites the goal observation (None without ``route``)."""
        self._generator = torch.Generator(device=self.device)
        self._history = HistoryRecorder(self.num_envs, self.motion.latent_dim, record_features) if record_history \
            else None
        self._state: RolloutState | None = None
        n, dev = self.num_envs, self.device
        self._text_idx = torch.zeros(n, dtype=torch.long, device=dev)
        self._steps = torch.zeros(n, dtype=torch.int32, device=dev)
        self._ep_len = torch.zeros(n, dtype=torch.int32, device=dev)
        self._ep_return = torch.zeros(n, dtype=torch.float32, device=dev)
        self._ep_goals = torch.zeros(n, dtype=torch.int32, device=dev)
        self._all = torch.ones(n, dtype=torch.bool, device=dev)

    # ------------------------------------------------------------------ construction
    def _setup_spaces(self) -> None:
        self._obs = ObservationLayout(self.goal_fields, self.text_table.dim,
                                      self.scene.num_rays if self.observe_scene else 0, self.height_grid ** 2,
                                      self.task_group)
        bound, latent = self.step_settings.action_bound, self.motion.latent_dim
        self.single_action_space = gym.spaces.Box(-bound, bound, (latent,), np.float32)
        self.single_observation_space = gym.spaces.Box(-np.inf, np.inf, (self._obs.size,), np.float32)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.metadata = {
            **type(self).metadata,
            "autoreset_mode": self.autoreset_mode,
            "observation_layout": OrderedDict((k, list(v)) for k, v in self._obs.groups.items()),
            "observation_fields": OrderedDict((k, list(v)) for k, v in self._obs.fields.items()),
        }

    @property
    def observation_layout(self) -> OrderedDict[str, tuple[int, int]]:
        """Group name -> ``[start, stop)`` in the observation vector: goal, text, motion, scene.

        Trainers split observations only through this (also in ``metadata["observation_layout"]``).
        """
        return OrderedDict(self._obs.groups)

    @property
    def observation_fields(self) -> OrderedDict[str, tuple[int, int]]:
        """Field name -> ``[start, stop)``: goal_dir, goal_dist, [next_goal_*,] text, motion, scene."""
        return OrderedDict(self._obs.fields)

    def history_world(self, idx: torch.Tensor | None = None) -> torch.Tensor:
        """(N or M, 2, 22, 3) world joints of the current history (optionally of envs ``idx``)."""
        state = self._require_state()
        history, world = state.history, state.world
        if idx is not None:
            history, world = history[idx], world.index(idx)
        return world.apply(joints_of(history))

    def set_history(self, features_world: torch.Tensor) -> None:
        """Replace every env's history with (N, 2, 276) world features, canonicalized as a step's would be.

        For executing primitives outside the motion model (``latentrl eval --physics``: the simulated frames
        become the next history, so the policy acts on what physics did). Recorded episodes keep the planned frames.
        """
        state = self._require_state()
        feats = torch.as_tensor(features_world, dtype=state.history.dtype, device=self.device)
        require(tuple(feats.shape) == tuple(state.history.shape), "features_world",
                f"expected shape {tuple(state.history.shape)}, got {tuple(feats.shape)}")
        history, world = world_to_canonical(feats, self.motion.pelvis_delta)
        self._state = RolloutState(history, world, torch.zeros(self.num_envs, dtype=torch.bool, device=self.device))

    # ------------------------------------------------------------------ reset
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None
              ) -> tuple[torch.Tensor, dict[str, Any]]:
        """Reset all envs, or those in ``options["reset_mask"]`` ((N,) bool, numpy or torch).

        ``seed`` re-seeds the env's device generator (goals, texts, seed histories), so equal
        seeds and equal actions give equal observations.
        """
        options = dict(options or {})
        check_reset(seed, options)
        first = self._state is None
        super().reset(seed=seed)
        if seed is not None:
            self._generator.manual_seed(int(seed))
        elif first:
            self._generator.manual_seed(int(self.np_random.integers(2**62)))
        mask = options.get("reset_mask")
        if mask is None:
            idx = torch.arange(self.num_envs, device=self.device)
        else:
            if first:
                raise ValueError("call reset() without a reset_mask first: no env has a state yet")
            idx = mask_to_index(mask, self.num_envs, self.device)
        with torch.no_grad():
            self._reset_envs(idx, randomize_steps=mask is None and self.random_initial_steps)
            obs = self._observe()
        return obs, {}

    def _reset_envs(self, idx: torch.Tensor, randomize_steps: bool = False) -> None:
        """Fresh seed history, text, goal and counters for envs ``idx``; others are untouched."""
        fresh = self.motion.initial_state(len(idx), generator=self._generator)
        if self._state is None or len(idx) == self.num_envs:
            self._state = fresh
        else:
            self._state = replace_rows(self._state, idx, fresh)
        if randomize_steps:
            start = torch.randint(self.max_episode_steps, (len(idx),), generator=self._generator, device=self.device)
            self._steps[idx] = start.to(torch.int32)
        else:
            self._steps[idx] = 0
        self._ep_len[idx] = 0
        self._ep_return[idx] = 0.0
        self._ep_goals[idx] = 0
        self._reset_task(idx)
        if self.scene is not None:
            self.scene.reset(idx, self.history_world(idx), self.goal_world[idx], self._generator)
        if self._history is not None:
            self._history.on_reset(idx, self.history_world(idx), self._text_idx[idx], self._history_features(idx))

    # ------------------------------------------------------------------ step
    def step(self, actions: torch.Tensor | np.ndarray
             ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, dict[str, Any]]:
        """Advance every env by one primitive (8 frames) with ``actions`` (N, D) as latent noise.

        Returns ``(obs (N, obs_dim) float32, reward (N,) float32, terminated (N,) bool,
        truncated (N,) bool, infos)`` on ``device``.
        """
        state = self._require_state()
        # no_grad rather than inference_mode (the model samples under no_grad too, which torch.compile needs):
        # what we return must be ordinary tensors that a trainer may feed to autograd
        # (inference tensors cannot be saved for backward).
        with torch.no_grad():
            noise, nonfinite = self._prepare_actions(actions)
            goal = self.goal_world.clone()
            out, future, reached, diverged, reward, terms, new_state = self._core(state, self._text_idx, noise, goal)
            if self._history is not None:
                feats = None
                if self._history.record_features:
                    feats = features_to_world(out.future, out.placement, self.motion.pelvis_delta)
                self._history.on_step(future, noise, self._text_idx, goal, feats)
            self._state = new_state
            return self._finish_step(reward, terms, reached, diverged, nonfinite, future, goal)

    def _motion_core(
        self, state: RolloutState, text_idx: torch.Tensor, noise: torch.Tensor, goal: torch.Tensor
    ) -> tuple:
        """The tensor maths of a step: sample, decode and place the primitive, divergence, rewards.

        Pure tensor code with no host syncs, so that ``compile=True`` runs it as one
        ``torch.compile(fullgraph=True)`` graph (tests/envs/test_compiled_step.py checks there is no
        graph break); counters, task updates, infos and autoreset stay in :meth:`_finish_step`.
        Returns ``(step, future, reached, diverged, reward, terms, next_state)``.
        """
        out = self.motion.rollout_step(
            state, self.text_table.embeddings[text_idx], noise.view(self.num_envs, *self.motion.latent_shape),
            self.guidance_scale,
            # priors without a lock keep working unlocked
            **({"foot_lock": True, "lock_min_weight": self.foot_lock_min_weight} if self.foot_lock else {}),
            **({"terrain": self.scene.batch} if self.scene is not None else {}),  # stairs and box tops carry the body
        )
        diverged = diverged_envs(out.joints_world, out.state, self.divergence_limit, self.floor_height,
                                 self._feature_range)
        before = state.world.apply(joints_of(state.history))  # (N, 2, 22, 3)
        future = torch.where(diverged[:, None, None, None], before[:, -1:], out.joints_world)
        reached = self._reached(future, goal) & ~diverged
        reward, terms = self.rewards(RewardInputs(
            torch.cat((before, future), 1), goal, reached, self.text_table.floor_scale[text_idx], self.floor_height,
            actions=noise, skill=self.text_table.skill_code[text_idx],
            scene=self.scene.batch if self.scene is not None else None,
            **self._reward_inputs(before, future, goal, reached)))
        reward = torch.where(diverged, 0.0, reward)
        terms = {k: torch.where(diverged, 0.0, v) for k, v in terms.items()}
        return out, future, reached, diverged, reward, terms, keep_finite(out.state, state, diverged)

    def _finish_step(self, reward: torch.Tensor, terms: dict[str, torch.Tensor], reached: torch.Tensor,
                     diverged: torch.Tensor, nonfinite: torch.Tensor, future: torch.Tensor, goal: torch.Tensor
                     ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, dict[str, Any]]:
        """Counters, task update, terminations, infos and SAME_STEP autoreset (after the motion moved)."""
        self._steps += 1
        self._ep_len += 1
        self._ep_return += reward
        self._ep_goals += reached.to(torch.int32)
        far = torch.linalg.vector_norm(future[:, -1, PELVIS, :2] - goal[:, :2], dim=-1) > self.terminate_distance
        task_done, success = self._advance_task(reached)
        terminated = task_done | far | diverged
        if self.scene is not None:
            self.scene.clear_goals(self.goal_world)
            if self.terminate_on_collision:
                terminated = terminated | (terms["collision"] < 0)
        truncated = self._steps >= self.max_episode_steps
        done = terminated | truncated
        obs = self._observe()
        infos = step_infos(terms, success, diverged, nonfinite, self._all)
        self._task_infos(infos, reached)
        if bool(done.any()):
            infos["episode"] = {
                "r": torch.where(done, self._ep_return, 0.0),
                "l": torch.where(done, self._ep_len, 0),
                "goals": torch.where(done, self._ep_goals, 0),
            }
            infos["_episode"] = done
            if self.autoreset_mode == AutoresetMode.SAME_STEP:
                infos["final_obs"] = obs
                infos["_final_obs"] = done
                self._reset_envs(done.nonzero()[:, 0])
                obs = self._observe()
        return obs, reward, terminated, truncated, infos

    def _prepare_actions(self, actions: torch.Tensor | np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        """(N, D) checked, clamped float32 actions and the (N,) non-finite mask (:func:`prepare_actions`)."""
        return prepare_actions(actions, self.num_envs, self.motion.latent_dim, self.action_bound,
                               self.nonfinite_actions, self.device)

    def _reached(self, future: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """(N,) min over the new frames of the pelvis xy distance to the goal < ``success_threshold``."""
        dist = torch.linalg.vector_norm(future[:, :, PELVIS, :2] - goal[:, None, :2], dim=-1)
        return dist.amin(dim=1) < self.success_threshold

    # ------------------------------------------------------------------ observation
    def _observe(self) -> torch.Tensor:
        """(N, obs_dim) float32: [goal | text | motion | scene] (see :attr:`observation_layout`)."""
        state = self._require_state()
        history_world = state.world.apply(joints_of(state.history))
        obs = observe(state.history, history_world, self._goal_observation(history_world),
                      self.text_table.embeddings[self._text_idx], self.floor_height,
                      self.scene.rays(history_world) if self.observe_scene else None,
                      self.scene.height_grid(history_world, self._grid_offsets) if self.height_grid else None)
        return obs if self.guide is None else self.guide.observe(obs, history_world)

    def _goal_features(self, history_world: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """(N, 4) :func:`goal_features` of ``goal`` with this env's clips."""
        return goal_features(history_world[:, -1], self._state.world.rotation, goal, self.obs_goal_angle_clip_deg,
                             self.obs_goal_dist_clip)

    def goal_features_of(self, goal: torch.Tensor, history_world: torch.Tensor | None = None) -> torch.Tensor:
        """(N, 4) the ``goal_dir`` and ``goal_dist`` fields this env would observe for (N, 3) world ``goal``s.

        Why: a route guide (:mod:`latentrl.envs.guide`) shows a policy a waypoint of its route in place of the
        task's goal, in exactly the form the policy was trained on. ``history_world``: :meth:`history_world`, when
        the caller holds it already.
        """
        with torch.no_grad():
            return self._goal_features(self.history_world() if history_world is None else history_world, goal)

    route_target_moves = False
    """Whether :meth:`route_target` moves with the body (a joystick's), so a route guide replans only when it has
    moved a cell's worth rather than at every change."""

    def route_target(self, history_world: torch.Tensor) -> torch.Tensor:
        """(N, 3) where a route guide (:mod:`latentrl.envs.guide`) plans each env's route to: the task's goal."""
        return self.goal_world

    def routed_observation(self, obs: torch.Tensor, rows: torch.Tensor, seen: torch.Tensor,
                           history_world: torch.Tensor) -> torch.Tensor:
        """``obs`` whose ``rows`` observe the world points ``seen`` (N, 3) as their goal (``goal_dir``, ``goal_dist``).

        A route guide's hook: a task whose goal is elsewhere in its observation overrides it (the joystick's
        command direction).
        """
        fields = self.observation_fields
        a, b = fields["goal_dir"][0], fields["goal_dist"][1]
        feats = self.goal_features_of(seen.to(self.goal_world.device, self.goal_world.dtype), history_world)
        out = torch.as_tensor(obs).clone()
        out[rows, a:b] = feats[rows].to(out.device, out.dtype)
        return out

    @classmethod
    def routable(cls) -> bool:
        """Whether a route guide can lead this task: it observes a goal on the floor (reach, path, timed)."""
        return hasattr(cls, "goal_world") and {"goal_dir", "goal_dist"} <= {name for name, _ in cls.goal_fields}

    def step_inputs(self) -> dict[str, Any]:
        """What the next :meth:`step` feeds the motion model besides the noise.

        Keyword arguments of :meth:`MotionModel.differentiable_step` (``post_process=True``): a planner that
        predicts the step outside the env (``latentrl.optim.refine``) places it exactly as the env will.
        """
        lock = bool(self.foot_lock)  # as _motion_core: the env's lock, else the model's own setting (None)
        return {"state": self._require_state(), "text_embedding": self.text_table.embeddings[self._text_idx],
                "guidance_scale": self.guidance_scale, "foot_lock": True if lock else None,
                "lock_min_weight": self.foot_lock_min_weight if lock else LOCK_MIN_WEIGHT,
                "terrain": self.scene.batch if self.scene is not None else None}

    def _require_state(self) -> RolloutState:
        if self._state is None:
            raise RuntimeError("call reset() before step() (or before reading the env state)")
        return self._state

    def observation(self) -> torch.Tensor:
        """(N, obs_dim) observation of the current state (what the last reset or step returned)."""
        self._require_state()
        with torch.no_grad():
            return self._observe()

    # ------------------------------------------------------------------ resume
    def get_rng_state(self) -> dict[str, Any]:
        """The generator and every episode tensor, which checkpoints store to resume (:func:`snapshot`)."""
        return snapshot(self)

    def set_rng_state(self, state: Mapping[str, Any]) -> None:
        """Inverse of :meth:`get_rng_state`; episode tensors are restored only if their shapes still fit."""
        restore(self, state)
