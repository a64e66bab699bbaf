"""Warm start from a policy: the noises a reach/path policy picks on its way to a problem's pelvis target.

Why: RL and noise optimization act on the same latent noise. A policy knows how to walk somewhere; the
optimizer knows how to land joints exactly. Starting the optimizer from the policy's noises gives it the
steering for free (``latentrl optimize --init POLICY``; ``latentrl bench optimize --warm`` measures the gain).

Each problem becomes a one-waypoint path at its pelvis target (the last pelvis row of its constraints; the
mean of its last frame's targets when it has none) with its first prompt; the policy runs as in evaluation
(its training env settings, deterministic) for the problem's primitives, and the clamped actions are the
start noises. The policy's env starts from its own seed history, which may differ from the problem's start.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from latentrl.envs.path import WaypointPath
from latentrl.errors import ConfigError
from latentrl.evaluation.config import EvalSettings
from latentrl.evaluation.runner import make_env, policy_fn
from latentrl.evaluation.trained import stored_env
from latentrl.optim.problems import Problem
from latentrl.ppo import load_policy
from latentrl.resources import policy_file

POLICY_TASKS = ("reach", "path")
"""Tasks whose policies steer the pelvis to a point (the ones a warm start can use)."""


def pelvis_goal(problem: Problem) -> tuple[float, float]:
    """The xy a policy should walk to: the problem's last pelvis target, else the mean of its last frame's targets."""
    pelvis = np.nonzero(problem.joints == 0)[0]
    if len(pelvis):
        row = pelvis[np.argmax(problem.frames[pelvis])]
        return float(problem.targets[row, 0]), float(problem.targets[row, 1])
    last = problem.frames == problem.frames.max()
    xy = problem.targets[last, :2].mean(axis=0)
    return float(xy[0]), float(xy[1])


def policy_warm_start(spec: str, guidance: float | None = None) -> Callable[[object, list[Problem]], torch.Tensor]:
    """A ``warm_start(model, problems) -> (S, B, 1, D)`` that rolls the policy ``spec`` (file or shipped name)."""
    from pathlib import Path

    from latentrl.ppo.checkpoint import read_checkpoint

    path = policy_file(spec)
    if not Path(path).is_file():
        raise ConfigError(f"--init {spec}: expected 'zeros', 'randn' or a reach/path policy file (or shipped name); "
                          "no such file")
    read_checkpoint(path)  # an unreadable or hostile file is its own one line, not "its task: None"
    env_cfg = stored_env(path)
    if env_cfg is None or env_cfg.task not in POLICY_TASKS:
        task = None if env_cfg is None else env_cfg.task
        raise ConfigError(f"--init {spec}: expected 'zeros', 'randn' or a reach/path policy file (its task: {task})")

    def warm(model, problems: list[Problem]) -> torch.Tensor:
        device = str(model.device)
        settings = EvalSettings(episodes=1, max_steps=problems[0].primitives, deterministic=True, seed=0,
                                device=device)
        settings.take_training_env(env_cfg)
        info = model.info
        loaded = load_policy(str(path), device, motion={"path": info.get("source"), "sha256": info.get("sha256")})
        act = policy_fn(loaded.policy, deterministic=True)
        paths = [WaypointPath(((*pelvis_goal(p), 0.0),), (p.texts[0],)) for p in problems]
        env = make_env(model, paths, len(paths), settings, observe_next=bool(env_cfg.observe_next),
                       max_steps=problems[0].primitives)
        obs, _ = env.reset(seed=0)
        noises = []
        with torch.no_grad():
            for _ in range(problems[0].primitives):
                action = act(obs).clamp(-env.action_bound, env.action_bound)
                noises.append(action.reshape(len(problems), *model.latent_shape))
                obs, *_ = env.step(action)
        env.close()
        return torch.stack(noises)  # (S, B, 1, D)

    return warm
