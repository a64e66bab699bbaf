"""The Stable-Baselines3 path: ``stable_baselines3.PPO`` with our actor-critic, tags, checkpoints and resume.

- :class:`LatentActorCriticPolicy` is an SB3 ``ActorCriticPolicy`` whose whole network is an
  :class:`~latentrl.ppo.policy.ActorCritic` (``policy.net``): same encoders, ``4 tanh`` mean, clamped
  log-std and zero init as the native trainer, and the same state dict, so ``final.pt`` of either
  trainer loads with :func:`latentrl.ppo.checkpoint.load_policy`.
- :func:`sb3_ppo_kwargs` maps :class:`PPOConfig` onto ``PPO(...)`` arguments.
- :class:`Sb3Trainer` (a :class:`~latentrl.ppo.runner.Runner`) runs ``PPO.learn`` with a callback that
  routes SB3's logger into our :class:`~latentrl.monitor.Monitor` (env steps on the x-axis, one events
  file per run), adds ``reward/<term>``, ``time/collection_s`` and ``time/update_s``, and writes our checkpoints.

Where SB3 and CleanRL/DART differ at equal settings (documented in docs/training.md): SB3 clips the
value *prediction* (not ``max`` of clipped and unclipped losses) and always clips actions to the
action space before stepping; the value weight is mapped so both scale ``(V - R)^2`` alike.

The VecEnv must give per-env info dicts with ``episode`` and ``is_success`` at episode ends (SB3's
convention), ``terminal_observation``/``TimeLimit.truncated`` (SB3's bootstrap), and every
``reward/<term>`` at every step (and ``diverged``, counted as ``rollout/diverged``, if the env reports
it); its ``metadata["observation_layout"]`` (or the ``layout`` argument) gives the observation layout.
Non-finite observations or rewards (checked at every step) and losses or weights (after every update)
stop training with :class:`~latentrl.errors.NonFiniteError`, as in the native trainer.
"""

from __future__ import annotations

import io
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
import torch
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import KVWriter, Logger
from stable_baselines3.common.policies import ActorCriticPolicy

from latentrl.monitor import REWARD_PREFIX, TRAIN_PREFIX, Monitor, RolloutStats
from latentrl.ppo import checkpoint as ckpt
from latentrl.ppo.algorithm import adam_kwargs
from latentrl.ppo.config import BatchPlan, PolicyConfig, PPOConfig
from latentrl.ppo.contract import DIVERGED, action_magnitude, observation_layout, reward_weights
from latentrl.ppo.policy import ActorCritic, plain_layout
from latentrl.ppo.runner import ROLLOUT_HINT, Runner, nonfinite_update, stop_if_nonfinite
from latentrl.safe_io import atomic_write_bytes

SB3_ZIP_SUFFIX = ".sb3.zip"


# --------------------------------------------------------------------------- policy
class LatentActorCriticPolicy(ActorCriticPolicy):
    """SB3 policy whose network is ``self.net``, an :class:`ActorCritic` built from ``policy_config``.

    Args:
        observation_space: flat Box of D floats.
        action_space: Box of A floats.
        lr_schedule: SB3 learning-rate schedule.
        policy_config: a :class:`PolicyConfig` as a dict (``to_dict``) or the dataclass.
        observation_layout: name -> [start, stop) of the observation groups, or None.
        **kwargs: ``ActorCriticPolicy`` arguments (``optimizer_kwargs``...); ``net_arch`` and friends are ignored.
    """

    def __init__(self, observation_space, action_space, lr_schedule, policy_config: Any = None,
                 observation_layout: Mapping[str, Any] | None = None, **kwargs: Any):
        if isinstance(policy_config, PolicyConfig):
            policy_config = ckpt.plain_config(policy_config)
        self.policy_config = dict(policy_config or {})
        self.observation_layout = observation_layout
        kwargs["ortho_init"] = False  # our own init (DART's zero init) happens in ActorCritic
        super().__init__(observation_space, action_space, lr_schedule, **kwargs)

    def _build(self, lr_schedule) -> None:
        spec = {"obs_dim": int(np.prod(self.observation_space.shape)),
                "action_dim": int(np.prod(self.action_space.shape)),
                "layout": self.observation_layout,
                "config": {**ckpt.plain_config(PolicyConfig()), **self.policy_config}}
        self.net = ActorCritic.from_spec(spec)
        self.optimizer = self.optimizer_class(self.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs)

    def _get_constructor_parameters(self) -> dict[str, Any]:
        data = super()._get_constructor_parameters()
        data.update(policy_config=self.policy_config, observation_layout=self.observation_layout)
        return data

    @property
    def log_std(self) -> torch.Tensor:
        """(1, A) clamped log-std; SB3 logs ``train/std`` from it."""
        return self.net.log_std

    def forward(self, obs: torch.Tensor, deterministic: bool = False):
        """SB3's rollout call: sampled action, value (B, 1) and log-probability from our actor-critic."""
        step = self.net.act(obs.float(), deterministic)
        return step.action, step.value[:, None], step.log_prob

    def evaluate_actions(self, obs: torch.Tensor, actions: torch.Tensor):
        """SB3's loss inputs: value (B, 1), log-probability and entropy of the stored actions."""
        out = self.net.evaluate(obs.float(), actions)
        return out.value[:, None], out.log_prob, out.entropy

    def predict_values(self, obs: torch.Tensor) -> torch.Tensor:
        """Value (B, 1), for SB3's bootstrap at the end of a rollout."""
        return self.net.value(obs.float())[:, None]

    def get_distribution(self, obs: torch.Tensor):
        """SB3's Gaussian action distribution built from our mean and log standard deviation."""
        out = self.net(obs.float())
        return self.action_dist.proba_distribution(out.mean, out.log_std)

    def _predict(self, observation: torch.Tensor, deterministic: bool = False) -> torch.Tensor:
        return self.net.act(observation.float(), deterministic).action


# --------------------------------------------------------------------------- config mapping
class IterationLinearSchedule:
    """SB3 schedule reproducing the native annealing ``lr_k = (1 - k / K) lr_0`` of iteration k.

    SB3 calls it with ``progress_remaining = 1 - steps / total_steps`` after collecting iteration k
    (steps = (k + 1) * batch), so k is recovered from the progress.
    """

    def __init__(self, lr: float, total_steps: int, batch_size: int, num_iterations: int):
        self.lr, self.total, self.batch, self.iterations = lr, total_steps, batch_size, num_iterations

    def __call__(self, progress_remaining: float) -> float:
        """The learning rate SB3 asks for at ``progress_remaining``: iteration k's linear anneal."""
        k = round((1.0 - progress_remaining) * self.total / self.batch) - 1
        return self.lr * (1.0 - max(k, 0) / self.iterations)


def sb3_ppo_kwargs(ppo: PPOConfig, policy: PolicyConfig, plan: BatchPlan,
                   layout: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Keyword arguments for ``stable_baselines3.PPO(LatentActorCriticPolicy, venv, **kwargs)``."""
    # SB3's progress counts to num_iterations * batch (learn() asks for whole iterations), on resume too
    lr = (IterationLinearSchedule(ppo.learning_rate, plan.num_iterations * plan.batch_size, plan.batch_size,
                                  plan.num_iterations)
          if ppo.anneal_lr else ppo.learning_rate)
    return dict(
        learning_rate=lr, n_steps=ppo.num_steps, batch_size=plan.minibatch_size, n_epochs=ppo.update_epochs,
        gamma=ppo.gamma, gae_lambda=ppo.gae_lambda, clip_range=ppo.clip_coef,
        clip_range_vf=ppo.clip_coef if ppo.clip_vloss else None, normalize_advantage=ppo.norm_adv,
        ent_coef=ppo.ent_coef,
        vf_coef=0.5 * ppo.vf_coef,  # CleanRL/DART weigh 0.5 * MSE by vf_coef; SB3 weighs the MSE itself
        max_grad_norm=ppo.max_grad_norm, target_kl=ppo.target_kl, stats_window_size=ppo.stats_window,
        seed=ppo.seed, device=ppo.device, verbose=0,
        policy_kwargs=dict(policy_config=ckpt.plain_config(policy), observation_layout=layout,
                           optimizer_kwargs=adam_kwargs(ppo)),
    )


# --------------------------------------------------------------------------- logging bridge
class MonitorOutput(KVWriter):
    """SB3 logger output that writes through our :class:`Monitor` (same events file, same step axis)."""

    def __init__(self, monitor: Monitor):
        self.monitor = monitor
        self.latest: dict[str, Any] = {}

    def write(self, key_values: dict[str, Any], key_excluded: dict[str, Any], step: int = 0) -> None:
        """Keep SB3's latest values and write them through the monitor."""
        self.latest.update(key_values)
        self.monitor.log_sb3(step, key_values, key_excluded)

    def close(self) -> None:
        """Nothing to release: the monitor belongs to the runner, which closes it."""
        pass


class _TrainingHooks(BaseCallback):
    """Per-iteration bookkeeping of :class:`Sb3Trainer`; an iteration ends when the next rollout starts."""

    def __init__(self, trainer: Sb3Trainer):
        super().__init__(verbose=0)
        self.trainer = trainer
        self.rollout_start: float | None = None
        self.rollout_end: float | None = None
        self.collection_s = 0.0
        self.term_sums: dict[str, float] = {}
        self.term_count = 0
        self.diverged: int | None = 0 if getattr(trainer.env, "reports_diverged", False) else None
        """Env steps with ``diverged`` infos this rollout (None: the VecEnv does not report them)."""
        self.moments: tuple[torch.Tensor, torch.Tensor, int] | None = None
        self.weights = {REWARD_PREFIX + k: v for k, v in (reward_weights(trainer.env) or {}).items()}
        self.running: dict[str, np.ndarray] = {}
        """``reward/<term>`` -> (N,) weighted sum so far of each env's current episode."""
        self.episode_sums: dict[str, float] = {}
        self.episodes_ended = 0
        self.actions: list[np.ndarray] = []

    def _on_training_start(self) -> None:
        self.trainer._on_training_start()

    def _on_rollout_start(self) -> None:
        now = time.perf_counter()
        if self.rollout_end is not None:
            self._finish_iteration(now - self.rollout_end)
        self.rollout_start = time.perf_counter()

    def _on_step(self) -> bool:
        self._check_finite()
        infos, dones = self.locals["infos"], np.asarray(self.locals["dones"], dtype=bool)
        for i, info in enumerate(infos):
            for key, value in info.items():
                if key.startswith(REWARD_PREFIX):
                    self.term_sums[key] = self.term_sums.get(key, 0.0) + float(value)
                    if key in self.weights:
                        running = self.running.setdefault(key, np.zeros(len(infos)))
                        running[i] += self.weights[key] * float(value)
            if self.diverged is not None and info.get(DIVERGED):
                self.diverged += 1
        if dones.any():  # the step that ends an episode belongs to it; the next one starts from zero
            self.episodes_ended += int(dones.sum())
            for key, running in self.running.items():
                self.episode_sums[key] = self.episode_sums.get(key, 0.0) + float(running[dones].sum())
                running[dones] = 0.0
        if self.locals.get("clipped_actions") is not None:  # what SB3 sent to the env
            self.actions.append(np.array(self.locals["clipped_actions"], dtype=np.float32))
        self.term_count += len(infos)
        return not self.trainer.stop_requested  # False aborts PPO.learn (an evaluation asked to stop)

    def _check_finite(self) -> None:
        """Stop on a NaN/inf observation or reward the env just returned, naming the env."""
        for name, key in (("observation", "new_obs"), ("reward", "rewards")):
            value = np.asarray(self.locals[key])
            bad = ~np.isfinite(value.reshape(len(value), -1)).all(-1)
            if bad.any():
                n = int(np.flatnonzero(bad)[0])
                row = value[n].reshape(-1)
                step = self.model.rollout_buffer.pos  # the step being collected (stored after this callback)
                when = "returned by" if name == "observation" else "at"
                stop_if_nonfinite(self.trainer, self.trainer.bar,
                                  f"{name} of env {n} {when} rollout step {step} is {row[~np.isfinite(row)][0]}",
                                  ROLLOUT_HINT)

    def _on_rollout_end(self) -> None:
        self.rollout_end = time.perf_counter()
        self.collection_s = self.rollout_end - self.rollout_start
        if self.trainer.policy.obs_normalizer is not None:
            obs = torch.from_numpy(np.asarray(self.model.rollout_buffer.observations, dtype=np.float32))
            flat = obs.reshape(-1, obs.shape[-1])
            self.moments = (flat.mean(0), flat.var(0, unbiased=False), flat.shape[0])

    def _on_training_end(self) -> None:
        if self.rollout_end is not None:
            self._finish_iteration(time.perf_counter() - self.rollout_end)

    def _finish_iteration(self, update_s: float) -> None:
        if self.moments is not None:  # fold the rollout into the normalizer after its update, as natively
            self.trainer.policy.obs_normalizer.update_from_moments(*self.moments)
            self.moments = None
        terms = {k.removeprefix(REWARD_PREFIX): v / max(self.term_count, 1) for k, v in self.term_sums.items()}
        self.term_sums, self.term_count = {}, 0
        diverged, self.diverged = self.diverged, None if self.diverged is None else 0
        episodes = {k.removeprefix(REWARD_PREFIX): v / self.episodes_ended for k, v in self.episode_sums.items()
                    } if self.episodes_ended else {}
        self.episode_sums, self.episodes_ended = {}, 0
        actions = action_magnitude(np.stack(self.actions)) if self.actions else None
        self.actions = []
        self.trainer._after_iteration(terms, self.collection_s, update_s, diverged, episodes, actions)
        self.rollout_end = None


# --------------------------------------------------------------------------- trainer
class Sb3Trainer(Runner):
    """``stable_baselines3.PPO`` on an SB3 ``VecEnv`` with the native trainer's config, tags and checkpoints.

    Args are those of :class:`latentrl.ppo.runner.Runner`, with ``env`` an SB3 ``VecEnv`` (e.g.
    ``latentrl.envs.Sb3VecEnv(env)``).
    """

    name = "sb3"
    checkpoint_suffixes = (SB3_ZIP_SUFFIX,)

    def build(self, policy_cfg: PolicyConfig, layout: Mapping[str, Any] | None) -> None:
        """SB3's PPO with our actor-critic policy on this env."""
        from stable_baselines3 import PPO

        kwargs = sb3_ppo_kwargs(self.cfg, policy_cfg, self.plan, plain_layout(observation_layout(self.env, layout)))
        self.model = PPO(LatentActorCriticPolicy, self.env, **kwargs)
        self.policy: ActorCritic = self.model.policy.net
        self.optimizer = self.model.policy.optimizer

    @property
    def venv(self) -> Any:
        """The SB3 ``VecEnv`` trained on (the runner's ``env``)."""
        return self.env

    # ------------------------------------------------------------------ checkpoints
    def checkpoint_extra(self) -> dict:
        """SB3's step and update counters, so a resumed run continues its schedule."""
        return {"num_timesteps": self.env_steps, "n_updates": int(self.model._n_updates)}

    def load_extra(self, extra: Mapping[str, Any]) -> None:
        """Put back SB3's step and update counters."""
        self.model.num_timesteps = extra["num_timesteps"]
        self.model._n_updates = extra["n_updates"]

    def after_save(self, path: Path) -> None:
        """SB3's own zip (``PPO.load``-able) beside our checkpoint, as ``*.sb3.zip``."""
        buf = io.BytesIO()
        self.model.save(buf)
        atomic_write_bytes(path.with_suffix(SB3_ZIP_SUFFIX), buf.getvalue())

    # ------------------------------------------------------------------ loop
    def learn(self) -> None:
        """``PPO.learn`` up to ``plan.num_iterations`` iterations (SB3 resets the env)."""
        self.output = MonitorOutput(self.monitor)
        self.model.set_logger(Logger(str(self.run_dir), [self.output]))
        self.env.seed(self.cfg.seed + self.iteration)
        remaining = self.plan.num_iterations * self.plan.batch_size - self.env_steps
        if remaining > 0:
            self.model.learn(remaining, callback=_TrainingHooks(self), log_interval=self.cfg.log_every,
                             reset_num_timesteps=self.iteration == 0)

    def _on_training_start(self) -> None:
        """After SB3 reset the env: restore the random streams of a resumed run; start the clocks."""
        self.restore_pending_rng()
        self.restart_clock()

    def rollout_stats(self) -> RolloutStats:
        """Episode statistics from SB3's episode-info and success buffers."""
        eps, succ = self.model.ep_info_buffer or [], self.model.ep_success_buffer or []
        return RolloutStats(float(np.mean([e["r"] for e in eps])) if eps else None,
                            float(np.mean([e["l"] for e in eps])) if eps else None,
                            float(np.mean(succ)) if succ else None, len(eps))

    def _after_iteration(self, reward_terms: dict[str, float], collection_s: float, update_s: float,
                         diverged: int | None = None, episode_terms: Mapping[str, float] | None = None,
                         actions: tuple[float, float] | None = None) -> None:
        """Called after each PPO update: SB3's train/* dump, our extra tags, then the runner's eval and checkpoint."""
        recorded = {k[len(TRAIN_PREFIX):]: v for k, v in self.model.logger.name_to_value.items()
                    if k.startswith(TRAIN_PREFIX) and isinstance(v, (int, float, np.floating, np.integer))}
        stop_if_nonfinite(self, self.bar, nonfinite_update(recorded, self.policy))
        fps = self.count_iteration(int(self.model.num_timesteps), collection_s, update_s)
        k, step, logging = self.iteration, self.env_steps, self.logging_now
        if logging:
            self.model.logger.dump(step=step)  # the train/* SB3 recorded during this iteration's update
        else:
            _clear(self.model.logger)
        self.last_train = {k_[len(TRAIN_PREFIX):]: float(v) for k_, v in self.output.latest.items()
                           if k_.startswith(TRAIN_PREFIX) and isinstance(v, (int, float, np.floating, np.integer))}
        rollout = self.rollout_stats()
        if logging:
            self.monitor.log_rewards(step, reward_terms)
            self.monitor.log_episode_rewards(step, episode_terms or {})
            self.monitor.log_actions(step, *(actions or (None, None)))
            self.monitor.log_diverged(step, diverged)
            self.monitor.log_time(step, collection_s=collection_s, update_s=update_s)
            self.bar.log_iteration(k, step, fps, rollout, self.last_train, collection_s, update_s, reward_terms,
                                   diverged)
        self.finish_iteration(fps, rollout)


def _clear(logger: Logger) -> None:
    """Drop what SB3 recorded since the last dump (an iteration that is not logged)."""
    logger.name_to_value.clear()
    logger.name_to_count.clear()
    logger.name_to_excluded.clear()
