"""The torch-native PPO loop: collect -> GAE -> update -> log -> checkpoint, everything on the env's device.

The trainer sees only the Gymnasium ``VectorEnv`` interface of a torch env with SAME_STEP autoreset:
``reset(seed) -> (obs (N, D), infos)`` and ``step(actions (N, A)) -> (obs, reward (N,), terminated (N,),
truncated (N,), infos)`` with ``infos["final_obs"]`` (N, D) + ``_final_obs``, ``episode``/``_episode``,
``is_success`` and ``reward/<term>``; the observation layout comes from ``env.metadata``. It never
imports ``latentrl.envs`` or ``latentrl.motion``; the caller passes the motion model's identity.

Inside the collection loop nothing is moved to the host (no ``.item()``); statistics are summarized
once per iteration.

Non-finite values stop the run: after each collection the rollout (observations, rewards, values,
advantages) and after each update the losses and weights are checked (one host sync each), and a
:class:`~latentrl.errors.NonFiniteError` names the iteration, the quantity and the last good
checkpoint, which is left as it was (nothing is saved after the bad iteration).
"""

from __future__ import annotations

import random
import time
import warnings
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch

from latentrl.errors import NonFiniteError
from latentrl.monitor import EvalReport, Monitor, RolloutStats
from latentrl.ppo import checkpoint as ckpt
from latentrl.ppo.config import PolicyConfig, PPOConfig
from latentrl.ppo.episodes import EpisodeRecorder
from latentrl.ppo.policy import ActorCritic
from latentrl.ppo.progress import RunProgress
from latentrl.ppo.storage import RolloutBuffer
from latentrl.ppo.update import ppo_update

Evaluator = Callable[[ActorCritic], EvalReport]
"""Evaluation hook: gets the policy (eval mode), returns metrics and figures; must not train it."""


class IterationTime(NamedTuple):
    collection_s: float
    """Wall seconds collecting the rollout (GAE included)."""
    update_s: float
    """Wall seconds in the PPO update."""


class TrainResult(NamedTuple):
    run_dir: Path
    final_checkpoint: Path
    iterations: int
    env_steps: int
    elapsed_s: float
    rollout: RolloutStats
    """Episode statistics over the last ``stats_window`` episodes at the end."""
    train: dict[str, float]
    """Update statistics of the last iteration ({} if no iteration ran)."""
    eval: EvalReport | None
    """The last evaluation, if any ran."""
    times: list[IterationTime]
    """Per-iteration timings of the iterations this call ran (benchmarks)."""
    stopped_early: bool
    """An evaluation asked to stop (``EvalReport.stop``) before ``num_iterations``."""


def seed_everything(seed: int, deterministic: bool = True) -> None:
    """Seed python, numpy and torch (all devices); ask cuDNN for deterministic kernels."""
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)
    torch.backends.cudnn.deterministic = deterministic
    if deterministic:
        torch.backends.cudnn.benchmark = False


def adam_kwargs(ppo: PPOConfig) -> dict[str, Any]:
    """Adam settings of both trainers: ``eps`` from the config, and the fused kernel where torch has one.

    Fused means one kernel for all parameters instead of a loop over ~30 tensors: ~25% off a small policy's step.
    """
    return {"eps": ppo.adam_eps, "fused": torch.device(ppo.device).type in ("cpu", "cuda")}


def run_evaluation(evaluate: Evaluator, policy: ActorCritic) -> EvalReport:
    """Call the hook in eval mode without perturbing the training random streams (restored afterwards)."""
    state = ckpt.capture_rng()
    was_training = policy.training
    policy.eval()
    try:
        with torch.no_grad():
            report = evaluate(policy)
    finally:
        ckpt.restore_rng(state)
        policy.train(was_training)
    return report if isinstance(report, EvalReport) else EvalReport(dict(report))


def observation_layout(env: Any, given: Mapping[str, Any] | None = None) -> Mapping[str, Any] | None:
    """The layout passed explicitly, else ``env.metadata["observation_layout"]``, else None."""
    if given is not None:
        return given
    return (getattr(env, "metadata", None) or {}).get("observation_layout")


LOSS_NAMES = {"policy_gradient_loss": "policy loss", "value_loss": "value loss", "entropy_loss": "entropy loss",
              "loss": "total loss", "approx_kl": "approx KL", "grad_norm": "gradient norm"}
"""Update statistics that must be finite, and how errors name them."""


def nonfinite_rollout(buffer: RolloutBuffer) -> str | None:
    """The first non-finite quantity of a filled buffer, e.g. ``'reward of env 3 at rollout step 5 is nan'``.

    The fast path sums each tensor (a sum is finite only if every element is) and syncs once; the
    slow path, which finds the env and step, runs only when something is wrong. None if all is finite.
    Final observations count only where an episode ended (the rows GAE reads).
    """
    checks = (("observation", buffer.obs), ("reward", buffer.rewards), ("value estimate", buffer.values),
              ("advantage", buffer.advantages))
    read_final = torch.where(buffer.dones[..., None], buffer.final_obs, 0.0)
    if bool(torch.isfinite(torch.stack([x.sum() for _, x in checks] + [read_final.sum()])).all()):
        return None
    T, N = buffer.num_steps, buffer.num_envs
    ended = buffer.dones.nonzero()  # (M, 2) [t, n] of the rows whose final observation is read
    final = buffer.final_obs[buffer.dones]  # (M, D)
    found = [(name, (~torch.isfinite(x.reshape(T, N, -1)).all(-1)).nonzero(), x) for name, x in checks]
    found.append(("final observation", ended[(~torch.isfinite(final).all(-1)).nonzero()[:, 0]], buffer.final_obs))
    for name, where, x in found:
        if len(where):
            t, n = (int(i) for i in where[0])
            row = x[t, n].reshape(-1)
            value = row[~torch.isfinite(row)][0].item()
            if name == "observation":  # row t holds the observation step t - 1 returned (row 0: the rollout's start)
                when = f"returned by rollout step {t - 1}" if t else "at the start of the rollout"
                return f"observation of env {n} {when} is {value}"
            return f"{name} of env {n} at rollout step {t} is {value}"
    return None  # a sum overflowed, but every value is finite


def nonfinite_update(stats: Mapping[str, float], policy: torch.nn.Module) -> str | None:
    """The first non-finite update statistic or weight after a PPO update, or None."""
    for key, name in LOSS_NAMES.items():
        value = stats.get(key)
        if value is not None and not np.isfinite(value):
            others = ", ".join(f"{LOSS_NAMES[k]} {stats[k]:.4g}" for k in LOSS_NAMES if k in stats and k != key)
            return f"{name} is {value} ({others})"
    params = dict(policy.named_parameters())
    if not bool(torch.stack([torch.isfinite(p).all() for p in params.values()]).all()):
        bad = next(n for n, p in params.items() if not bool(torch.isfinite(p).all()))
        return f"policy weight '{bad}' became non-finite"
    return None


def _now(device: torch.device) -> float:
    if device.type == "cuda":
        torch.cuda.synchronize(device)
    return time.perf_counter()


class NativeTrainer:
    """Torch-native PPO on a torch ``VectorEnv``.

    Args:
        env: the training env (already built, on its device).
        run_dir: where events, checkpoints and ``train.log`` go.
        ppo: PPO settings.
        policy_cfg: network settings.
        config: the full resolved run config stored in checkpoints (default: the two sections).
        motion: ``{"path", "sha256"}`` of the env's motion model, stored and checked on resume.
        evaluate: optional evaluation hook called every ``ppo.eval_every`` iterations.
        layout: observation layout override (default: ``env.metadata["observation_layout"]``).
        progress: show the tqdm bar.
    """

    name = "native"

    def __init__(self, env: Any, run_dir: str | Path, ppo: PPOConfig, policy_cfg: PolicyConfig, *,
                 config: Any = None, motion: Mapping[str, Any] | None = None, evaluate: Evaluator | None = None,
                 layout: Mapping[str, Any] | None = None, progress: bool = True):
        ppo.validate()
        policy_cfg.validate()
        self.env, self.run_dir, self.cfg = env, Path(run_dir), ppo
        self.config = config if config is not None else {"ppo": ppo, "policy": policy_cfg}
        self.motion, self.evaluate, self.progress = motion, evaluate, progress
        self.plan = ppo.plan(env.num_envs)
        self.device = torch.device(ppo.device)
        seed_everything(ppo.seed, ppo.torch_deterministic)
        obs_dim = int(np.prod(env.single_observation_space.shape))
        action_dim = int(np.prod(env.single_action_space.shape))
        self.policy = ActorCritic(obs_dim, action_dim, policy_cfg, observation_layout(env, layout)).to(self.device)
        self.optimizer = torch.optim.Adam(self.policy.parameters(), lr=ppo.learning_rate, **adam_kwargs(ppo))
        self.buffer = RolloutBuffer(ppo.num_steps, env.num_envs, obs_dim, action_dim, self.device)
        self.episodes = EpisodeRecorder(ppo.num_steps, env.num_envs, self.device, ppo.stats_window)
        space = env.single_action_space
        self.action_low = torch.as_tensor(space.low, dtype=torch.float32, device=self.device)
        self.action_high = torch.as_tensor(space.high, dtype=torch.float32, device=self.device)
        self.iteration, self.env_steps, self.elapsed_s = 0, 0, 0.0
        self._pending_rng: dict | None = None
        self.last_train: dict[str, float] = {}
        self.last_eval: EvalReport | None = None
        self.times: list[IterationTime] = []
        self.stop_requested = False
        self.last_checkpoint: Path | None = None
        """The newest checkpoint this run wrote or resumed from (named by non-finite errors)."""

    # ------------------------------------------------------------------ checkpoints
    def checkpoint(self) -> dict:
        return ckpt.make_checkpoint(trainer=self.name, iteration=self.iteration, env_steps=self.env_steps,
                                    elapsed_s=self.elapsed_s, policy=self.policy, optimizer=self.optimizer,
                                    config=self.config, motion=self.motion, env=self.env)

    def save(self, path: str | Path) -> Path:
        self.last_checkpoint = ckpt.save_checkpoint(self.checkpoint(), path)
        return self.last_checkpoint

    def resume(self, allow_motion_mismatch: bool = False) -> Path | None:
        """Continue from the newest readable checkpoint in ``run_dir``; None (fresh start) if there is none."""
        found = ckpt.load_latest(self.run_dir, map_location=self.device)
        if found is None:
            warnings.warn(f"{self.run_dir}: no checkpoint to resume from; starting at step 0", stacklevel=2)
            return None
        path, state = found
        ckpt.check_resumable(state, path, trainer=self.name, config=self.config, motion=self.motion,
                             allow_motion_mismatch=allow_motion_mismatch)
        ckpt.check_shapes(state, path, self.policy.obs_dim, self.policy.action_dim)
        self.policy.load_state_dict(state["policy"])
        self.optimizer.load_state_dict(state["optimizer"])
        self.iteration, self.env_steps, self.elapsed_s = state["iteration"], state["env_steps"], state["elapsed_s"]
        self._pending_rng = state["rng"]
        self.last_checkpoint = path
        return path

    # ------------------------------------------------------------------ phases
    def _reset_env(self) -> torch.Tensor:
        """Fresh runs reset with ``seed``; resumed runs with ``seed + iteration``, then restore the saved RNGs."""
        obs, _ = self.env.reset(seed=self.cfg.seed + self.iteration)
        if self._pending_rng is not None:
            ckpt.restore_rng(self._pending_rng, self.env)
            self._pending_rng = None
        return torch.as_tensor(obs)

    def _set_learning_rate(self) -> float:
        """CleanRL's annealing: ``lr_k = (1 - k / K) lr_0`` for iteration k = 0..K-1."""
        lr = self.cfg.learning_rate
        if self.cfg.anneal_lr:
            lr *= 1.0 - self.iteration / self.plan.num_iterations
        for group in self.optimizer.param_groups:
            group["lr"] = lr
        return lr

    @torch.no_grad()
    def collect(self, obs: torch.Tensor) -> torch.Tensor:
        """Fill the buffer with ``num_steps`` steps from ``obs`` (N, D); compute GAE; return the next obs."""
        env_device = obs.device
        buf, cfg = self.buffer, self.cfg
        for t in range(cfg.num_steps):
            obs = obs.to(self.device)
            step = self.policy.act(obs)
            action = step.action.clamp(self.action_low, self.action_high) if cfg.clip_actions else step.action
            next_obs, reward, terminated, truncated, infos = self.env.step(action.to(env_device))
            final_obs = infos.get("final_obs")
            buf.insert(t, obs, step.action, step.log_prob, step.value, torch.as_tensor(reward),
                       torch.as_tensor(terminated), torch.as_tensor(truncated),
                       None if final_obs is None else torch.as_tensor(final_obs))
            self.episodes.record(t, infos)
            obs = torch.as_tensor(next_obs)
        last_value = self.policy.value(obs.to(self.device))
        buf.compute_returns(last_value, self.policy.value, cfg.gamma, cfg.gae_lambda, cfg.bootstrap_truncated)
        return obs

    def update(self) -> dict[str, float]:
        """PPO epochs on the filled buffer, then fold this rollout into the observation normalizer."""
        self.policy.train()
        stats = ppo_update(self.policy, self.optimizer, self.buffer, self.cfg, self.plan.minibatch_size)
        self.policy.update_normalizer(self.buffer.obs)
        self.policy.eval()
        return stats

    # ------------------------------------------------------------------ loop
    def train(self) -> TrainResult:
        """Run iterations until ``plan.num_iterations``; checkpoint periodically and write ``final.pt``."""
        monitor = Monitor(self.run_dir, resume_step=self.env_steps if self.iteration else None)
        bar = RunProgress(self.run_dir, self.plan.num_iterations * self.plan.batch_size, self.env_steps, self.progress)
        if self.iteration == 0:
            monitor.log_hparams(ckpt.plain_config(self.config))
        bar.write(f"{self.name} trainer: start at iteration {self.iteration}, {self.env_steps} env steps, "
                  f"{self.plan.num_iterations} iterations of {self.plan.batch_size} steps")
        obs = self._reset_env()
        start, steps_at_start, elapsed_at_start = time.perf_counter(), self.env_steps, self.elapsed_s
        ran = 0
        try:
            while self.iteration < self.plan.num_iterations and not self.stop_requested:
                lr = self._set_learning_rate()
                t0 = _now(self.device)
                obs = self.collect(obs)
                stop_if_nonfinite(self, bar, nonfinite_rollout(self.buffer), ROLLOUT_HINT)
                summary = self.episodes.summarize()
                t1 = _now(self.device)
                self.last_train = {**self.update(), "learning_rate": lr}
                stop_if_nonfinite(self, bar, nonfinite_update(self.last_train, self.policy))
                t2 = _now(self.device)
                self.iteration, self.env_steps, ran = self.iteration + 1, self.env_steps + self.plan.batch_size, ran + 1
                self.elapsed_s = elapsed_at_start + (t2 - start)
                fps = (self.env_steps - steps_at_start) / max(t2 - start, 1e-9)
                self.times.append(IterationTime(t1 - t0, t2 - t1))
                self._after_iteration(monitor, bar, summary, fps, t1 - t0, t2 - t1)
        finally:
            monitor.close()
            bar.close()
        final = self.run_dir / ckpt.FINAL
        if ran or not final.is_file():
            self.save(final)
        return TrainResult(self.run_dir, final, self.iteration, self.env_steps, self.elapsed_s,
                           self.episodes.stats(), self.last_train, self.last_eval, self.times, self.stop_requested)

    def _after_iteration(self, monitor: Monitor, bar: RunProgress, summary, fps: float,
                         collection_s: float, update_s: float) -> None:
        cfg, k, step = self.cfg, self.iteration, self.env_steps
        last = k == self.plan.num_iterations
        if k % cfg.log_every == 0 or last:
            monitor.log_rollout(step, summary.stats, summary.diverged)
            monitor.log_train(step, self.last_train)
            monitor.log_rewards(step, summary.reward_terms)
            monitor.log_time(step, fps, collection_s, update_s)
            bar.log_iteration(k, step, fps, summary.stats, self.last_train, collection_s, update_s,
                              summary.reward_terms, summary.diverged)
        if self.evaluate is not None and cfg.eval_every and (k % cfg.eval_every == 0 or last):
            self.last_eval = run_evaluation(self.evaluate, self.policy)
            self.stop_requested = bool(self.last_eval.stop)
            monitor.log_eval(step, self.last_eval)
            bar.write(f"eval iter {k} steps {step}: "
                      + " ".join(f"{n} {v:.4g}" for n, v in self.last_eval.metrics.items()))
        if cfg.checkpoint_every and k % cfg.checkpoint_every == 0 and not (last or self.stop_requested):
            self.save(ckpt.iteration_path(self.run_dir, k))
            ckpt.prune_checkpoints(self.run_dir, cfg.keep_checkpoints)
        monitor.flush()
        bar.update(step, fps, summary.stats)


ROLLOUT_HINT = "the env must return finite observations and rewards"
UPDATE_HINT = "a new run with a lower ppo.learning_rate or max_grad_norm may avoid it"


def stop_if_nonfinite(trainer: Any, bar: RunProgress, problem: str | None, hint: str = UPDATE_HINT) -> None:
    """Raise :class:`NonFiniteError` for ``problem`` in the trainer's current iteration (also logged to train.log)."""
    if problem is None:
        return
    last = trainer.last_checkpoint or "none yet"
    message = (f"iteration {trainer.iteration + 1}: {problem}; training stopped without saving this iteration "
               f"(last good checkpoint: {last}); {hint}")
    bar.write(f"stopped: {message}")
    raise NonFiniteError(message)
