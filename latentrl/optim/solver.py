"""Latent noise optimization (DART's second control mode, its ``optim_mld``): Adam on the noise sequence.

The noises of all primitives of a problem are optimized together through the frozen rollout
(:meth:`MotionModel.differentiable_step`: DDIM sampler with classifier-free guidance, VAE decoder,
canonicalization, world placement). As in DART: each problem's gradient is normalized to unit length over
its whole noise sequence, the learning rate falls linearly to 0, the sampler is deterministic.
Problems of the same length are solved as one batch; each problem's loss is its own, so a problem's
result does not depend on the others in its batch (tested). No floor snap and no foot lock run: the
returned motion is exactly the rollout of the returned noise (floor and skate are losses instead).
"""

from __future__ import annotations

import time
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import torch

from latentrl.constants import GUIDANCE_SCALE, MAX_GUIDANCE
from latentrl.errors import DataError, LatentRLError
from latentrl.motion.canonical import WorldTransform, features_to_world, world_to_canonical
from latentrl.motion.clip import MotionClip, primitive_layout
from latentrl.motion.representation import FUTURE_LENGTH, HISTORY_LENGTH, joints_of
from latentrl.motion.rollout import RolloutState
from latentrl.motion.skeleton import FPS
from latentrl.optim.losses import REGULARIZERS, constraint_loss, goal_error_cm, regularizers
from latentrl.optim.problems import Problem, stack_targets

INITS = ("zeros", "randn")
"""Starting noises besides a policy file: all zeros (the prior's mode) or N(0, init_scale^2) per problem."""


@dataclass
class OptimizeSettings:
    """How to optimize (the flags of ``latentrl optimize``; docs/optimize.md)."""

    steps: int = 100
    lr: float = 0.05
    init: str = "randn"
    """'zeros', 'randn' or a policy ``.pt`` (warm start: :mod:`latentrl.optim.warm`)."""
    init_scale: float = 0.1
    """Standard deviation of the 'randn' start (DART's ``init_noise_scale``)."""
    samples: int = 1
    """Starts per problem; the one with the lowest final loss is returned."""
    batch: int = 16
    """Problems solved together as one tensor."""
    guidance: float = GUIDANCE_SCALE
    seed: int = 0
    weights: dict[str, float] = field(default_factory=lambda: {"floor": 1.0, "skate": 1.0, "jerk": 0.0,
                                                               "prior": 0.1})
    stop_cm: float | None = None
    """End a batch early once every problem's goal error is at most this (None: run every step)."""

    def check(self) -> None:
        """One-line :class:`LatentRLError` for a value out of range."""
        if not 1 <= self.steps <= 100_000:
            raise LatentRLError(f"steps: expected 1-100000, got {self.steps}")
        if not (0 < self.lr <= 10):
            raise LatentRLError(f"lr: expected a learning rate in (0, 10], got {self.lr}")
        if not 1 <= self.samples <= 256:
            raise LatentRLError(f"samples: expected 1-256, got {self.samples}")
        if not 1 <= self.batch <= 4096:
            raise LatentRLError(f"batch: expected 1-4096 problems, got {self.batch}")
        if not (0 <= self.init_scale <= 10):
            raise LatentRLError(f"init_scale: expected 0-10, got {self.init_scale}")
        if not (np.isfinite(self.guidance) and abs(self.guidance) <= MAX_GUIDANCE):  # nan/1e30: a NaN motion
            raise LatentRLError(f"guidance: expected a finite number in [-{MAX_GUIDANCE:g}, {MAX_GUIDANCE:g}], "
                                f"got {self.guidance}")
        unknown = sorted(set(self.weights) - set(REGULARIZERS))
        if unknown:
            raise LatentRLError(f"weights: unknown regularizer {unknown[0]!r}; expected {', '.join(REGULARIZERS)}")
        bad = [k for k, v in self.weights.items() if not (v >= 0 and np.isfinite(v))]
        if bad:
            raise LatentRLError(f"weights.{bad[0]}: expected a finite number >= 0, got {self.weights[bad[0]]}")


@dataclass
class Result:
    """One problem's answer: the motion of the returned noise, its scores and its trace."""

    problem: Problem
    noise: np.ndarray  # (S, D) the optimized noise per primitive
    joints: np.ndarray  # (2 + 8 S, 22, 3) world metres: the 2 start frames, then the generated frames
    features: np.ndarray  # (2 + 8 S, 276) world features
    metrics: dict[str, float]
    trace: list[tuple[float, float, float]]  # (seconds since the batch began, goal error cm, loss) per step

    def clip(self) -> MotionClip:
        """The result as the shared motion type (BVH, GIF, the viewer)."""
        texts = [""] * HISTORY_LENGTH + [t for t in self.problem.texts for _ in range(FUTURE_LENGTH)]
        meta = {"problem": self.problem.name, **{k: v for k, v in self.metrics.items() if v is not None}}
        return MotionClip(self.joints, float(FPS), texts, actions=self.noise, features=self.features,
                          primitive=primitive_layout(self.problem.primitives), meta=meta)


def start_states(model, problems: list[Problem]) -> RolloutState:
    """The start of every problem: a seed history placed as ``initial_state`` does, or two frames of a file."""
    states, built = [], {}
    for p in problems:
        if id(p) in built:  # the same problem again (samples): its start once
            states.append(built[id(p)])
            continue
        built[id(p)] = _start_state(model, p)
        states.append(built[id(p)])
    return RolloutState(torch.cat([s.history for s in states]),
                        WorldTransform(torch.cat([s.world.rotation for s in states]),
                                       torch.cat([s.world.translation for s in states])),
                        torch.cat([s.airborne_flags() for s in states]))


def _start_state(model, p: Problem) -> RolloutState:
    """One problem's start (batch 1)."""
    if p.start.seed is not None:
        k = model.seed_history.shape[0] if model.seed_history is not None else 0
        if p.start.seed >= k:
            raise DataError(f"problem {p.name!r}: start.seed {p.start.seed} is outside the model's "
                            f"{k} seed histories (0-{k - 1})")
        return model.initial_state(1, seed_index=torch.tensor([p.start.seed]))
    clip = MotionClip.load(p.start.motion)
    if clip.features is None:
        raise DataError(f"{p.start.motion}: has no 'features' (a motion written by latentrl eval, motion "
                        f"sample or optimize has them); problem {p.name!r} cannot start from it")
    end = p.start.frame if p.start.frame >= 0 else clip.frames - 1
    if not HISTORY_LENGTH - 1 <= end < clip.frames:
        raise DataError(f"problem {p.name!r}: start.frame {p.start.frame} is outside {p.start.motion}'s "
                        f"{clip.frames} frames (needs {HISTORY_LENGTH} frames ending there)")
    feats = torch.as_tensor(clip.features[end - HISTORY_LENGTH + 1:end + 1], dtype=torch.float32)
    canon, world = world_to_canonical(feats[None].to(model.device), model.pelvis_delta)
    return RolloutState(canon, world, torch.zeros(1, dtype=torch.bool, device=model.device))


def rollout(model, start: RolloutState, embeddings: list[torch.Tensor], noise: torch.Tensor, guidance: float,
            with_features: bool = False) -> tuple[torch.Tensor, torch.Tensor | None]:
    """(B, 2 + 8 S, 22, 3) world joints of the start and of every primitive of ``noise`` (S, B, 1, D).

    Differentiable in ``noise`` when autograd is on; ``with_features`` also returns the world features.
    """
    joints = [start.world.apply(joints_of(start.history))]
    feats = [features_to_world(start.history, start.world, model.pelvis_delta)] if with_features else None
    state = start
    for s in range(noise.shape[0]):
        out = model.differentiable_step(state, embeddings[s], noise[s], guidance)
        joints.append(out.joints_world)
        if with_features:
            feats.append(features_to_world(out.future, out.placement, model.pelvis_delta))
        state = out.state
    return torch.cat(joints, dim=1), (torch.cat(feats, dim=1) if with_features else None)


def initial_noise(problems: list[Problem], model, settings: OptimizeSettings, warm: torch.Tensor | None = None
                  ) -> torch.Tensor:
    """(S, B * samples, 1, D): per problem and sample its own generator, so a batch never changes a problem's start."""
    steps = problems[0].primitives
    shape = model.latent_shape
    out = []
    for i, p in enumerate(problems):
        for k in range(settings.samples):
            if warm is not None:
                out.append(warm[:, i])
            elif settings.init == "zeros":
                out.append(torch.zeros(steps, *shape))
            else:
                g = torch.Generator().manual_seed(_problem_seed(settings.seed, p.name, k))
                out.append(torch.randn(steps, *shape, generator=g) * settings.init_scale)
    return torch.stack(out, dim=1).to(model.device)


def _problem_seed(seed: int, name: str, sample: int) -> int:
    """A start seed of one problem and sample that depends on neither the batch nor the suite order."""
    return (seed * 1_000_003 + zlib.crc32(name.encode()) * 31 + sample) % (2**63)


def total_loss(joints: torch.Tensor, noise: torch.Tensor, targets, weights: dict[str, float],
               names: tuple[str, ...]) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """(B,) constraint loss plus the weighted regularizers, and the regularizers ``names`` computed on the way.

    The optimizer's loop asks only for the weighted ones; the final rollout asks for all (they are its metrics).
    """
    loss = constraint_loss(joints[:, HISTORY_LENGTH:], targets)
    reg = regularizers(joints, noise, float(FPS), names) if names else {}
    for k, w in weights.items():
        loss = loss + w * reg[k]
    return loss, reg


def solve_batch(model, problems: list[Problem], settings: OptimizeSettings,
                warm: torch.Tensor | None = None, on_step: Callable[[int, int], None] | None = None) -> list[Result]:
    """Optimize problems of one length together; one :class:`Result` per problem (its best sample)."""
    steps_p = problems[0].primitives
    if any(p.primitives != steps_p for p in problems):
        raise ValueError("solve_batch needs problems of one length; optimize() groups them")
    reps = settings.samples
    expanded = [p for p in problems for _ in range(reps)]
    targets = stack_targets(expanded, model.device)
    start = start_states(model, expanded)
    embeddings = [model.encode_text([p.texts[s] for p in expanded]) for s in range(steps_p)]
    z = initial_noise(problems, model, settings, warm).requires_grad_(True)
    opt = torch.optim.Adam([z], lr=settings.lr)
    weights = {k: float(v) for k, v in settings.weights.items() if v > 0}
    b = len(expanded)
    traces: list[list[tuple[float, float, float]]] = [[] for _ in range(b)]
    t0 = time.perf_counter()
    for step in range(settings.steps):
        for group in opt.param_groups:  # DART: linear decay to 0
            group["lr"] = settings.lr * (1.0 - step / settings.steps)
        opt.zero_grad(set_to_none=True)
        joints, _ = rollout(model, start, embeddings, z, settings.guidance)
        loss, _ = total_loss(joints, z, targets, weights, tuple(weights))
        loss.sum().backward()  # per-problem losses: each problem's gradient is its own
        with torch.no_grad():
            norm = z.grad.flatten(2).norm(dim=(0, 2)).clamp(min=1e-12)  # (B,) over the whole sequence
            z.grad /= norm[None, :, None, None]
            err = goal_error_cm(joints[:, HISTORY_LENGTH:], targets)
        opt.step()
        elapsed = time.perf_counter() - t0
        for i, (e, lo) in enumerate(zip(err.tolist(), loss.detach().tolist())):
            traces[i].append((elapsed, e, lo))
        if on_step is not None:
            on_step(step, len(problems))
        if settings.stop_cm is not None and bool((err <= settings.stop_cm).all()):
            break
    return _finish(model, problems, expanded, start, embeddings, z.detach(), targets, traces, settings, weights)


def _finish(model, problems, expanded, start, embeddings, z, targets, traces, settings, weights) -> list[Result]:
    """Roll the final noise out once more (no gradient): the returned motion and its metrics."""
    with torch.no_grad():
        joints, feats = rollout(model, start, embeddings, z, settings.guidance, with_features=True)
        err = goal_error_cm(joints[:, HISTORY_LENGTH:], targets)
        loss, reg = total_loss(joints, z, targets, weights, REGULARIZERS)  # every regularizer: the report's metrics
        start_joints = start.world.apply(joints_of(start.history))
        history_err = (joints[:, :HISTORY_LENGTH] - start_joints).norm(dim=-1).mean(dim=(1, 2)) * 100.0
    reps = settings.samples
    out = []
    for i, p in enumerate(problems):
        rows = list(range(i * reps, (i + 1) * reps))
        best = min(rows, key=lambda r: float(loss[r]))
        trace = traces[best]
        below = next((t for t, e, _ in trace if e <= 1.0), None)
        metrics = {
            "goal_error_cm": float(err[best]),
            "goal_error_start_cm": trace[0][1] if trace else float(err[best]),
            "history_error_cm": float(history_err[best]),
            "skate_cm_s": float(reg["skate"][best]) * 100.0,
            "floor_cm": float(reg["floor"][best]) * 100.0,
            "jerk": float(reg["jerk"][best]),
            "noise_rms": float(z[:, best].pow(2).mean().sqrt()),
            "loss": float(loss[best]),
            "steps": len(trace),
            "seconds": trace[-1][0] if trace else 0.0,
            "seconds_to_1cm": below,
            "batch": len(problems),
        }
        out.append(Result(p, z[:, best, 0].cpu().numpy(), joints[best].cpu().numpy(), feats[best].cpu().numpy(),
                          metrics, trace))
    return out


def group_problems(problems: list[Problem], batch: int) -> list[list[int]]:
    """Indices of ``problems`` in batches of one length, at most ``batch`` each, in suite order."""
    by_len: dict[int, list[int]] = {}
    for i, p in enumerate(problems):
        by_len.setdefault(p.primitives, []).append(i)
    groups = []
    for idx in by_len.values():
        groups += [idx[k:k + batch] for k in range(0, len(idx), batch)]
    return sorted(groups, key=lambda g: g[0])


def unconstrained_jerk(model, problem: Problem, guidance: float, samples: int = 4, seed: int = 0) -> float:
    """Mean jerk of ``samples`` plain rollouts (prior noise) of the problem's start and prompts.

    The reference the result's jerk is compared with (DART: constrained 0.61 vs data 0.74).
    """
    with torch.no_grad():
        start = start_states(model, [problem] * samples)
        emb = [model.encode_text([problem.texts[s]] * samples) for s in range(problem.primitives)]
        g = torch.Generator().manual_seed(seed)
        z = torch.randn(problem.primitives, samples, *model.latent_shape, generator=g).to(model.device)
        joints, _ = rollout(model, start, emb, z, guidance)
        return float(regularizers(joints, z, float(FPS), ("jerk",))["jerk"].mean())


def add_unconstrained_jerk(model, results: list[Result], guidance: float, seed: int = 0) -> None:
    """Set every result's ``jerk_unconstrained`` metric (:func:`unconstrained_jerk`), as the reports show it."""
    for r in results:
        r.metrics["jerk_unconstrained"] = unconstrained_jerk(model, r.problem, guidance, seed=seed)


def optimize(model, problems: list[Problem], settings: OptimizeSettings | None = None,
             warm_start: Callable[[object, list[Problem]], torch.Tensor] | None = None,
             on_step: Callable[[int, int], None] | None = None) -> list[Result]:
    """Solve every problem; results in suite order.

    ``warm_start(model, problems) -> (S, B, 1, D)`` gives start noises; ``on_step(step, problems)`` is called after
    every optimizer step of a batch of ``problems`` problems (a progress bar).
    """
    settings = settings or OptimizeSettings()
    settings.check()
    if not hasattr(model, "differentiable_step"):
        raise LatentRLError(f"{type(model).__name__} has no differentiable_step; noise optimization needs a "
                            "MotionModel (the embedded default or a DART checkpoint)")
    results: list[Result | None] = [None] * len(problems)
    for idx in group_problems(problems, settings.batch):
        chunk = [problems[i] for i in idx]
        warm = warm_start(model, chunk) if warm_start is not None else None
        for i, r in zip(idx, solve_batch(model, chunk, settings, warm, on_step)):
            results[i] = r
    return results
