"""What the trainers need from an env: the contract, written down once.

Both trainers see only the Gymnasium ``VectorEnv`` interface (the SB3 trainer through an SB3
``VecEnv`` adapter of it) and the info keys below; they never import ``latentrl.envs`` or the
motion model. The native trainer needs SAME_STEP autoreset:

``reset(seed) -> (obs (N, D), infos)``, ``step(actions (N, A)) -> (obs, reward (N,), terminated (N,),
truncated (N,), infos)``, ``num_envs``, ``single_observation_space`` and ``single_action_space``
(flat Boxes), and optionally ``metadata["observation_layout"]`` (observation group -> [start, stop)).

The info keys read are the constants below (vector form: (N,) arrays, with a ``_<key>`` mask where
Gymnasium adds one; the SB3 adapter gives the same keys per env, in SB3's per-env dicts, plus SB3's
own ``terminal_observation`` and ``TimeLimit.truncated``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from latentrl.monitor import REWARD_PREFIX

FINAL_OBS = "final_obs"
"""(N, D) observation an episode ended on, with mask ``_final_obs`` (SAME_STEP autoreset); bootstraps truncations."""
EPISODE = "episode"
"""``{"r": (N,), "l": (N,)}`` return and length of episodes that ended this step, mask ``_episode``."""
IS_SUCCESS = "is_success"
"""(N,) bool, read at episode ends: ``rollout/success_rate``."""
DIVERGED = "diverged"
"""(N,) bool, envs whose motion diverged this step (terminated and reset): ``rollout/diverged`` (optional)."""
REWARD_TERM_PREFIX = REWARD_PREFIX
"""``reward/<term>`` (N,) float, every unweighted reward term at every step: ``reward/<term>`` tags."""
OBSERVATION_LAYOUT = "observation_layout"
"""``env.metadata`` key of the observation groups (optional; the policy encodes groups apart)."""

INFO_KEYS = (FINAL_OBS, EPISODE, IS_SUCCESS, DIVERGED, REWARD_TERM_PREFIX + "<term>")
"""Every info key a trainer reads."""


def reward_weights(env: Any) -> dict[str, float] | None:
    """The weight of each ``reward/<term>`` (``env.rewards.weights``, optional), or None when the env has none.

    With them the trainers log ``Episode_Reward/<term>``; the env (or the env an adapter wraps as
    ``env.env``) must compute its reward as the weighted sum of its terms.
    """
    for candidate in (env, getattr(env, "env", None), getattr(env, "unwrapped", None)):
        weights = getattr(getattr(candidate, "rewards", None), "weights", None)
        if isinstance(weights, Mapping):
            return {str(k): float(v) for k, v in weights.items()}
    return None


def action_magnitude(actions: Any) -> tuple[float, float] | None:
    """``(mean |z|, share of |z| > sqrt(d))`` of actions (..., d) as the env received them; None for no actions.

    A standard normal z in d dimensions has ``|z|`` close to ``sqrt(d)`` (the Gaussian shell), so the
    share beyond it tells how far a policy pushes the motion prior's noise out of distribution.
    """
    import torch

    z = torch.as_tensor(actions, dtype=torch.float32)
    if z.numel() == 0:
        return None
    norms = torch.linalg.vector_norm(z.reshape(-1, z.shape[-1]), dim=-1)
    return float(norms.mean()), float((norms > z.shape[-1] ** 0.5).float().mean())


def observation_layout(env: Any, given: Mapping[str, Any] | None = None) -> Mapping[str, Any] | None:
    """The layout passed explicitly, else ``env.metadata["observation_layout"]``, else None."""
    if given is not None:
        return given
    return (getattr(env, "metadata", None) or {}).get(OBSERVATION_LAYOUT)
