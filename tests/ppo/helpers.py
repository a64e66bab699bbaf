"""Reading TensorBoard events back, as a user's TensorBoard would."""

from __future__ import annotations

from pathlib import Path

SB3_SCALARS = ("rollout/ep_rew_mean", "rollout/ep_len_mean", "rollout/success_rate", "train/approx_kl",
               "train/clip_fraction", "train/entropy_loss", "train/policy_gradient_loss", "train/value_loss",
               "train/explained_variance", "train/std", "train/learning_rate", "time/fps")
OUR_SCALARS = ("time/collection_s", "time/update_s", "reward/dist", "reward/success", "reward/effort")


def scalars(run_dir: Path) -> dict[str, list[tuple[int, float]]]:
    """Tag -> [(step, value)] of every scalar in the run's events files."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(run_dir), size_guidance={"scalars": 0, "images": 0, "tensors": 0})
    acc.Reload()
    return {tag: [(e.step, e.value) for e in acc.Scalars(tag)] for tag in acc.Tags()["scalars"]}


def tags(run_dir: Path) -> dict[str, list[str]]:
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    acc = EventAccumulator(str(run_dir), size_guidance={"scalars": 0, "images": 0, "tensors": 0})
    acc.Reload()
    return acc.Tags()
