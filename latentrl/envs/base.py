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

import os
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
from latentrl.envs.goal import goal_features
from latentrl.envs.history import HistoryRecorder
from latentrl.envs.settings import StepSettings
from latentrl.errors import ConfigError, NonFiniteError, closest
from latentrl.motion.canonical import WorldTransform, features_to_world
from latentrl.motion.clip import MotionClip
from latentrl.motion.prior import MotionPrior
from latentrl.motion.representation import FEATURE_DIM, HISTORY_LENGTH, joints_of
from latentrl.motion.rollout import AMP_DTYPES, LOCK_MIN_WEIGHT, RolloutState
from latentrl.motion.skeleton import PELVIS
from latentrl.motion.text import prompt_problem
from latentrl.rewards.compose import COMMON_TERMS, DART_TERMS, RewardComposer, RewardConfig, RewardInputs

_AUTORESET_MODES = {AutoresetMode.SAME_STEP, AutoresetMode.DISABLED}
_RESET_OPTIONS = ("reset_mask",)


def _autoreset_mode(value: AutoresetMode | str) -> AutoresetMode:
    try:
        mode = value if isinstance(value, AutoresetMode) else AutoresetMode(value)
    except ValueError:
        names = [m.value for m in _AUTORESET_MODES]
        raise ConfigError(f"autoreset_mode: unknown mode {value!r}; expected one of {names}") from None
    require(
        mode in _AUTORESET_MODES,
        "autoreset_mode",
        f"{mode.value} is not supported; use SameStep (default) or Disabled with reset(options={{'reset_mask': ...}})",
    )
    return mode


DIVERGENCE_DEPTH_M = 1.0
"""A joint this far under the floor means the motion diverged (feet dip a few centimetres at most)."""
DIVERGENCE_SIGMAS = 1000.0
"""A history feature this many of the data's standard deviations from its mean means the motion diverged."""


class LatentMotionVectorEnv(VectorEnv):
    """Batched envs whose action is the initial DDIM noise of a frozen motion model.

    Subclasses implement the goal: :meth:`_reset_task`, :attr:`goal_world`,
    :meth:`_goal_observation` and :meth:`_advance_task`, and name its fields in :attr:`goal_fields`.
    See ``docs/envs.md`` for every argument, observation field, reward term and info key.

    Args:
        num_envs: N, environments stepped together.
        motion: ``"default"`` (the embedded model), a model path, or a loaded
            :class:`~latentrl.motion.MotionPrior` such as :class:`~latentrl.motion.MotionModel` (moved to
            ``device`` in place).
        texts: prompts an episode's text is drawn from (encoded once, at construction).
        text_weights: (K,) sampling weights of ``texts``; ``None`` = uniform.
        device: where state, model and outputs live.
        max_episode_steps: steps (primitives of 8 frames) before truncation (DART 32).
        autoreset_mode: ``SAME_STEP`` (default) or ``DISABLED`` (reset with ``reset_mask``).
        action_bound: actions are clamped to ``[-action_bound, action_bound]`` (DART's 4 tanh bound).
        guidance_scale: classifier-free guidance weight of the sampler (DART 5).
        nonfinite_actions: ``"error"`` raises :class:`~latentrl.errors.NonFiniteError` naming the
            envs; ``"zero"`` replaces those rows with 0 and reports ``infos["nonfinite_action"]``.
        obs_goal_angle_clip_deg: goal-direction cone half-width, degrees (DART 60).
        obs_goal_dist_clip: goal-distance clip, metres (DART 5).
        floor_height: world z of the floor, metres (rewards and the ``scene`` observation).
        success_threshold: a goal is reached when the pelvis comes closer (xy) than this during
            a step, metres (DART 0.3).
        terminate_distance: terminate when the pelvis is farther (xy) than this from the goal, metres
            (DART's ``terminate_threshold``, 100).
        divergence_limit: terminate envs whose motion has a non-finite value or a joint
            coordinate beyond this, metres; their state is frozen, their reward 0. An env also
            diverges when a joint sinks more than :data:`DIVERGENCE_DEPTH_M` under the floor or a
            history feature leaves the motion data's range by more than :data:`DIVERGENCE_SIGMAS`
            standard deviations (the model's normalizer).
        random_initial_steps: start the episode counters of a full reset uniformly in
            ``[0, max_episode_steps)`` so truncations do not synchronize.
        reward_weights: per-term weight overrides (names in :data:`latentrl.rewards.TERM_NAMES`).
        reward_config: thresholds and weights (:class:`~latentrl.rewards.RewardConfig`).
        record_history: keep every step's world joints, actions, texts and goals for
            :meth:`export_history` (one device-to-host copy per step; clear it to bound memory).
        record_features: also record world-frame 276-D features (costs a transform per step).
        render_mode: only ``None``; render exported histories with :mod:`latentrl.render`.
        compile: run each step's tensor maths (:meth:`_motion_core`) as one
            ``torch.compile(fullgraph=True)`` graph, on CUDA captured as a CUDA graph
            (``mode="reduce-overhead"``, :mod:`latentrl.envs.compiled`; run on an H200 by tests/gpu/test_cuda.py);
            the first step compiles (tens of seconds).
        foot_lock: keep planted feet from sliding (:func:`latentrl.motion.rollout.lock_feet`): the body
            moves by its steps, not by sliding feet.
        foot_lock_min_weight: the summed contact weight from which the lock pins a foot fully (the
            lock's ``min_weight``; 0.5 as before, 0.05 pins any foot inside DART's 3 cm band).
        amp: sample the motion model under autocast in this dtype ('bf16'; on CUDA also 'fp16'); sets the
            model's ``amp_dtype`` (a model shared with other envs samples so there too). None: the model's own
            setting (float32 unless changed). Only the sampler and decoder run in it; the step's outputs stay float32.
    """

    metadata: dict[str, Any] = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}
    goal_fields: tuple[tuple[str, int], ...] = (("goal_dir", 3), ("goal_dist", 1))
    """Named fields of the ``goal`` observation group, in order; tasks may extend."""
    reward_terms: tuple[str, ...] = (*DART_TERMS, *COMMON_TERMS)
    """The reward terms this task computes and reports (``infos["reward/<name>"]``)."""

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
    ):
        require(int(num_envs) >= 1, "num_envs", f"must be >= 1, got {num_envs}")
        require(int(max_episode_steps) >= 1, "max_episode_steps", f"must be >= 1, got {max_episode_steps}")
        require(
            nonfinite_actions in ("error", "zero"),
            "nonfinite_actions",
            f"expected 'error' or 'zero', got {nonfinite_actions!r}",
        )
        # how this env steps the motion; the attributes set below are copies for the step's hot path
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
        self.motion = self._load_motion(motion)
        self.amp = amp
        if amp is not None:
            if not hasattr(self.motion, "amp_dtype"):
                raise ConfigError(f"amp: the motion model ({type(self.motion).__name__}) has no amp_dtype to set")
            self.motion.amp_dtype = AMP_DTYPES[amp]
        self.max_episode_steps = int(max_episode_steps)
        self.autoreset_mode = _autoreset_mode(autoreset_mode)
        self.action_bound = float(action_bound)
        self.guidance_scale = float(guidance_scale)
        self.nonfinite_actions = nonfinite_actions
        self.obs_goal_angle_clip_deg = float(obs_goal_angle_clip_deg)
        self.obs_goal_dist_clip = float(obs_goal_dist_clip)
        self.floor_height = float(floor_height)
        self.success_threshold = float(success_threshold)
        self.terminate_distance = float(terminate_distance)
        self.divergence_limit = float(divergence_limit)
        self.random_initial_steps = bool(random_initial_steps)
        self.render_mode = None
        self.foot_lock = bool(foot_lock)
        self.foot_lock_min_weight = float(foot_lock_min_weight)
        self.compiled = bool(compile)
        if self.compiled:
            self.motion.prepare_compile()  # no cache fill inside the graph (it would recompile it)
        self._core = compile_step_core(self._motion_core, self.device) if self.compiled else self._motion_core
        self.rewards = RewardComposer(reward_config, reward_weights, terms=self.reward_terms)
        self._setup_texts(texts, text_weights)
        self._setup_spaces()
        self._generator = torch.Generator(device=self.device)
        self._history = (
            HistoryRecorder(self.num_envs, self.motion.latent_dim, record_features) if record_history else None
        )
        self._state: RolloutState | None = None
        n, dev = self.num_envs, self.device
        self._text_idx = torch.zeros(n, dtype=torch.long, device=dev)
        self._steps = torch.zeros(n, dtype=torch.int32, device=dev)
        self._ep_len = torch.zeros(n, dtype=torch.int32, device=dev)
        self._ep_return = torch.zeros(n, dtype=torch.float32, device=dev)
        self._ep_goals = torch.zeros(n, dtype=torch.int32, device=dev)
        self._all = torch.ones(n, dtype=torch.bool, device=dev)

    # ------------------------------------------------------------------ construction
    def _load_motion(self, motion: str | MotionPrior) -> MotionPrior:
        if not isinstance(motion, (str, os.PathLike)):
            model = motion.to(self.device)
        else:
            from latentrl.motion.checkpoint import load_motion_model

            model = load_motion_model(motion, device=self.device)
        if model.seed_history is None or model.pelvis_delta is None:
            raise ConfigError(
                "motion: the model has no seed history/pelvis_delta, so episodes cannot start; "
                "load it with seed_history=... (docs/motion.md)"
            )
        return model

    def _setup_texts(self, texts: Sequence[str], text_weights: Sequence[float] | None) -> None:
        """Encode the prompt list once: (K, E) table, (K,) sampling weights and floor scales."""
        if isinstance(texts, str):
            texts = (texts,)
        self.texts: tuple[str, ...] = tuple(dict.fromkeys(self._all_texts(tuple(texts))))
        require(len(self.texts) > 0, "texts", "give at least one prompt")
        for text in self.texts:
            require(prompt_problem(text) is None, "texts", str(prompt_problem(text)))
        self._text_emb = self.motion.encode_text(list(self.texts)).to(self.device, torch.float32)
        self._floor_scale = self.rewards.floor_scales(self.texts).to(self.device)
        self._skill_code = self.rewards.skill_codes(self.texts).to(self.device)
        self._sample_texts_from = torch.tensor([self.texts.index(t) for t in texts], device=self.device)
        if text_weights is None:
            self._text_weights = torch.ones(len(texts), device=self.device)
        else:
            w = torch.as_tensor(np.asarray(text_weights, dtype=np.float32), device=self.device)
            require(
                w.shape == (len(texts),), "text_weights", f"needs one weight per text ({len(texts)}), got {w.shape}"
            )
            require(
                bool(torch.isfinite(w).all() and (w >= 0).all() and w.sum() > 0),
                "text_weights",
                f"must be finite, >= 0 and not all 0, got {w.tolist()}",
            )
            self._text_weights = w

    def _all_texts(self, texts: tuple[str, ...]) -> tuple[str, ...]:
        """Every prompt the env may use; tasks with their own texts (paths) extend it."""
        return texts

    def _setup_spaces(self) -> None:
        latent = self.motion.latent_dim
        fields = (
            *self.goal_fields,
            ("text", self._text_emb.shape[1]),
            ("motion", HISTORY_LENGTH * FEATURE_DIM),
            ("scene", 1),
        )
        self._fields, start = OrderedDict(), 0
        for name, size in fields:
            self._fields[name] = (start, start + size)
            start += size
        goal_stop = self._fields[self.goal_fields[-1][0]][1]
        self._layout = OrderedDict(goal=(0, goal_stop), **{k: self._fields[k] for k in ("text", "motion", "scene")})
        self.single_action_space = gym.spaces.Box(-self.action_bound, self.action_bound, (latent,), np.float32)
        self.single_observation_space = gym.spaces.Box(-np.inf, np.inf, (start,), np.float32)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.metadata = {
            **type(self).metadata,
            "autoreset_mode": self.autoreset_mode,
            "observation_layout": OrderedDict((k, list(v)) for k, v in self._layout.items()),
            "observation_fields": OrderedDict((k, list(v)) for k, v in self._fields.items()),
        }

    @property
    def observation_layout(self) -> OrderedDict[str, tuple[int, int]]:
        """Group name -> ``[start, stop)`` in the observation vector: goal, text, motion, scene.

        Trainers split observations only through this (also in ``metadata["observation_layout"]``).
        """
        return OrderedDict(self._layout)

    @property
    def observation_fields(self) -> OrderedDict[str, tuple[int, int]]:
        """Field name -> ``[start, stop)``: goal_dir, goal_dist, [next_goal_*,] text, motion, scene."""
        return OrderedDict(self._fields)

    # ------------------------------------------------------------------ task hooks
    @property
    def goal_world(self) -> torch.Tensor:
        """(N, 3) the goal each env is heading to now, world metres."""
        raise NotImplementedError

    def _reset_task(self, idx: torch.Tensor) -> None:
        """Choose texts and goals for envs ``idx`` ((M,) long) whose motion state was just reset."""
        raise NotImplementedError

    def _goal_observation(self, history_world: torch.Tensor) -> torch.Tensor:
        """(N, 2, 22, 3) world joints of the history -> (N, G) goal observation (:attr:`goal_fields`)."""
        raise NotImplementedError

    def _advance_task(self, reached: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """React to (N,) reached goals after the motion state moved on.

        Returns ``(terminated, is_success)``, both (N,) bool: task terminations and the
        ``is_success`` info of this step.
        """
        raise NotImplementedError

    def _task_infos(self, infos: dict[str, Any], reached: torch.Tensor) -> None:
        """Add task-specific infos (batched, with ``_key`` masks); ``reached`` is the (N,) goal mask."""

    def _reward_inputs(
        self, before: torch.Tensor, future: torch.Tensor, goal: torch.Tensor, reached: torch.Tensor
    ) -> dict[str, torch.Tensor]:
        """Task fields of :class:`~latentrl.rewards.RewardInputs` for this step (``command``, ...); none here.

        Called before :meth:`_advance_task`, with the (N, 2, 22, 3) history before the step, the (N, 8, 22, 3)
        new frames, the (N, 3) goal in force and the (N,) reached mask.
        """
        return {}

    # ------------------------------------------------------------------ helpers for tasks
    def _sample_texts(self, count: int) -> torch.Tensor:
        """(count,) indices into :attr:`texts`, drawn with ``text_weights`` from the env generator."""
        pick = torch.multinomial(self._text_weights, count, replacement=True, generator=self._generator)
        return self._sample_texts_from[pick]

    def _uniform(self, count: int, low: float, high: float) -> torch.Tensor:
        """(count,) uniform samples in [low, high) from the env generator."""
        u = torch.rand(count, generator=self._generator, device=self.device)
        return low + (high - low) * u

    def history_world(self, idx: torch.Tensor | None = None) -> torch.Tensor:
        """(N or M, 2, 22, 3) world joints of the current history (optionally of envs ``idx``)."""
        state = self._require_state()
        history, world = state.history, state.world
        if idx is not None:
            history, world = history[idx], world.index(idx)
        return world.apply(joints_of(history))

    # ------------------------------------------------------------------ reset
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[torch.Tensor, dict[str, Any]]:
        """Reset all envs, or those in ``options["reset_mask"]`` ((N,) bool, numpy or torch).

        ``seed`` re-seeds the env's device generator (goals, texts, seed histories), so equal
        seeds and equal actions give equal observations.
        """
        options = dict(options or {})
        for key in options:
            if key not in _RESET_OPTIONS:
                raise ValueError(f"unknown reset option '{key}'{closest(key, _RESET_OPTIONS)}; known: {_RESET_OPTIONS}")
        if seed is not None and not isinstance(seed, (int, np.integer)):
            raise TypeError(f"seed must be one int for the whole batch (it seeds one device generator), got {seed!r}")
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
            idx = self._mask_to_index(mask)
        with torch.no_grad():
            self._reset_envs(idx, randomize_steps=mask is None and self.random_initial_steps)
            obs = self._observe()
        return obs, {}

    def _mask_to_index(self, mask: Any) -> torch.Tensor:
        mask = torch.as_tensor(mask, device=self.device)
        if mask.dtype != torch.bool or mask.shape != (self.num_envs,):
            raise ValueError(
                f"reset_mask must be a bool array of shape ({self.num_envs},), got {mask.dtype} {tuple(mask.shape)}"
            )
        if not bool(mask.any()):
            raise ValueError("reset_mask must select at least one env")
        return mask.nonzero()[:, 0]

    def _reset_envs(self, idx: torch.Tensor, randomize_steps: bool = False) -> None:
        """Fresh seed history, text, goal and counters for envs ``idx``; others are untouched."""
        fresh = self.motion.initial_state(len(idx), generator=self._generator)
        if self._state is None or len(idx) == self.num_envs:
            self._state = fresh
        else:
            s = self._state
            self._state = RolloutState(
                s.history.index_copy(0, idx, fresh.history),
                WorldTransform(
                    s.world.rotation.index_copy(0, idx, fresh.world.rotation),
                    s.world.translation.index_copy(0, idx, fresh.world.translation),
                ),
                s.airborne_flags().index_copy(0, idx, fresh.airborne_flags()),
            )
        if randomize_steps:
            start = torch.randint(self.max_episode_steps, (len(idx),), generator=self._generator, device=self.device)
            self._steps[idx] = start.to(torch.int32)
        else:
            self._steps[idx] = 0
        self._ep_len[idx] = 0
        self._ep_return[idx] = 0.0
        self._ep_goals[idx] = 0
        self._reset_task(idx)
        if self._history is not None:
            self._history.on_reset(idx, self.history_world(idx), self._text_idx[idx], self._history_features(idx))

    def _history_features(self, idx: torch.Tensor) -> torch.Tensor | None:
        """(M, 2, 276) world features of the current history of envs ``idx``, if they are recorded."""
        if self._history is None or not self._history.record_features:
            return None
        s = self._state
        return features_to_world(s.history[idx], s.world.index(idx), self.motion.pelvis_delta)

    # ------------------------------------------------------------------ step
    def step(
        self, actions: torch.Tensor | np.ndarray
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
            state, self._text_emb[text_idx], noise.view(self.num_envs, *self.motion.latent_shape), self.guidance_scale,
            # priors without a lock keep working unlocked
            **({"foot_lock": True, "lock_min_weight": self.foot_lock_min_weight} if self.foot_lock else {}),
        )
        diverged = self._diverged(out.joints_world, out.state)
        before = state.world.apply(joints_of(state.history))  # (N, 2, 22, 3)
        future = torch.where(diverged[:, None, None, None], before[:, -1:], out.joints_world)
        reached = self._reached(future, goal) & ~diverged
        reward, terms = self.rewards(
            RewardInputs(
                torch.cat((before, future), 1),
                goal,
                reached,
                self._floor_scale[text_idx],
                self.floor_height,
                actions=noise,
                skill=self._skill_code[text_idx],
                **self._reward_inputs(before, future, goal, reached),
            )
        )
        reward = torch.where(diverged, 0.0, reward)
        terms = {k: torch.where(diverged, 0.0, v) for k, v in terms.items()}
        return out, future, reached, diverged, reward, terms, self._keep_finite(out.state, state, diverged)

    def _finish_step(
        self,
        reward: torch.Tensor,
        terms: dict[str, torch.Tensor],
        reached: torch.Tensor,
        diverged: torch.Tensor,
        nonfinite: torch.Tensor,
        future: torch.Tensor,
        goal: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor, dict[str, Any]]:
        """Counters, task update, terminations, infos and SAME_STEP autoreset (after the motion moved)."""
        self._steps += 1
        self._ep_len += 1
        self._ep_return += reward
        self._ep_goals += reached.to(torch.int32)
        far = torch.linalg.vector_norm(future[:, -1, PELVIS, :2] - goal[:, :2], dim=-1) > self.terminate_distance
        task_done, success = self._advance_task(reached)
        terminated = task_done | far | diverged
        truncated = self._steps >= self.max_episode_steps
        done = terminated | truncated
        obs = self._observe()
        infos = self._step_infos(terms, success, diverged, nonfinite)
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

    def _step_infos(
        self, terms: dict[str, torch.Tensor], success: torch.Tensor, diverged: torch.Tensor, nonfinite: torch.Tensor
    ) -> dict[str, Any]:
        infos: dict[str, Any] = {}
        for name, value in terms.items():
            infos[f"reward/{name}"] = value
            infos[f"_reward/{name}"] = self._all
        infos["is_success"] = success
        infos["diverged"] = diverged
        infos["nonfinite_action"] = nonfinite
        for key in ("is_success", "diverged", "nonfinite_action"):
            infos[f"_{key}"] = self._all
        return infos

    def _prepare_actions(self, actions: torch.Tensor | np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        """Validate shape, handle non-finite rows, clamp; returns ((N, D) float32, (N,) non-finite mask)."""
        d = self.motion.latent_dim
        actions = torch.as_tensor(actions, dtype=torch.float32, device=self.device)
        if actions.shape != (self.num_envs, d):
            raise ValueError(
                f"actions must have shape (num_envs, D) = ({self.num_envs}, {d}), got {tuple(actions.shape)}"
            )
        nonfinite = ~torch.isfinite(actions).all(dim=1)
        if bool(nonfinite.any()):
            if self.nonfinite_actions == "error":
                bad = nonfinite.nonzero()[:, 0].tolist()
                raise NonFiniteError(
                    f"actions of envs {bad[:20]} contain NaN or inf; pass finite actions or build the env with "
                    "nonfinite_actions='zero' to replace them by 0"
                )
            actions = torch.where(nonfinite[:, None], 0.0, actions)
        return actions.clamp(-self.action_bound, self.action_bound), nonfinite

    def _diverged(self, joints_world: torch.Tensor, new_state: RolloutState) -> torch.Tensor:
        """(N,) envs whose new frames or state are non-finite or beyond ``divergence_limit``."""
        ok = (joints_world.abs() <= self.divergence_limit).flatten(1).all(1)  # False for NaN as well
        ok &= (joints_world[..., 2] >= self.floor_height - DIVERGENCE_DEPTH_M).flatten(1).all(1)  # metres underground
        scaled = (new_state.history - self.motion.mean) / self.motion.std  # the motion data's range, per feature
        ok &= (scaled.abs() <= DIVERGENCE_SIGMAS).flatten(1).all(1)
        for value in (new_state.history, new_state.world.rotation, new_state.world.translation):
            ok &= torch.isfinite(value).flatten(1).all(1)
        return ~ok

    @staticmethod
    def _keep_finite(new: RolloutState, old: RolloutState, diverged: torch.Tensor) -> RolloutState:
        """The new state, except that diverged envs keep their old one (never NaN in observations)."""
        d = diverged[:, None, None]
        return RolloutState(
            torch.where(d, old.history, new.history),
            WorldTransform(
                torch.where(d, old.world.rotation, new.world.rotation),
                torch.where(diverged[:, None], old.world.translation, new.world.translation),
            ),
            torch.where(diverged, old.airborne_flags(), new.airborne_flags()),
        )

    def _reached(self, future: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """(N,) min over the new frames of the pelvis xy distance to the goal < ``success_threshold``."""
        dist = torch.linalg.vector_norm(future[:, :, PELVIS, :2] - goal[:, None, :2], dim=-1)
        return dist.amin(dim=1) < self.success_threshold

    # ------------------------------------------------------------------ observation
    def _observe(self) -> torch.Tensor:
        """(N, obs_dim) float32: [goal | text | motion | scene] (see :attr:`observation_layout`)."""
        state = self._require_state()
        history_world = state.world.apply(joints_of(state.history))
        scene = self.floor_height - history_world[:, 0, PELVIS, 2:3]
        return torch.cat(
            (
                self._goal_observation(history_world),
                self._text_emb[self._text_idx],
                state.history.reshape(self.num_envs, -1),
                scene,
            ),
            dim=1,
        )

    def _goal_features(self, history_world: torch.Tensor, goal: torch.Tensor) -> torch.Tensor:
        """(N, 4) :func:`goal_features` of ``goal`` with this env's clips."""
        return goal_features(
            history_world[:, -1],
            self._state.world.rotation,
            goal,
            self.obs_goal_angle_clip_deg,
            self.obs_goal_dist_clip,
        )

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
        """The env generator and every episode tensor (motion state, goals, texts, counters).

        Training checkpoints store it, so a resumed run continues the episodes it was in with the
        same random stream, and matches a run that was never interrupted.
        """
        state: dict[str, Any] = {"generator": self._generator.get_state()}
        if self._state is not None:
            tensors = {name: value.clone() for name, value in vars(self).items() if torch.is_tensor(value)}
            tensors.update({"state.history": self._state.history.clone(),
                            "state.world.rotation": self._state.world.rotation.clone(),
                            "state.world.translation": self._state.world.translation.clone(),
                            "state.airborne": self._state.airborne_flags().clone()})
            state["episode"] = tensors
        return state

    def set_rng_state(self, state: Mapping[str, Any]) -> None:
        """Inverse of :meth:`get_rng_state`; episode tensors are restored only if their shapes still fit."""
        self._generator.set_state(state["generator"].cpu())
        tensors = state.get("episode")
        if not tensors or tensors["state.history"].shape[0] != self.num_envs:
            return
        for name, value in tensors.items():
            current = getattr(self, name, None) if not name.startswith("state.") else None
            if torch.is_tensor(current) and current.shape == value.shape:
                setattr(self, name, value.to(current.device, current.dtype))
        self._state = RolloutState(
            tensors["state.history"].to(self.device),
            WorldTransform(tensors["state.world.rotation"].to(self.device),
                           tensors["state.world.translation"].to(self.device)),
            tensors["state.airborne"].to(self.device) if "state.airborne" in tensors else None,
        )

    # ------------------------------------------------------------------ history
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

    def close_extras(self, **kwargs: Any) -> None:
        self._history = None
