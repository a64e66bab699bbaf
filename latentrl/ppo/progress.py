"""What a person watching a run sees: a tqdm bar over env steps and one ``train.log`` line per logged iteration."""

from __future__ import annotations

import os
import time
from collections.abc import Mapping
from pathlib import Path

from latentrl.monitor import RolloutStats
from latentrl.safe_io import open_no_follow

LOG_FILE = "train.log"
LINE_STATS = ("approx_kl", "clip_fraction", "value_loss", "policy_gradient_loss", "entropy_loss", "std",
              "explained_variance", "learning_rate")
"""Update statistics repeated in each ``train.log`` line (all of them are in TensorBoard)."""


class RunProgress:
    """Progress bar (env steps/s, success rate, mean return) plus the run's ``train.log``.

    Args:
        run_dir: the run directory; ``train.log`` is appended to, so a resumed run continues it.
        total_steps: env steps of the whole run (the bar's total).
        initial_steps: env steps already done (non-zero when resuming).
        enabled: show the bar (the log file is always written).
    """

    def __init__(self, run_dir: str | Path, total_steps: int, initial_steps: int = 0, enabled: bool = True):
        from tqdm import tqdm

        self.path = Path(run_dir) / LOG_FILE
        os.close(self._open())  # a linked or hard-linked train.log is refused before training starts
        self.bar = tqdm(total=total_steps, initial=initial_steps, unit="step", unit_scale=True,
                        desc="train", disable=not enabled, dynamic_ncols=True)

    def _open(self) -> int:
        """``train.log`` for appending, never through a symbolic link (``ConfigError`` naming it)."""
        return open_no_follow(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, "training log")

    def write(self, text: str) -> None:
        """Append one timestamped line to ``train.log``."""
        with os.fdopen(self._open(), "a", encoding="utf-8") as f:
            f.write(f"{time.strftime('%Y-%m-%d %H:%M:%S')} {text}\n")

    def update(self, env_steps: int, fps: float, rollout: RolloutStats) -> None:
        """Move the bar to ``env_steps`` and show throughput and episode statistics."""
        self.bar.update(env_steps - self.bar.n)
        post = {"steps/s": f"{fps:.0f}"}
        if rollout.success_rate is not None:
            post["success"] = f"{rollout.success_rate:.2f}"
        if rollout.ep_rew_mean is not None:
            post["return"] = f"{rollout.ep_rew_mean:.3g}"
        self.bar.set_postfix(post, refresh=False)

    def log_iteration(self, iteration: int, env_steps: int, fps: float, rollout: RolloutStats,
                      train: Mapping[str, float], collection_s: float, update_s: float,
                      reward_terms: Mapping[str, float] | None = None, diverged: int | None = None) -> None:
        """One ``train.log`` line: counters, throughput, episode stats, diverged steps, update stats, reward terms."""
        parts = [f"iter {iteration}", f"steps {env_steps}", f"fps {fps:.0f}",
                 f"collect_s {collection_s:.3f}", f"update_s {update_s:.3f}"]
        for name, value in (("ep_rew_mean", rollout.ep_rew_mean), ("ep_len_mean", rollout.ep_len_mean),
                            ("success_rate", rollout.success_rate)):
            if value is not None:
                parts.append(f"{name} {value:.4g}")
        if diverged is not None:
            parts.append(f"diverged {diverged}")
        parts += [f"{k} {float(train[k]):.4g}" for k in LINE_STATS if k in train]
        parts += [f"reward/{k} {v:.4g}" for k, v in (reward_terms or {}).items()]
        self.write(" | ".join(parts))

    def close(self) -> None:
        """Close the progress bar (``train.log`` is opened per line and needs no closing)."""
        self.bar.close()
