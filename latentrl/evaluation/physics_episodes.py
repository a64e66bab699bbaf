"""Path episodes with physics in the loop (``latentrl eval --physics``), beside the kinematic run of the same seeds.

Each env step the policy's primitive is planned by the motion model as usual, then executed by the physics
tracker (:class:`~latentrl.physics.loop.PrimitiveExecutor`); the last two simulated frames replace the env's
history (:meth:`~latentrl.envs.base.LatentMotionVectorEnv.set_history`), so the policy observes, and the model
plans from, what physics did. One env per episode (batch 1): the simulator steps one character. Success and
reach time are the env's (judged on the frames the model planned from the simulated history, as in a kinematic
eval); the physical metrics (falls, assist, CLoSD penetration / floating / skating) are measured on the
simulated frames. The kinematic run uses the same seeds and policy, without physics.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch

from latentrl.envs.path import WaypointPath
from latentrl.evaluation.config import EvalSettings
from latentrl.evaluation.metrics import closd_floating_mm, closd_penetration_mm, closd_skating_mm
from latentrl.evaluation.results import frames_after
from latentrl.motion.skeleton import FPS, PELVIS

GRAVITY = 9.81
"""m/s^2, for the assist as a share of body weight."""


def closd_quality(joints: np.ndarray, floor: float = 0.0) -> dict[str, float]:
    """CLoSD's penetration, floating and skating (mm) of (T, 22, 3) world joints."""
    joints = torch.as_tensor(np.asarray(joints, dtype=np.float64))
    return {"penetration_mm": float(closd_penetration_mm(joints, floor)),
            "floating_mm": float(closd_floating_mm(joints, floor)),
            "skating_mm": float(closd_skating_mm(joints, floor))}


def run_episode(act, motion, path: WaypointPath, settings: EvalSettings, seed: int, observe_next: bool = False,
                humanoid: Any = None, assist_hz: float | None = None, on_step=None) -> dict[str, Any]:
    """One episode of ``path`` (batch 1); with ``humanoid`` every primitive is executed by physics.

    ``on_step(env, executor)`` (tests) sees the env after each step's history was replaced.
    Returns success, steps, reach time, final distance and the metrics of the frames that happened.
    """
    from latentrl.evaluation.runner import make_env

    env = make_env(motion, [path], 1, settings, observe_next, record_history=True, record_features=True)
    torch.manual_seed(seed)
    obs, _ = env.reset(seed=seed)
    executor = None
    if humanoid is not None:
        from latentrl.physics.loop import PrimitiveExecutor

        start = env.export_clip(0)
        executor = PrimitiveExecutor(humanoid, start.joints, start.features,
                                     motion.pelvis_delta.detach().cpu().numpy(), assist_hz)
    success, steps = False, settings.max_steps
    for k in range(1, settings.max_steps + 1):
        obs, _, terminated, truncated, infos = env.step(act(obs))
        if executor is not None:
            clip = env.export_clip(0)
            history = executor.execute(clip.joints[-8:], clip.features[-8:])
            env.set_history(torch.as_tensor(history[None], dtype=torch.float32))
            obs = env.observation()
            if on_step is not None:
                on_step(env, executor)
        success = bool(infos["is_success"][0])
        if success or bool(terminated[0]) or bool(truncated[0]):
            steps = k
            break
    joints = executor.simulated if executor is not None else env.export_clip(0).joints
    env.close()
    final = np.asarray(path.waypoints[-1], dtype=np.float64)
    out = {"seed": seed, "success": success, "steps": steps,
           "reach_time_s": frames_after(steps) / FPS if success else settings.budget_s,
           "final_dist_m": float(np.linalg.norm(joints[-1, PELVIS, :2] - final[:2])),
           **closd_quality(joints, env.floor_height)}
    if executor is not None:
        weight = humanoid.mass * GRAVITY
        out["falls"] = len(executor.falls)
        out["assist_percent_body_weight"] = float(100 * executor.assist_force[2:].mean() / weight)
    return out


def summarize(episodes: list[dict[str, Any]]) -> dict[str, float]:
    """Means over episodes of every numeric field (success as a rate; falls summed too)."""
    keys = [k for k in episodes[0] if k not in ("seed",)]
    out = {k: float(np.mean([float(e[k]) for e in episodes])) for k in keys}
    out["success_rate"] = out.pop("success")
    if "falls" in out:
        out["falls_total"] = int(sum(e["falls"] for e in episodes))
    return out
