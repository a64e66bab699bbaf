"""The ``policy:`` and ``ppo:`` sections of a training config.

Both are plain dataclasses whose fields carry their docstrings (units, DART's value); YAML files
hold only values and :func:`latentrl.config.load_config` merges them with type checks. The lead's
``TrainConfig`` nests them as ``policy: PolicyConfig`` and ``ppo: PPOConfig``, so one YAML reads::

    ppo:
      learning_rate: 3.0e-4
      num_steps: 32
    policy:
      architecture: dart
      latent_dim: 512

Derived sizes (batch, minibatch, iterations) depend on the env's ``num_envs`` and are computed in
one place, :meth:`PPOConfig.plan`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

from latentrl.config import require, require_seed

ARCHITECTURES = ("dart", "mlp")


MAX_WIDTH = 16_384
"""Layer widths of the policy, at most (a 16k x 16k layer is already 1 GiB of weights)."""
MAX_BLOCKS = 64
"""Residual blocks or MLP layers, at most."""


@dataclass
class PolicyConfig:
    """The actor-critic network (see :class:`latentrl.ppo.policy.ActorCritic`)."""

    architecture: str = "dart"
    """'dart': per-group encoders -> shared embedding -> residual actor and critic heads
    (DART's ``PolicyReachLocationMLP``); 'mlp': separate plain MLPs on the whole observation."""
    latent_dim: int = 512
    """Width of the group encoders, the shared embedding and the residual blocks ('dart'). DART: 512."""
    n_blocks: int = 2
    """Residual blocks (each 2 Linear + LeakyReLU) in the actor and in the critic ('dart'). DART: 2."""
    mlp_hidden: list[int] = field(default_factory=lambda: [256, 256])
    """Hidden widths of the actor and of the critic MLP ('mlp' only)."""
    use_zero_init: bool = True
    """Zero the bias and scale the weight by 0.01 of every actor Linear layer, so the untrained policy
    samples ~N(0, I), the motion model's own prior. DART: True (all five actor layers)."""
    action_scale: float = 4.0
    """Action mean = ``action_scale * tanh(out)``; bounds the mean, not the samples. DART: 4."""
    log_std_init: float = 0.0
    """Initial value of the state-independent log standard deviation. DART: 0 (std 1)."""
    log_std_bounds: tuple[float, float] = (-1.0, 1.0)
    """The log-std is clamped to this [low, high] range in the forward pass. DART: (-1, 1)."""
    obs_norm: bool = False
    """Running mean/std observation normalization (stored in checkpoints, frozen in evaluation). DART: off."""
    obs_norm_clip: float = 10.0
    """Normalized observations are clipped to +/- this many standard deviations."""

    def validate(self) -> None:
        """Check every field once; a bad one raises a one-line ``ConfigError`` naming it."""
        require(self.architecture in ARCHITECTURES, "architecture",
                f"expected one of {ARCHITECTURES}, got '{self.architecture}'")
        require(0 < self.latent_dim <= MAX_WIDTH, "latent_dim", f"must lie in [1, {MAX_WIDTH}], got {self.latent_dim}")
        require(0 <= self.n_blocks <= MAX_BLOCKS, "n_blocks", f"must lie in [0, {MAX_BLOCKS}], got {self.n_blocks}")
        require(all(0 < w <= MAX_WIDTH for w in self.mlp_hidden) and len(self.mlp_hidden) <= MAX_BLOCKS,
                "mlp_hidden", f"at most {MAX_BLOCKS} widths, each in [1, {MAX_WIDTH}], got {self.mlp_hidden}")
        require(self.action_scale > 0, "action_scale", f"must be > 0, got {self.action_scale}")
        low, high = self.log_std_bounds
        require(low <= high, "log_std_bounds",
                f"expected [low, high] with low <= high, got {list(self.log_std_bounds)}")
        require(low <= self.log_std_init <= high, "log_std_init",
                f"{self.log_std_init} lies outside log_std_bounds {list(self.log_std_bounds)}")
        require(self.obs_norm_clip > 0, "obs_norm_clip", f"must be > 0, got {self.obs_norm_clip}")


class BatchPlan(NamedTuple):
    """Sizes derived from :class:`PPOConfig` and the env's ``num_envs``."""

    num_envs: int
    batch_size: int
    """Transitions per iteration: ``num_steps * num_envs``."""
    minibatch_size: int
    num_minibatches: int
    num_iterations: int
    """``ceil(total_steps / batch_size)``: the last iteration may overshoot ``total_steps``."""


@dataclass
class PPOConfig:
    """Proximal policy optimization settings shared by the native and the SB3 trainer."""

    total_steps: int = 200_000_000
    """Environment steps (transitions summed over envs) to train for. DART: 2e8 (24414 iterations)."""
    num_steps: int = 32
    """Steps per env per iteration (rollout length T). DART: 32. SB3: ``n_steps``."""
    num_minibatches: int = 8
    """Minibatches per epoch; ignored when ``minibatch_size`` is set. DART: 8 (minibatch 1024)."""
    minibatch_size: int | None = None
    """Transitions per minibatch; when set it overrides ``num_minibatches``. SB3: ``batch_size``."""
    update_epochs: int = 10
    """Passes over the rollout per iteration. DART: 10. SB3: ``n_epochs``."""
    learning_rate: float = 3e-4
    """Adam step size at the start of training. DART: 3e-4."""
    anneal_lr: bool = True
    """Decay the learning rate linearly to 0 over the run. DART: True."""
    adam_eps: float = 1e-5
    """Adam epsilon. DART and SB3: 1e-5."""
    gamma: float = 0.99
    """Discount per env step (one motion primitive, 8 frames). DART: 0.99."""
    gae_lambda: float = 0.95
    """GAE lambda. DART: 0.95."""
    bootstrap_truncated: bool = True
    """Add gamma * V(final_obs) to the reward of truncated (not terminated) steps. DART: False
    (its episodes all end at step 32 together, so it never needs it); SB3: True."""
    clip_coef: float = 0.2
    """PPO ratio clip epsilon (also the value clip range when ``clip_vloss``). DART: 0.2."""
    clip_vloss: bool = True
    """Clip the value update to +/- clip_coef around the rollout value (CleanRL's max form). DART: True."""
    norm_adv: bool = True
    """Normalize advantages per minibatch (zero mean, unit std). DART: True."""
    ent_coef: float = 0.0
    """Entropy bonus weight. DART: 0."""
    vf_coef: float = 0.5
    """Value loss weight on CleanRL's 0.5 * MSE. DART: 0.5."""
    max_grad_norm: float = 0.1
    """Global gradient-norm clip. DART: 0.1 (CleanRL's default 0.5)."""
    target_kl: float | None = None
    """Stop the epoch loop when a minibatch's approx-KL exceeds 1.5 * target_kl (SB3's rule). DART: None."""
    clip_actions: bool = False
    """Clamp sampled actions to the action-space bounds before ``env.step`` (the buffer keeps the
    unclamped sample). DART: False. The SB3 path always clamps (SB3's behaviour)."""
    seed: int = 1
    """Seed of python, numpy, torch and the env's first reset. DART: 1."""
    device: str = "cpu"
    """Torch device of the policy and the PPO buffers ('cpu', 'cuda', 'cuda:1'); should match the env's."""
    torch_deterministic: bool = True
    """Ask torch/cuDNN for deterministic kernels (``cudnn.deterministic``). DART: True."""
    stats_window: int = 100
    """``rollout/ep_rew_mean`` etc. average the last this-many finished episodes (SB3's window)."""
    log_every: int = 1
    """Iterations between TensorBoard writes and ``train.log`` lines."""
    checkpoint_every: int = 50
    """Iterations between ``checkpoints/iter_N.pt`` (0: only ``final.pt``). DART exported every 1000."""
    keep_checkpoints: int = 5
    """How many ``iter_N.pt`` files to keep, newest first (0 keeps all)."""
    eval_every: int = 0
    """Iterations between calls of the evaluation hook (0: never)."""
    init_from: str | None = None
    """Warm start: a trained policy (shipped name such as ``reach_walk_default``, or a checkpoint path) whose
    weights a fresh run starts from; observation fields it lacks start silent (:mod:`latentrl.ppo.warm_start`).
    A resumed run continues its own weights. DART: none."""

    def validate(self) -> None:
        """Check every field once; a bad one raises a one-line ``ConfigError`` naming it."""
        require(self.total_steps > 0, "total_steps", f"must be > 0, got {self.total_steps}")
        require(self.num_steps > 0, "num_steps", f"must be > 0, got {self.num_steps}")
        require(self.num_minibatches > 0, "num_minibatches", f"must be > 0, got {self.num_minibatches}")
        require(self.minibatch_size is None or self.minibatch_size > 0, "minibatch_size",
                f"must be > 0 or null, got {self.minibatch_size}")
        require(self.update_epochs > 0, "update_epochs", f"must be > 0, got {self.update_epochs}")
        require(self.learning_rate > 0, "learning_rate", f"must be > 0, got {self.learning_rate}")
        require(self.adam_eps > 0, "adam_eps", f"must be > 0, got {self.adam_eps}")
        require(0.0 <= self.gamma <= 1.0, "gamma", f"must lie in [0, 1], got {self.gamma}")
        require(0.0 <= self.gae_lambda <= 1.0, "gae_lambda", f"must lie in [0, 1], got {self.gae_lambda}")
        require(self.clip_coef > 0, "clip_coef", f"must be > 0, got {self.clip_coef}")
        require(self.ent_coef >= 0, "ent_coef", f"must be >= 0, got {self.ent_coef}")
        require(self.vf_coef >= 0, "vf_coef", f"must be >= 0, got {self.vf_coef}")
        require(self.max_grad_norm > 0, "max_grad_norm", f"must be > 0, got {self.max_grad_norm}")
        require(self.target_kl is None or self.target_kl > 0, "target_kl", f"must be > 0 or null, got {self.target_kl}")
        require(self.stats_window > 0, "stats_window", f"must be > 0, got {self.stats_window}")
        require(self.log_every > 0, "log_every", f"must be > 0, got {self.log_every}")
        require(self.checkpoint_every >= 0, "checkpoint_every", f"must be >= 0, got {self.checkpoint_every}")
        require(self.keep_checkpoints >= 0, "keep_checkpoints", f"must be >= 0, got {self.keep_checkpoints}")
        require(self.eval_every >= 0, "eval_every", f"must be >= 0, got {self.eval_every}")
        require(self.num_steps <= MAX_NUM_STEPS, "num_steps", f"must be <= {MAX_NUM_STEPS}, got {self.num_steps}")
        require_seed(self.seed)

    def plan(self, num_envs: int) -> BatchPlan:
        """Batch, minibatch and iteration counts for ``num_envs`` envs; raises ``ConfigError`` if they don't fit."""
        require(num_envs > 0, "num_envs", f"must be > 0, got {num_envs}")
        batch = self.num_steps * num_envs
        require(batch <= MAX_BATCH, "num_steps", f"the batch num_steps * num_envs = {self.num_steps} * {num_envs} = "
                f"{batch} exceeds {MAX_BATCH} transitions; lower ppo.num_steps or env.num_envs")
        if self.minibatch_size is not None:
            mb = self.minibatch_size
            if batch % mb:  # the hint is computed only on failure (it factors the batch)
                require(False, "minibatch_size", f"{mb} does not divide the batch num_steps * num_envs = "
                        f"{self.num_steps} * {num_envs} = {batch}; try {_nearest_divisor(batch, mb)}")
        else:
            n = self.num_minibatches
            if batch % n:
                require(False, "num_minibatches", f"{n} does not divide the batch num_steps * num_envs = "
                        f"{self.num_steps} * {num_envs} = {batch}; try {_nearest_divisor(batch, n)}")
            mb = batch // n
        iterations = -(-self.total_steps // batch)
        return BatchPlan(num_envs, batch, mb, batch // mb, iterations)


MAX_NUM_STEPS = 100_000
"""Rollout steps per env per iteration, at most."""
MAX_BATCH = 2**26
"""Transitions per PPO batch (num_steps * num_envs), at most: 64 Mi already needs tens of GB."""


def _nearest_divisor(n: int, near: int) -> int:
    """The divisor of ``n`` closest to ``near``, found through the pairs (d, n // d) with d <= sqrt(n)."""
    divisors = set()
    d = 1
    while d * d <= n:
        if n % d == 0:
            divisors.update((d, n // d))
        d += 1
    return min(divisors, key=lambda x: (abs(x - near), x))
