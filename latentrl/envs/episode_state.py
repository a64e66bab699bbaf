"""An env's episode bookkeeping outside its tensor maths: resets, actions in, the resume snapshot.

Partial resets replace rows of the motion state (:func:`replace_rows`); ``reset()``'s arguments and the
actions a step is handed are checked here. Training checkpoints store :func:`snapshot` of the env so that
a resumed run continues the episodes it was in with the same random stream, and matches a run that was
never interrupted.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
from gymnasium.vector import AutoresetMode

from latentrl.config import require
from latentrl.errors import ConfigError, NonFiniteError, closest
from latentrl.motion.canonical import WorldTransform
from latentrl.motion.rollout import RolloutState


def replace_rows(state: RolloutState, idx: torch.Tensor, fresh: RolloutState) -> RolloutState:
    """``state`` with rows ``idx`` replaced by ``fresh`` (M rows), the others untouched."""
    return RolloutState(
        state.history.index_copy(0, idx, fresh.history),
        WorldTransform(
            state.world.rotation.index_copy(0, idx, fresh.world.rotation),
            state.world.translation.index_copy(0, idx, fresh.world.translation),
        ),
        state.airborne_flags().index_copy(0, idx, fresh.airborne_flags()),
    )


def snapshot(env: Any) -> dict[str, Any]:
    """The env's generator and every episode tensor (its tensor attributes and the motion state), copied."""
    out: dict[str, Any] = {"generator": env._generator.get_state()}
    state = env._state
    if state is not None:
        tensors = {name: value.clone() for name, value in vars(env).items() if torch.is_tensor(value)}
        tensors.update({"state.history": state.history.clone(),
                        "state.world.rotation": state.world.rotation.clone(),
                        "state.world.translation": state.world.translation.clone(),
                        "state.airborne": state.airborne_flags().clone()})
        out["episode"] = tensors
    return out


def restore(env: Any, snap: Mapping[str, Any]) -> None:
    """Inverse of :func:`snapshot`; episode tensors are restored only if their shapes still fit."""
    env._generator.set_state(snap["generator"].cpu())
    tensors = snap.get("episode")
    if not tensors or tensors["state.history"].shape[0] != env.num_envs:
        return
    for name, value in tensors.items():
        current = getattr(env, name, None) if not name.startswith("state.") else None
        if torch.is_tensor(current) and current.shape == value.shape:
            setattr(env, name, value.to(current.device, current.dtype))
    env._state = RolloutState(
        tensors["state.history"].to(env.device),
        WorldTransform(tensors["state.world.rotation"].to(env.device),
                       tensors["state.world.translation"].to(env.device)),
        tensors["state.airborne"].to(env.device) if "state.airborne" in tensors else None,
    )


AUTORESET_MODES = {AutoresetMode.SAME_STEP, AutoresetMode.DISABLED}
RESET_OPTIONS = ("reset_mask",)
"""The ``options`` keys of ``reset()``."""


def autoreset_mode(value: AutoresetMode | str) -> AutoresetMode:
    """The env's autoreset mode from its argument: SameStep or Disabled (reset with ``reset_mask``)."""
    try:
        mode = value if isinstance(value, AutoresetMode) else AutoresetMode(value)
    except ValueError:
        names = [m.value for m in AUTORESET_MODES]
        raise ConfigError(f"autoreset_mode: unknown mode {value!r}; expected one of {names}") from None
    require(
        mode in AUTORESET_MODES,
        "autoreset_mode",
        f"{mode.value} is not supported; use SameStep (default) or Disabled with reset(options={{'reset_mask': ...}})",
    )
    return mode


def check_reset(seed: Any, options: Mapping[str, Any]) -> None:
    """Refuse unknown ``reset()`` options and a seed that is not one int."""
    for key in options:
        if key not in RESET_OPTIONS:
            raise ValueError(f"unknown reset option '{key}'{closest(key, RESET_OPTIONS)}; known: {RESET_OPTIONS}")
    if seed is not None and not isinstance(seed, (int, np.integer)):
        raise TypeError(f"seed must be one int for the whole batch (it seeds one device generator), got {seed!r}")


def mask_to_index(mask: Any, num_envs: int, device: torch.device) -> torch.Tensor:
    """(M,) indices of a ``reset_mask`` ((N,) bool, numpy or torch) that selects at least one env."""
    mask = torch.as_tensor(mask, device=device)
    if mask.dtype != torch.bool or mask.shape != (num_envs,):
        raise ValueError(
            f"reset_mask must be a bool array of shape ({num_envs},), got {mask.dtype} {tuple(mask.shape)}")
    if not bool(mask.any()):
        raise ValueError("reset_mask must select at least one env")
    return mask.nonzero()[:, 0]


def prepare_actions(actions: Any, num_envs: int, dim: int, bound: float, nonfinite: str,
                    device: torch.device) -> tuple[torch.Tensor, torch.Tensor]:
    """Validate shape, handle non-finite rows (``nonfinite``: 'error' or 'zero'), clamp to +/- ``bound``.

    Returns ((N, D) float32, (N,) non-finite mask).
    """
    actions = torch.as_tensor(actions, dtype=torch.float32, device=device)
    if actions.shape != (num_envs, dim):
        raise ValueError(f"actions must have shape (num_envs, D) = ({num_envs}, {dim}), got {tuple(actions.shape)}")
    rows = ~torch.isfinite(actions).all(dim=1)
    if bool(rows.any()):
        if nonfinite == "error":
            bad = rows.nonzero()[:, 0].tolist()
            raise NonFiniteError(
                f"actions of envs {bad[:20]} contain NaN or inf; pass finite actions or build the env with "
                "nonfinite_actions='zero' to replace them by 0"
            )
        actions = torch.where(rows[:, None], 0.0, actions)
    return actions.clamp(-bound, bound), rows


def step_infos(terms: Mapping[str, torch.Tensor], success: torch.Tensor, diverged: torch.Tensor,
               nonfinite: torch.Tensor, every: torch.Tensor) -> dict[str, Any]:
    """A step's batched infos: ``reward/<term>``, ``is_success``, ``diverged`` and ``nonfinite_action``.

    Each comes with its ``_key`` mask (``every``: (N,) True).
    """
    infos: dict[str, Any] = {}
    for name, value in terms.items():
        infos[f"reward/{name}"] = value
        infos[f"_reward/{name}"] = every
    infos["is_success"] = success
    infos["diverged"] = diverged
    infos["nonfinite_action"] = nonfinite
    for key in ("is_success", "diverged", "nonfinite_action"):
        infos[f"_{key}"] = every
    return infos
