"""Warm start (``ppo.init_from``): begin a training from a trained policy's weights.

Why: a new task is often an old one plus something (reach among obstacles = reach + rays). Starting from the
shipped reach policy spends the training on the new part instead of relearning to walk to a goal.

The new network may observe more than the old one. A new field that joins an old encoder group (``scene_rays``
joins ``scene``) gets zero input columns; a new group gets a fresh encoder whose columns in the shared embedding
are zero. Either way the warm-started policy acts exactly as the old one until training moves them. Every other
tensor must have the old shape. The observation normalizer is copied field by field (with new fields its count
restarts at :data:`WARM_COUNT` at most). Architecture, widths and field sizes must match; anything else is
refused in one line naming the file and the setting or tensor.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import torch

from latentrl.errors import CheckpointError
from latentrl.ppo.checkpoint import check_motion, read_checkpoint
from latentrl.ppo.policy import ActorCritic, group_of

WARM_COUNT = 10_000
"""With new observation fields, the normalizer's count restarts at most here (transitions), so the new fields'
statistics settle within a few iterations instead of being outweighed by the source's whole training."""

EMBEDDING = "trunk.embedding_encoder.layers.0.weight"
"""The shared embedding's first weight: its input columns are the group codes, ``latent_dim`` each."""


def _fields(layout: Mapping[str, Any] | None, obs_dim: int) -> dict[str, tuple[int, int]]:
    return {k: (int(v[0]), int(v[1])) for k, v in (layout or {"obs": (0, obs_dim)}).items()}


def _offsets(fields: Mapping[str, tuple[int, int]], names: list[str]) -> dict[str, tuple[int, int]]:
    """Field -> (offset, size) inside the concatenated input made of ``names``'s spans in observation order."""
    out, at = {}, 0
    for name in sorted(names, key=lambda k: fields[k][0]):
        a, b = fields[name]
        out[name] = (at, b - a)
        at += b - a
    return out


def _input_maps(old: dict[str, tuple[int, int]], new: dict[str, tuple[int, int]], groups_old: dict[str, list[str]],
                groups_new: dict[str, list[str]]) -> dict[str, list[tuple[int, int, int]]]:
    """Group -> ``(old_column, new_column, width)`` of each field its old and new encoder inputs share."""
    maps = {}
    for g, names in groups_new.items():
        if g not in groups_old:
            continue
        o, n = _offsets(old, groups_old[g]), _offsets(new, names)
        maps[g] = [(o[k][0], n[k][0], o[k][1]) for k in o]
    return maps


def _by_group(fields: Mapping[str, tuple[int, int]], architecture: str) -> dict[str, list[str]]:
    if architecture != "dart":
        return {"obs": list(fields)}
    groups: dict[str, list[str]] = {}
    for name in fields:
        groups.setdefault(group_of(name), []).append(name)
    return groups


def warm_start(policy: ActorCritic, path: str | Path, motion: Mapping[str, Any] | None = None,
               allow_motion_mismatch: bool = False) -> list[str]:
    """Load ``path``'s weights into ``policy`` (in place); return the observation fields that start fresh.

    Raises:
        CheckpointError: another architecture or motion model, a tensor of another shape, or a field the env lacks.
    """
    path = Path(path)
    state = read_checkpoint(path)
    check_motion(state, path, motion, allow_motion_mismatch)
    spec, cfg = state["policy_spec"], policy.cfg
    for field in ("architecture", "latent_dim", "n_blocks", "mlp_hidden", "obs_norm"):
        old_value, new_value = spec["config"].get(field), getattr(cfg, field)
        if isinstance(old_value, (list, tuple)):
            old_value, new_value = list(old_value), list(new_value)
        if old_value != new_value:
            raise CheckpointError(f"{path}: init_from policy has policy.{field} = {old_value!r}; this config has "
                                  f"{new_value!r} (they must match)")
    if int(spec["action_dim"]) != policy.action_dim:
        raise CheckpointError(f"{path}: init_from policy acts in {spec['action_dim']} dims; this env in "
                              f"{policy.action_dim}")
    old, new = _fields(spec.get("layout"), int(spec["obs_dim"])), _fields(policy.layout, policy.obs_dim)
    for name, (a, b) in old.items():
        if name not in new:
            raise CheckpointError(f"{path}: init_from policy observes '{name}', which this env does not have "
                                  f"(env fields: {', '.join(new)})")
        if new[name][1] - new[name][0] != b - a:
            raise CheckpointError(f"{path}: observation field '{name}' has {b - a} dims in the init_from policy "
                                  f"and {new[name][1] - new[name][0]} in this env")
    groups_old, groups_new = _by_group(old, cfg.architecture), _by_group(new, cfg.architecture)
    maps = _input_maps(old, new, groups_old, groups_new)
    inputs = _input_keys(cfg, groups_new)
    src, dst = state["policy"], policy.state_dict()
    with torch.no_grad():
        for key, target in dst.items():
            if any(key.startswith(f"trunk.{g}_encoder.") for g in groups_new if g not in groups_old):
                continue  # a new group: fresh encoder, silenced by its zero columns in the embedding
            if key not in src:
                raise CheckpointError(f"{path}: init_from policy has no tensor '{key}'")
            if key in inputs:
                target.zero_()
                for a, c, n in maps[inputs[key]]:
                    target[:, c:c + n] = src[key][:, a:a + n]
            elif key.startswith("obs_normalizer.") and target.dim() == 1:
                for name, (a, b) in old.items():
                    target[new[name][0]:new[name][0] + b - a] = src[key][a:b]
            elif key == "obs_normalizer.count" and len(new) > len(old):
                target.copy_(src[key].clamp(max=WARM_COUNT))
            elif key == EMBEDDING and cfg.architecture == "dart":
                target.zero_()
                width, order = cfg.latent_dim, list(groups_new)
                for i, g in enumerate(groups_old):
                    j = order.index(g)
                    target[:, j * width:(j + 1) * width] = src[key][:, i * width:(i + 1) * width]
            elif src[key].shape != target.shape:
                raise CheckpointError(f"{path}: tensor '{key}' has shape {tuple(src[key].shape)} in the init_from "
                                      f"policy and {tuple(target.shape)} here")
            else:
                target.copy_(src[key])
    return [k for k in new if k not in old]


def _input_keys(cfg: Any, groups: Mapping[str, list[str]]) -> dict[str, str]:
    """Weight name -> group, for the weights that read observation fields (their columns follow the fields)."""
    if cfg.architecture == "dart":
        return {f"trunk.{g}_encoder.layers.0.weight": g for g in groups}
    first = "body.layers.0.weight" if cfg.mlp_hidden else "out_fc.weight"
    return {f"actor.{first}": "obs", f"critic.{first}": "obs"}
