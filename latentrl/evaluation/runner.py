"""Run a policy over waypoint path files: DART's evaluation protocol, without hiding failures.

For each path of each file, ``episodes`` environments of :class:`~latentrl.envs.FollowPathEnv`
run in parallel on that same path (batch = episodes, DART's 32), with actions sampled from the
policy (DART samples; ``deterministic=True`` takes the mean). Each env stops counting at its final
waypoint (the env terminates it with ``is_success``); the batch stops when every env is done or the
step budget ``max_steps`` is spent. What we fix in DART's script (``reference/dart.md`` section 5):

- an episode that runs out of budget is a **failure** (DART only saved finished runs, so its
  success rate was 1.0 by construction); its reach time is the budget time (a censored value),
  and the mean over successful episodes only is reported beside it;
- divergence and losing the path (farther than ``terminate_distance``) are failures too.

What we keep: success is the pelvis within 0.3 m (xy) of the final waypoint at one of the 8 frames
of a step (DART's min over the last 8 frames of the saved sequence); reach time is
``num_frames / 30`` including the 2 seed frames; metrics are computed on the whole episode's world
joints, seed frames included. Each waypoint's segment is also checked against its text
(:mod:`~latentrl.evaluation.skills`).

The runner needs from the env package: ``FollowPathEnv(paths=[p], path_assignment="by_env",
autoreset_mode="Disabled", record_history=True, max_episode_steps=...)``, the infos
``waypoint_reached``, ``waypoint_index``, ``is_success``, ``diverged``, and ``export_history``.
From the policy it needs only a callable ``obs (N, D) -> actions (N, A)`` (:data:`PolicyFn`);
:func:`policy_fn` makes one from a PPO :class:`~latentrl.ppo.ActorCritic`.
"""

from __future__ import annotations

import time
import zlib
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch

from latentrl.envs.path import FollowPathEnv, WaypointPath, load_paths
from latentrl.envs.scene import resolve_scene
from latentrl.errors import CheckpointError
from latentrl.evaluation import metrics as M
from latentrl.evaluation.config import EvalSettings
from latentrl.evaluation.episodes import collect_returns, end_of, rollout
from latentrl.evaluation.results import EpisodeResult, PathResult, SuiteResult, frames_after
from latentrl.evaluation.skills import judge_clip
from latentrl.evaluation.video import recorder_for
from latentrl.motion.clip import MotionClip
from latentrl.motion.representation import FUTURE_LENGTH
from latentrl.motion.skeleton import FPS
from latentrl.scenes.contact import scene_metrics
from latentrl.scenes.courses import CoursePool
from latentrl.scenes.scene import Scene
from latentrl.scenes.spec import scene_to_json

__all__ = ["EpisodeResult", "EvalSettings", "PathResult", "SuiteResult", "frames_after", "policy_fn", "fit_policy",
           "make_env", "run_path", "run_suites", "load_suites", "training_eval_hook", "measure_speed"]

PolicyFn = Callable[[torch.Tensor], torch.Tensor]
"""The policy seam: observations (N, D) float32 on the env's device -> actions (N, A)."""

EpisodeSink = Callable[["EpisodeResult", dict], "str | None"]
"""Called once per finished episode with its result and its motion: the fields of its
:class:`~latentrl.motion.clip.MotionClip` (``MotionClip.to_dict()``: ``joints``, ``fps``, ``texts``,
``contacts``, ``floor``, ``primitive``, ``actions``, ``goals``) cut at the episode's end, with the path's
``waypoints`` (W, 3). Returns the file it wrote (stored in ``EpisodeResult.motion_file``) or None."""


# --------------------------------------------------------------------------- policy seam
def policy_fn(policy: torch.nn.Module, deterministic: bool = False) -> PolicyFn:
    """Wrap a PPO ``ActorCritic`` (anything with ``act(obs, deterministic) -> (action, ...)``) as a :data:`PolicyFn`.

    Sampling draws from torch's global generator, which :func:`run_path` seeds per path.
    """

    def act(obs: torch.Tensor) -> torch.Tensor:
        with torch.no_grad():
            return policy.act(obs, deterministic=deterministic).action

    return act


def check_policy_shapes(obs_dim: int, action_dim: int, env: FollowPathEnv) -> None:
    """Refuse a policy whose observation or action size does not fit the eval env, naming the fix."""
    env_obs, env_act = env.single_observation_space.shape[0], env.single_action_space.shape[0]
    if action_dim != env_act:
        raise CheckpointError(
            f"the policy outputs {action_dim}-D actions but the motion model's latent has {env_act} values; "
            "evaluate with the motion model the policy was trained on (--motion)"
        )
    if obs_dim != env_obs:
        raise CheckpointError(
            f"the policy expects {obs_dim}-D observations but FollowPath gives {env_obs} "
            f"(goal {env.observation_layout['goal']}); was it trained on another task layout or text encoder?"
        )


def fit_policy(obs_dim: int, action_dim: int, motion, settings: EvalSettings, observe_next: bool | None = None) -> bool:
    """Check that a policy fits the eval env and return whether the env must ``observe_next``.

    ``observe_next`` comes from the env config stored with the policy when there is one; otherwise it
    is recognised from the observation size: a FollowPath policy trained with ``observe_next`` has a
    goal group of 8 values instead of 4 (ReachLocation and plain FollowPath policies have 4).
    """
    probe = WaypointPath(((0.0, 1.0, 0.0),), ("walk",))
    if observe_next is None:
        env = make_env(motion, [probe], 1, settings, observe_next=False)
        observe_next = obs_dim == env.single_observation_space.shape[0] + 4
    env = make_env(motion, [probe], 1, settings, observe_next=observe_next)
    check_policy_shapes(obs_dim, action_dim, env)
    return observe_next


# --------------------------------------------------------------------------- running
def make_env(
    motion,
    paths: Sequence[WaypointPath],
    num_envs: int,
    settings: EvalSettings,
    observe_next: bool = False,
    record_history: bool = False,
    max_steps: int | None = None,
    record_features: bool = False,
) -> FollowPathEnv:
    """The evaluation env: env i follows path ``i % len(paths)``, no autoreset, DART's clips and thresholds.

    The scene is the first path's own (its ``scene`` field) when it has one, else ``settings.scene``; the policy
    observes it only if it was trained with a scene (``settings.scene`` set). Random mazes bring their own
    routes, so a suite's paths without a scene of their own run on the open floor.
    """
    scene = paths[0].scene if paths[0].scene is not None else (
        resolve_scene(settings.scene) if settings.scene is not None else None)
    if isinstance(scene, CoursePool):
        scene = Scene()
    return FollowPathEnv(
        num_envs,
        motion=motion,
        paths=list(paths),
        path_assignment="by_env",
        observe_next=observe_next,
        next_at_last=settings.next_at_last,
        texts=(paths[0].texts[0],),
        device=settings.device,
        max_episode_steps=max_steps or settings.max_steps,
        autoreset_mode="Disabled",
        success_threshold=settings.success_threshold,
        **settings.motion_kwargs(),
        record_history=record_history,
        record_features=record_features,
        **settings.scene_kwargs(scene),
    )


def path_seed(seed: int, suite: str, index: int) -> int:
    """A per-path seed that does not depend on which other files or paths are evaluated."""
    return (int(seed) * 1_000_003 + zlib.crc32(f"{suite}:{index}".encode())) % 2**31


def _rollout(env: FollowPathEnv, act: PolicyFn, max_steps: int, seed: int) -> dict[str, torch.Tensor]:
    """:func:`~latentrl.evaluation.episodes.rollout` of a path batch, also noting when each waypoint was reached.

    Returns ``steps`` (N,) primitives until done, ``success``/``diverged``/``lost`` (N,) bool and
    ``wp_step`` (N, W) the step at which each waypoint was reached (0 = never).
    """
    n, dev = env.num_envs, env.device
    wp_step = torch.zeros(n, max(len(p.waypoints) for p in env.paths), dtype=torch.long, device=dev)
    rows = torch.arange(n, device=dev)

    def note_waypoints(k: int, infos: dict, live: torch.Tensor) -> None:
        reached = infos["waypoint_reached"] & live
        wp = (infos["waypoint_index"] - 1).clamp(min=0)  # the index after advancing, minus the one reached
        wp_step[rows[reached], wp[reached]] = k

    outcome = rollout(env, act, max_steps, seed, on_step=note_waypoints)
    outcome["success"] = outcome.pop("complete")  # a path's completion is its success
    return {**outcome, "wp_step": wp_step.cpu()}


def _episode_motion(env: FollowPathEnv, i: int, steps: int) -> MotionClip:
    """Env i's recorded episode cut at its end (steps continue for finished envs in a batch)."""
    clip = env.export_clip(i, episode=0).cut(steps)
    clip.meta.pop("from_reset", None)
    return clip


def run_path(
    act: PolicyFn,
    motion,
    path: WaypointPath,
    settings: EvalSettings,
    *,
    suite: str = "paths",
    index: int = 0,
    observe_next: bool = False,
    sink: EpisodeSink | None = None,
    wrap: Callable[[Any, PolicyFn], PolicyFn] | None = None,
) -> PathResult:
    """Evaluate ``settings.episodes`` episodes of one path in one batch; see the module docstring.

    ``wrap(env, act) -> act``: a policy function that also reads the env (``eval --avoid``'s scene filter).
    """
    t0 = time.perf_counter()
    env = make_env(motion, [path], settings.episodes, settings, observe_next, record_history=True)
    outcome = _rollout(env, act if wrap is None else wrap(env, act), settings.max_steps,
                       path_seed(settings.seed, suite, index))
    final_goal = torch.tensor(path.waypoints[-1])
    episodes = []
    for i in range(settings.episodes):
        steps = int(outcome["steps"][i])
        motion_i = _episode_motion(env, i, steps)
        joints = torch.as_tensor(motion_i.joints)
        success = bool(outcome["success"][i])
        terrain = env.scene.row(i) if env.scene is not None else None
        wp_times = [frames_after(int(s)) / FPS if s > 0 else None for s in outcome["wp_step"][i, : len(path.waypoints)]]
        result = EpisodeResult(
            suite=suite,
            path_index=index,
            episode=i,
            success=success,
            end=end_of(outcome, i, complete="success"),
            steps=steps,
            reach_time_s=frames_after(steps) / FPS if success else settings.budget_s,
            waypoint_times_s=wp_times,
            final_dist_m=float(M.final_goal_distance_m(joints, final_goal)),
            metrics={**M.episode_metrics(joints, FPS, env.floor_height, terrain),
                     **(scene_metrics(joints, terrain) if terrain is not None else {})},
            pelvis_xy=joints[:, 0, :2].numpy().copy(),
            segments=judge_clip(motion_i, terrain),
        )
        if env.scene is not None:
            motion_i.scene = result.scene = scene_to_json(env.scene.scene_of(i))
        if sink is not None:
            motion_i.waypoints = np.asarray(path.waypoints, np.float32)
            result.motion_file = sink(result, motion_i.to_dict())
        episodes.append(result)
    env.close()
    return PathResult(suite, index, path, episodes, time.perf_counter() - t0)


def load_suites(files: Sequence[str | Path], text: str | None = None) -> list[tuple[Path, list[WaypointPath]]]:
    """Parse and check every path file (DART's JSON, :func:`latentrl.envs.load_paths`) before anything runs.

    ``text`` replaces every waypoint's text (e.g. evaluate a 'run' policy on DART's walk paths).
    """
    loaded = [(Path(f), load_paths(f)) for f in files]
    if text is not None:
        loaded = [(f, [WaypointPath(p.waypoints, (text,) * len(p.waypoints), scene=p.scene) for p in paths])
                  for f, paths in loaded]
    return loaded


def run_suites(
    act: PolicyFn,
    motion,
    files: Sequence[str | Path],
    settings: EvalSettings,
    *,
    observe_next: bool = False,
    text: str | None = None,
    sink: EpisodeSink | None = None,
    progress: Callable[[PathResult], None] | None = None,
    wrap: Callable[[Any, PolicyFn], PolicyFn] | None = None,
) -> list[SuiteResult]:
    """Every path of every file, in order (all files are checked first, see :func:`load_suites`)."""
    settings.validate()
    results = []
    for file, paths in load_suites(files, text):
        suite = SuiteResult(file.stem, str(file), [])
        for index, path in enumerate(paths):
            result = run_path(act, motion, path, settings, suite=file.stem, index=index,
                              observe_next=observe_next, sink=sink, wrap=wrap)
            suite.paths.append(result)
            if progress is not None:
                progress(result)
        results.append(suite)
    return results


def training_eval_hook(files: Sequence[str | Path], motion, env_cfg: Any, eval_cfg: Any, device: str = "cpu"):
    """The trainer's periodic evaluation (``ppo.eval_every``): ``policy -> EvalReport``.

    Runs ``eval_cfg.paths``' suites (already resolved to ``files``) with ``eval_cfg.episodes``,
    ``max_steps``, ``deterministic`` and ``text``, and returns the overall DART-aggregated means
    (``success_rate``, ``reach_time_s``, ``skate_cm_s``, ``floor_cm``, ..., ``segment_skill_match``;
    undefined ones left out) and the episodes' mean return ``mean_reward``,
    the ``eval/trajectories`` figure, and ``stop`` once ``success_rate >= eval_cfg.success_target``.
    ``env_cfg`` gives ``guidance_scale``, ``action_bound``, ``foot_lock`` and, for path policies,
    ``observe_next``. Files and texts are checked now, not at the first evaluation. The trainer restores its
    random streams afterwards.
    """
    settings = EvalSettings(episodes=eval_cfg.episodes, max_steps=eval_cfg.max_steps,
                            deterministic=eval_cfg.deterministic, device=str(device))
    settings.take_training_env(env_cfg)
    settings.take_eval_config(eval_cfg)
    settings.validate()
    for _, paths in load_suites(files, eval_cfg.text):
        make_env(motion, paths, 1, settings)  # unknown prompts fail here (TextError), before training starts
    observe_next = getattr(env_cfg, "task", "reach") == "path" and bool(getattr(env_cfg, "observe_next", False))
    target = getattr(eval_cfg, "success_target", None)
    recorder = recorder_for(eval_cfg)

    def evaluate(policy: torch.nn.Module):
        from latentrl.evaluation.plots import paths_figure
        from latentrl.evaluation.report import pooled_metrics, skill_summary
        from latentrl.monitor import EVAL_TRAJECTORIES, EvalReport

        with collect_returns() as returns:
            suites = run_suites(policy_fn(policy, settings.deterministic), motion, files, settings,
                                observe_next=observe_next, text=eval_cfg.text,
                                sink=recorder.sink if recorder.start() else None)
        paths = [p for s in suites for p in s.paths]
        metrics = {k: v["mean"] for k, v in pooled_metrics(paths).items() if np.isfinite(v["mean"])}
        if returns:
            metrics["mean_reward"] = float(np.mean(returns))
        match = skill_summary(paths)["segment_skill_match"]
        if np.isfinite(match):
            metrics["segment_skill_match"] = match
        stop = target is not None and metrics["success_rate"] >= target
        return EvalReport(metrics, {EVAL_TRAJECTORIES: paths_figure(suites)}, stop, recorder.videos())

    return evaluate


# --------------------------------------------------------------------------- speed
def measure_speed(
    act: PolicyFn,
    motion,
    path: WaypointPath,
    settings: EvalSettings,
    batches: Sequence[int],
    observe_next: bool = False,
    repeats: int = 5,
) -> dict[str, dict[str, float]]:
    """Frames/s of the whole controller (policy + motion model + env bookkeeping) per batch size.

    Timed apart from the evaluation (which also records history and computes metrics) with
    :func:`latentrl.timing.median_time`: one warm-up step, then the median of ``repeats`` steps.
    Returns ``{str(batch): {"batch", "ms_per_step", "frames_per_s", "env_steps_per_s"}}``.
    """
    out = {}
    for batch in dict.fromkeys(int(b) for b in batches):
        env = make_env(motion, [path], batch, settings, observe_next, max_steps=10**9)
        seconds = _seconds_per_step(act, env, settings, repeats)
        out[str(batch)] = {
            "batch": batch,
            "ms_per_step": seconds * 1e3,
            "frames_per_s": batch * FUTURE_LENGTH / seconds,
            "env_steps_per_s": batch / seconds,
        }
        env.close()
    return out


def _seconds_per_step(act: PolicyFn, env: FollowPathEnv, settings: EvalSettings, repeats: int) -> float:
    """Median seconds of one policy call + one env step (the env never ends: no autoreset, huge budget)."""
    from latentrl.timing import median_time

    state = {"obs": env.reset(seed=settings.seed)[0]}

    def step() -> None:
        state["obs"] = env.step(act(state["obs"]))[0]

    return median_time(step, repeats=repeats, warmup=1, device=str(settings.device))
