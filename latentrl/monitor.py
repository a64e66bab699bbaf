"""TensorBoard writer of every training run: the only home of latentrl's tag scheme.

The x-axis of every scalar is **environment steps** (transitions summed over envs), as in SB3, so
native and SB3 runs overlay. Tags use SB3's names where SB3 has one:

==========================  ====================================================================
``rollout/ep_rew_mean``     mean return of the last ``stats_window`` finished episodes
``rollout/ep_len_mean``     mean length (env steps) of those episodes
``rollout/success_rate``    fraction of those episodes with ``is_success`` at their last step
``rollout/diverged``        env steps of the last rollout whose motion diverged (non-finite or absurd
                            joints; the env terminated and reset those envs), when the env reports it
``train/<stat>``            PPO update statistics: ``approx_kl``, ``clip_fraction``, ``entropy_loss``,
                            ``policy_gradient_loss``, ``value_loss``, ``loss``, ``explained_variance``,
                            ``std``, ``learning_rate``, ``clip_range`` (+ ``grad_norm``, ``epochs``
                            from the native trainer)
``time/fps``                env steps per second since the (re)start of this process
``time/collection_s``       seconds spent collecting the last rollout
``time/update_s``           seconds spent in the last PPO update
``reward/<term>``           rollout mean of each *unweighted* reward term (the env's ``reward/<term>`` infos)
``Episode_Reward/<term>``   mean over the episodes that ended in the rollout of each term's *weighted* sum over
                            the episode (rsl_rl/mjlab's name); the terms add up to those episodes' mean return
``action/norm_mean``        mean Euclidean norm of the actions sent to the env (the latent noise z)
``action/beyond_shell``     share of those actions with ``|z| > sqrt(d)``, outside the Gaussian shell of N(0, I_d)
                            (a policy that leaves the motion prior's noise distribution)
``eval/mean_reward``        periodic evaluation: mean return of its episodes (when the evaluator reports it)
``eval/<metric>``           periodic evaluation: ``success_rate``, ``reach_time_s``, ``skate_cm_s``, ``floor_cm``
``eval/trajectories``       top-down trajectory plot (image)
``eval/episode``            one rendered evaluation episode every ``eval.video_every`` evaluations (an animated GIF
                            image summary: TensorBoard's Images tab plays it)
``hyperparameters``         the resolved config as a markdown table (text)
``motion/<stage>/<term>``   motion-model training (``latentrl motion train``): each loss term of the
                            ``vae`` and ``denoiser`` stages, ``rollout_p`` and ``learning_rate``; x-axis: stage steps
==========================  ====================================================================
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NamedTuple

# --------------------------------------------------------------------------- the tag scheme
EP_REW_MEAN = "rollout/ep_rew_mean"
EP_LEN_MEAN = "rollout/ep_len_mean"
SUCCESS_RATE = "rollout/success_rate"
DIVERGED = "rollout/diverged"
TRAIN_PREFIX = "train/"
TRAIN_STATS = ("approx_kl", "clip_fraction", "entropy_loss", "policy_gradient_loss", "value_loss", "loss",
               "explained_variance", "std", "learning_rate", "clip_range")
"""Update statistics both trainers write (SB3's ``PPO.train`` names)."""
FPS = "time/fps"
COLLECTION_S = "time/collection_s"
UPDATE_S = "time/update_s"
REWARD_PREFIX = "reward/"
"""Prefix of reward-term tags, and of the env's per-step info keys they come from."""
EPISODE_REWARD_PREFIX = "Episode_Reward/"
"""Prefix of the weighted per-term episode sums (rsl_rl's and mjlab's tag)."""
ACTION_NORM = "action/norm_mean"
ACTION_BEYOND_SHELL = "action/beyond_shell"
EVAL_PREFIX = "eval/"
EVAL_METRICS = ("success_rate", "reach_time_s", "skate_cm_s", "floor_cm")
EVAL_MEAN_REWARD = "eval/mean_reward"
EVAL_TRAJECTORIES = "eval/trajectories"
EVAL_EPISODE = "eval/episode"
HPARAMS = "hyperparameters"
MOTION_PREFIX = "motion/"
"""Prefix of motion-model training tags: ``motion/<stage>/<term>``."""

SB3_ONLY_CONSOLE = ("time/iterations", "time/time_elapsed", "time/total_timesteps", "train/n_updates")
"""Keys SB3 records for its console table only (it excludes them from TensorBoard too)."""


def tag_for(kind: str, name: str) -> str:
    """The tag of a train/reward/eval scalar: ``tag_for('reward', 'skate') == 'reward/skate'``."""
    prefixes = {"train": TRAIN_PREFIX, "reward": REWARD_PREFIX, "eval": EVAL_PREFIX}
    return prefixes[kind] + name


class RolloutStats(NamedTuple):
    """Episode statistics over the last ``stats_window`` finished episodes (None: no episode yet)."""

    ep_rew_mean: float | None
    ep_len_mean: float | None
    success_rate: float | None
    episodes: int
    """How many episodes the means cover."""


class EpisodeVideo(NamedTuple):
    """A rendered episode for TensorBoard: an animated GIF and what it holds."""

    gif: bytes
    """The encoded GIF (TensorBoard's image plugin plays animated GIFs)."""
    width: int
    height: int
    frames: int
    fps: float


class EvalReport(NamedTuple):
    """What an evaluation hook returns to a trainer."""

    metrics: Mapping[str, float]
    """Metric name -> value, written as ``eval/<name>`` (see :data:`EVAL_METRICS`)."""
    figures: Mapping[str, Any] = {}
    """Tag -> matplotlib figure or (H, W, 3) uint8 image, e.g. ``{EVAL_TRAJECTORIES: fig}``."""
    stop: bool = False
    """Ask the trainer to end the run after this evaluation (e.g. a benchmark's success >= 0.9)."""
    videos: Mapping[str, EpisodeVideo] = {}
    """Tag -> rendered episode, e.g. ``{EVAL_EPISODE: video}`` (written as an animated GIF image)."""


class Monitor:
    """A ``SummaryWriter`` in ``log_dir`` that only knows the tags above.

    Args:
        log_dir: folder of the events file (the run directory).
        resume_step: env step of the checkpoint a resumed run starts from; events that the killed
            run wrote *after* it are hidden (TensorBoard's purge), so curves do not double back.
    """

    def __init__(self, log_dir: str | Path, resume_step: int | None = None):
        from torch.utils.tensorboard import SummaryWriter

        self.log_dir = Path(log_dir)
        purge = None if resume_step is None else int(resume_step) + 1
        self.writer = SummaryWriter(str(self.log_dir), purge_step=purge)

    def _scalar(self, tag: str, value: Any, step: int) -> None:
        if value is not None:
            self.writer.add_scalar(tag, float(value), int(step))

    def log_rollout(self, step: int, stats: RolloutStats, diverged: int | None = None) -> None:
        """``rollout/*`` means and the rollout's diverged count; a None writes nothing, as in SB3."""
        self._scalar(EP_REW_MEAN, stats.ep_rew_mean, step)
        self._scalar(EP_LEN_MEAN, stats.ep_len_mean, step)
        self._scalar(SUCCESS_RATE, stats.success_rate, step)
        self.log_diverged(step, diverged)

    def log_diverged(self, step: int, diverged: int | None) -> None:
        """``rollout/diverged``: env steps of the last rollout whose motion diverged (None writes nothing)."""
        self._scalar(DIVERGED, diverged, step)

    def log_train(self, step: int, stats: Mapping[str, float]) -> None:
        """Every update statistic as ``train/<name>``."""
        for name, value in stats.items():
            self._scalar(tag_for("train", name), value, step)

    def log_rewards(self, step: int, terms: Mapping[str, float]) -> None:
        """Rollout means of the unweighted reward terms as ``reward/<term>`` (names without the prefix)."""
        for name, value in terms.items():
            self._scalar(tag_for("reward", name.removeprefix(REWARD_PREFIX)), value, step)

    def log_episode_rewards(self, step: int, terms: Mapping[str, float]) -> None:
        """Weighted per-term episode sums as ``Episode_Reward/<term>`` (names without a prefix)."""
        for name, value in terms.items():
            self._scalar(EPISODE_REWARD_PREFIX + name.removeprefix(REWARD_PREFIX), value, step)

    def log_actions(self, step: int, norm_mean: float | None, beyond_shell: float | None) -> None:
        """``action/norm_mean`` and ``action/beyond_shell`` of a rollout's actions (None writes nothing)."""
        self._scalar(ACTION_NORM, norm_mean, step)
        self._scalar(ACTION_BEYOND_SHELL, beyond_shell, step)

    def log_time(self, step: int, fps: float | None = None, collection_s: float | None = None,
                 update_s: float | None = None) -> None:
        """Throughput and wall seconds of collection and update, each logged only when given."""
        self._scalar(FPS, fps, step)
        self._scalar(COLLECTION_S, collection_s, step)
        self._scalar(UPDATE_S, update_s, step)

    def log_eval(self, step: int, report: EvalReport | Mapping[str, float]) -> None:
        """``eval/<metric>`` scalars and any figures of an :class:`EvalReport` (or a plain metrics mapping)."""
        metrics = report.metrics if isinstance(report, EvalReport) else report
        for name, value in metrics.items():
            self._scalar(tag_for("eval", name), value, step)
        for tag, fig in (report.figures if isinstance(report, EvalReport) else {}).items():
            self.log_figure(tag, fig, step)
        for tag, video in (report.videos if isinstance(report, EvalReport) else {}).items():
            self.log_video(tag, video, step)

    def log_sb3(self, step: int, key_values: Mapping[str, Any], excluded: Mapping[str, Any] | None = None) -> None:
        """Scalars recorded by SB3's logger (its names are our names); non-scalars and console-only keys are skipped."""
        excluded = excluded or {}
        for key, value in key_values.items():
            skip = excluded.get(key) or ()
            if key in SB3_ONLY_CONSOLE or "tensorboard" in (skip if isinstance(skip, tuple) else (skip,)):
                continue
            try:
                self._scalar(key, float(value), step)
            except (TypeError, ValueError):
                continue  # SB3 Figure/Video/HParam objects: not part of our scheme

    def log_motion_stage(self, stage: str, step: int, terms: Mapping[str, Any]) -> None:
        """``motion/<stage>/<term>`` scalars of a motion-training stage (tensors or numbers)."""
        for name, value in terms.items():
            value = value.detach() if hasattr(value, "detach") else value
            self._scalar(f"{MOTION_PREFIX}{stage}/{name}", float(value), step)

    def log_hparams(self, config: Mapping[str, Any]) -> None:
        """The (nested) config as a markdown ``| parameter | value |`` table under ``hyperparameters``."""
        rows = [f"|{key}|{_cell(value)}|" for key, value in _flatten(config)]
        self.writer.add_text(HPARAMS, "|parameter|value|\n|-|-|\n" + "\n".join(rows), 0)

    def log_figure(self, tag: str, fig: Any, step: int) -> None:
        """A matplotlib figure (closed after writing) or an (H, W, 3) uint8 image."""
        if hasattr(fig, "savefig"):
            self.writer.add_figure(tag, fig, int(step), close=True)
        else:
            self.writer.add_image(tag, fig, int(step), dataformats="HWC")

    def log_video(self, tag: str, video: EpisodeVideo, step: int) -> None:
        """An animated GIF as an image summary: what ``SummaryWriter.add_video`` writes, without moviepy.

        ``add_video`` encodes its GIF with moviepy (not a dependency); the summary it writes is an image
        whose encoded bytes are a GIF, which is what this writes from the GIF :mod:`latentrl.render` made.
        """
        from tensorboard.compat.proto.summary_pb2 import Summary

        image = Summary.Image(height=int(video.height), width=int(video.width), colorspace=3,
                              encoded_image_string=bytes(video.gif))
        self.writer._get_file_writer().add_summary(Summary(value=[Summary.Value(tag=tag, image=image)]), int(step))

    def flush(self) -> None:
        """Push pending events to disk, so a running TensorBoard sees them."""
        self.writer.flush()

    def close(self) -> None:
        """Flush and close the events file."""
        self.writer.close()


def _flatten(tree: Mapping[str, Any], prefix: str = "") -> list[tuple[str, Any]]:
    out: list[tuple[str, Any]] = []
    for key, value in tree.items():
        if isinstance(value, Mapping):
            out.extend(_flatten(value, f"{prefix}{key}."))
        else:
            out.append((f"{prefix}{key}", value))
    return out


def _cell(value: Any) -> str:
    text = value if isinstance(value, str) else json.dumps(value, default=str)
    return text.replace("|", "\\|")
