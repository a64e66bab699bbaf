"""Episode statistics and reward-term means gathered on the device during collection.

:meth:`EpisodeRecorder.record` only copies tensors (no host sync inside the step loop);
:meth:`EpisodeRecorder.summarize` moves everything to the host once per rollout and keeps SB3's
rolling window of the last ``window`` finished episodes, so ``rollout/ep_rew_mean`` means the same
thing in native and SB3 runs.

Env info keys read: ``episode``, ``is_success``, ``reward/<term>`` and ``diverged``, as
:mod:`latentrl.ppo.contract` describes them.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from typing import Any, NamedTuple

import torch

from latentrl.monitor import REWARD_PREFIX, RolloutStats
from latentrl.ppo.contract import DIVERGED, EPISODE, IS_SUCCESS
from latentrl.ppo.distributed import SINGLE, Collective


class RolloutSummary(NamedTuple):
    """What one rollout reports to the log: window statistics, reward-term means, episode and divergence counts."""
    stats: RolloutStats
    """Means over the rolling window of finished episodes."""
    reward_terms: dict[str, float]
    """Term name (without ``reward/``) -> mean over the rollout's T * N steps."""
    episodes: int
    """Episodes that ended during this rollout."""
    diverged: int | None = None
    """Env steps of this rollout whose motion diverged (None: the env does not report ``diverged``)."""
    episode_terms: dict[str, float] = {}
    """Term name -> weighted sum over an episode, averaged over the episodes that ended in this rollout
    (empty without reward weights or without an ended episode): ``Episode_Reward/<term>``."""


class EpisodeRecorder:
    """(T, N) device buffers of episode ends, returns, lengths and successes, plus per-term reward sums.

    ``reward_weights`` (term name -> weight, :func:`latentrl.ppo.contract.reward_weights`): also keep
    each env's running weighted sum of every term and fold it in when its episode ends.
    """

    def __init__(self, num_steps: int, num_envs: int, device: str | torch.device = "cpu", window: int = 100,
                 reward_weights: Mapping[str, float] | None = None):
        T, N, dev = num_steps, num_envs, torch.device(device)
        self.num_steps, self.num_envs, self.device = T, N, dev
        self.ended = torch.zeros(T, N, dtype=torch.bool, device=dev)
        self.returns = torch.zeros(T, N, device=dev)
        self.lengths = torch.zeros(T, N, device=dev)
        self.success = torch.zeros(T, N, dtype=torch.bool, device=dev)
        self.has_success = False
        self.term_sums: dict[str, torch.Tensor] = {}
        self.weights = {REWARD_PREFIX + k: float(v) for k, v in (reward_weights or {}).items()}
        self.running: dict[str, torch.Tensor] = {}
        """``reward/<term>`` -> (N,) weighted sum so far of each env's current episode."""
        self.ended_sums: dict[str, torch.Tensor] = {}
        """``reward/<term>`` -> weighted sums of the episodes that ended in this rollout, added up."""
        self.diverged: torch.Tensor | None = None
        self.window_returns: deque[float] = deque(maxlen=window)
        self.window_lengths: deque[float] = deque(maxlen=window)
        self.window_success: deque[float] = deque(maxlen=window)

    def _put(self, dst: torch.Tensor, src: Any) -> None:
        dst.copy_(torch.as_tensor(src, device=self.device))

    def record(self, t: int, infos: Mapping[str, Any]) -> None:
        """Copy step ``t``'s episode ends, success flags and reward terms (no host sync)."""
        if f"_{EPISODE}" in infos:
            self._put(self.ended[t], infos[f"_{EPISODE}"])
            self._put(self.returns[t], infos[EPISODE]["r"])
            self._put(self.lengths[t], infos[EPISODE]["l"])
        else:
            self.ended[t].zero_()
        if IS_SUCCESS in infos:
            self._put(self.success[t], infos[IS_SUCCESS])
            self.has_success = True
        if DIVERGED in infos:
            count = torch.as_tensor(infos[DIVERGED], device=self.device).sum()
            self.diverged = count if self.diverged is None else self.diverged + count
        for key, value in infos.items():
            if key.startswith(REWARD_PREFIX):
                value = torch.as_tensor(value, device=self.device).float()
                total = value.sum()
                self.term_sums[key] = self.term_sums[key] + total if key in self.term_sums else total
                if key in self.weights:
                    weighted = self.weights[key] * value
                    self.running[key] = self.running[key] + weighted if key in self.running else weighted
        if self.running:  # the step that ends an episode belongs to it; the next one starts from zero
            ended = self.ended[t].float()
            for key, running in self.running.items():
                done = (running * ended).sum()
                self.ended_sums[key] = self.ended_sums[key] + done if key in self.ended_sums else done
                self.running[key] = running * (1.0 - ended)

    def summarize(self, collective: Collective = SINGLE) -> RolloutSummary:
        """One host transfer: extend the rolling window, average the reward terms, reset the sums.

        With several ranks every rank's finished episodes join the window (in rank order), reward-term
        means are averaged over ranks and diverged steps summed (one ``all_gather_object``).
        """
        ended = self.ended
        names = list(self.term_sums)
        sums = torch.stack([self.term_sums[k] for k in names]).tolist() if names else []
        done_names = list(self.ended_sums)
        done_sums = torch.stack([self.ended_sums[k] for k in done_names]).tolist() if done_names else []
        local = (self.returns[ended].tolist(), self.lengths[ended].tolist(),
                 self.success[ended].float().tolist() if self.has_success else [], dict(zip(names, sums)),
                 ended.numel(), None if self.diverged is None else int(self.diverged), dict(zip(done_names, done_sums)))
        self.term_sums, self.diverged, self.ended_sums = {}, None, {}
        ranks = collective.gather(local)
        term_sums: dict[str, float] = {}
        episode_sums: dict[str, float] = {}
        steps, episodes, diverged = 0, 0, None
        for returns, lengths, success, terms, numel, div, done in ranks:
            for k, v in done.items():
                episode_sums[k] = episode_sums.get(k, 0.0) + v
            self.window_returns.extend(returns)
            self.window_lengths.extend(lengths)
            self.window_success.extend(success)
            for k, v in terms.items():
                term_sums[k] = term_sums.get(k, 0.0) + v
            steps, episodes = steps + numel, episodes + len(returns)
            if div is not None:
                diverged = (diverged or 0) + div
        means = {k.removeprefix(REWARD_PREFIX): v / steps for k, v in term_sums.items()}
        per_episode = {k.removeprefix(REWARD_PREFIX): v / episodes for k, v in episode_sums.items()} if episodes else {}
        return RolloutSummary(self.stats(), means, episodes, diverged, per_episode)

    def stats(self) -> RolloutStats:
        """Mean return, length and success over the rolling window of finished episodes."""
        def mean(values: deque[float]) -> float | None:
            return sum(values) / len(values) if values else None

        return RolloutStats(mean(self.window_returns), mean(self.window_lengths), mean(self.window_success),
                            len(self.window_returns))
