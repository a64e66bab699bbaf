"""ReachLocation: DART's goal-reaching task on the latent-noise vector env."""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch

from latentrl.config import require
from latentrl.envs.base import LatentMotionVectorEnv
from latentrl.envs.goal import body_forward, rotate_xy


class ReachLocationEnv(LatentMotionVectorEnv):
    """Walk (run, hop...) to a 2-D goal on the floor; a new goal appears whenever one is reached.

    ## Description

    DART's ``EnvReachLocationMLD``: each step the policy picks the initial latent noise of the
    frozen motion model, which generates the next 8 frames (0.267 s at 30 fps) conditioned on the
    2-frame history and the episode's text. Goals are sampled relative to the body; reaching one
    (pelvis within ``success_threshold`` in xy at any of the 8 new frames) counts a success and
    samples the next goal, keeping the text, so one episode can hold several goals.

    ## Action Space

    ``Box(-action_bound, action_bound, (D,), float32)``: the DDIM initial noise ``x_T``, D = the
    model's latent size (256 for DART's model), reshaped to (1, D). Actions outside the bound are
    clamped by the env; non-finite actions raise (or are zeroed with ``nonfinite_actions="zero"``).

    ## Observation Space

    ``Box(-inf, inf, (4 + E + 552 + 1,), float32)``, E = text-embedding size (512 for CLIP):

    =================  ============  ===========================================================
    slice              name          meaning
    =================  ============  ===========================================================
    [0:3]              goal_dir      unit xy direction to the goal from the last history frame's
                                     pelvis, clipped to +-60 deg of that frame's forward axis,
                                     in the canonical frame of history frame 0 (z = 0)
    [3:4]              goal_dist     xy distance to the goal, metres, clipped at 5
    [4:4+E]            text          embedding of the episode's text
    [4+E:556+E]        motion        2 x 276 unnormalized canonical history features
    [556+E:557+E]      scene         floor z minus the pelvis z of history frame 0, metres
                                     (about -0.9 standing)
    =================  ============  ===========================================================

    The groups are published in ``metadata["observation_layout"]`` (goal, text, motion, scene).

    ## Rewards

    Weighted sum of the terms of :mod:`latentrl.rewards` with DART's README weights: dist 1,
    success 1, foot_floor 100 (x0.1 for hop/run texts), skate 100, orient 0.1, rotation 10,
    jerk 0. Each unweighted term is in ``infos["reward/<term>"]``.

    ## Starting State

    A seed history of the motion model (drawn with the env's generator), placed with the pelvis
    at the xy origin facing +y and the lowest joint on the floor; a text drawn from ``texts``
    with ``text_weights``; a goal at an angle uniform in +-``goal_angle_deg`` around the body's
    forward axis and a distance uniform in ``goal_distance``.

    ## Episode End

    - Termination: the pelvis is farther than ``terminate_distance`` (100 m) from the goal, or
      the motion diverged (non-finite or beyond ``divergence_limit``; ``infos["diverged"]``).
    - Truncation: ``max_episode_steps`` (DART 32) steps.

    ## Arguments

    ``goal_angle_deg`` (60) and ``goal_distance`` ((0.5, 5.0) metres) shape the goal
    distribution; every other argument is :class:`~latentrl.envs.base.LatentMotionVectorEnv`'s.
    ``gymnasium.make_vec("latentrl/ReachLocation-v0", num_envs=256, motion=..., texts=...)``.

    ## Version History

    - v0: DART's task, with per-env ``orient`` reward and true partial resets.
    """

    def __init__(
        self,
        num_envs: int = 1,
        *,
        goal_angle_deg: float = 60.0,
        goal_distance: Sequence[float] = (0.5, 5.0),
        **kwargs,
    ):
        require(0 <= goal_angle_deg <= 180, "goal_angle_deg", f"must be in [0, 180], got {goal_angle_deg}")
        lo, hi = (float(v) for v in goal_distance)
        require(0 <= lo <= hi, "goal_distance", f"must be (min, max) metres with 0 <= min <= max, got {goal_distance}")
        self.goal_angle_deg = float(goal_angle_deg)
        self.goal_distance = (lo, hi)
        super().__init__(num_envs, **kwargs)
        self._goal = torch.zeros(self.num_envs, 3, device=self.device)

    @property
    def goal_world(self) -> torch.Tensor:
        """(N, 3) current goal, world metres (z = floor height)."""
        return self._goal

    def _sample_goals(self, idx: torch.Tensor) -> torch.Tensor:
        """(M, 3) goals for envs ``idx`` around the last history frame's pelvis and forward axis."""
        forward, pelvis = body_forward(self.history_world(idx)[:, -1])
        a = math.radians(self.goal_angle_deg)
        angle = self._uniform(len(idx), -a, a)
        dist = self._uniform(len(idx), *self.goal_distance)
        xy = pelvis[:, :2] + rotate_xy(forward, angle) * dist[:, None]
        return torch.cat((xy, torch.full_like(xy[:, :1], self.floor_height)), dim=-1)

    def _reset_task(self, idx: torch.Tensor) -> None:
        self._text_idx[idx] = self._sample_texts(len(idx))
        self._goal[idx] = self._sample_goals(idx)

    def _goal_observation(self, history_world: torch.Tensor) -> torch.Tensor:
        return self._goal_features(history_world, self._goal)

    def _advance_task(self, reached: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Reached goals are replaced (text kept, DART's ``reset_text=False``); never terminates.

        ``is_success`` is the episode's outcome so far: at least one goal reached (so the value at
        an episode's last step, which SB3-style success rates read, is the episode's success).
        The per-step event is ``infos["goal_reached"]``.
        """
        if bool(reached.any()):
            idx = reached.nonzero()[:, 0]
            self._goal[idx] = self._sample_goals(idx)
        return torch.zeros_like(reached), self._ep_goals > 0

    def _task_infos(self, infos: dict, reached: torch.Tensor) -> None:
        infos["goal_reached"] = reached
        infos["_goal_reached"] = self._all
