"""``MotionPrior`` is all an env needs: a small protocol-only prior (no MotionModel, no networks) drives tasks.

The stub walks its one seed pose forward along the body's +y by a distance the noise sets; it has no
data normalizer (``mean``/``std`` None), so the divergence check uses joints and finiteness only.
"""

from __future__ import annotations

import torch

from latentrl.envs import JoystickEnv, ReachLocationEnv
from latentrl.motion.canonical import WorldTransform
from latentrl.motion.prior import MotionPrior
from latentrl.motion.representation import FEATURE_DIM, FUTURE_LENGTH, SLICES, joints_of
from latentrl.motion.rollout import RolloutState, StepResult


class StubPrior:
    """A standing pose that slides forward 0.1 m per step plus the mean of the noise."""

    def __init__(self, text_dim: int = 8):
        self.text_dim = text_dim
        frame = torch.zeros(FEATURE_DIM)
        joints = torch.linspace(0.05, 1.7, 22)[:, None] * torch.tensor([0.0, 0.0, 1.0])  # heights above the floor
        joints[:, 0] = torch.linspace(-0.2, 0.2, 22)  # spread in x so the hip axis has a direction
        joints[0] = torch.tensor([0.0, 0.0, 0.9])  # the pelvis
        frame[SLICES["joints"]] = joints.reshape(-1)
        self.seed_history = frame.expand(1, 2, FEATURE_DIM).clone()
        self.pelvis_delta = torch.zeros(3)
        self.mean = None
        self.std = None

    @property
    def device(self) -> torch.device:
        return torch.device("cpu")

    @property
    def latent_shape(self) -> tuple[int, int]:
        return (1, 4)

    @property
    def latent_dim(self) -> int:
        return 4

    def to(self, device):
        return self

    def encode_text(self, texts):
        return torch.stack([torch.full((self.text_dim,), float(len(t))) for t in texts])

    def initial_state(self, batch, generator=None, seed_index=None):
        history = self.seed_history.expand(batch, -1, -1).clone()
        return RolloutState(history, WorldTransform.identity(batch), torch.zeros(batch, dtype=torch.bool))

    def prepare_compile(self) -> None:
        pass

    def rollout_step(self, state, text_embedding, noise, guidance_scale=5.0, sampler="ddim", generator=None,
                     foot_lock=None, lock_min_weight=0.5):
        n = noise.shape[0]
        stride = 0.1 + noise.reshape(n, -1).mean(1)  # metres this step, along the body's +y
        frac = torch.arange(1, FUTURE_LENGTH + 1, dtype=torch.float32) / FUTURE_LENGTH
        offset = torch.zeros(n, FUTURE_LENGTH, 22, 3)
        offset[..., 1] = (stride[:, None] * frac)[:, :, None]
        future = state.history[:, -1:].expand(-1, FUTURE_LENGTH, -1).clone()
        future[..., SLICES["joints"]] = (joints_of(future) + offset).flatten(-2)
        joints_world = state.world.apply(joints_of(future))
        step = torch.zeros(n, 3)
        step[:, 1] = stride
        world = WorldTransform(state.world.rotation,
                               state.world.translation + (state.world.rotation @ step[..., None])[..., 0])
        landed = torch.zeros(n, dtype=torch.bool)
        return StepResult(future, joints_world, noise, RolloutState(state.history, world, landed), state.world)


def test_the_stub_is_a_motion_prior():
    assert isinstance(StubPrior(), MotionPrior)


def test_a_protocol_only_prior_drives_reach_for_a_few_steps():
    env = ReachLocationEnv(3, motion=StubPrior(), texts=("walk", "run"), record_history=True)
    obs, _ = env.reset(seed=0)
    start = env.history_world()[:, -1, 0].clone()
    for _ in range(3):
        obs, reward, terminated, truncated, infos = env.step(torch.full((3, 4), 0.2))
        assert torch.isfinite(obs).all() and torch.isfinite(reward).all() and not infos["diverged"].any()
    moved = env.history_world()[:, -1, 0] - start
    assert torch.allclose(moved[:, 1], torch.full((3,), 0.9), atol=1e-5)  # 3 steps of 0.1 + 0.2 m
    assert env.export_clip(0).joints.shape == (2 + 3 * FUTURE_LENGTH, 22, 3)


def test_a_protocol_only_prior_drives_joystick():
    env = JoystickEnv(2, motion=StubPrior(), texts=("walk",))
    env.reset(seed=1)
    for _ in range(2):
        obs, reward, *_ = env.step(torch.zeros(2, 4))
    assert obs.shape == (2, env.single_observation_space.shape[0]) and torch.isfinite(reward).all()
