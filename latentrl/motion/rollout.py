"""MotionModel: the frozen DART runtime, (history, text, noise) -> frames, history, world joints.

One call of :meth:`MotionModel.sample_primitive` is what one RL env step costs: 10 denoiser
passes, each a single batched forward of size 2B for classifier-free guidance (conditional and
unconditional halves; DART runs them as two passes), then one VAE decode.

Frames of reference: ``history`` and ``future`` are **canonical** (the frame of the history's
first frame) and **unnormalized**; :class:`RolloutState` carries the canonical-to-world transform
so rollouts of any length come back in world coordinates (metres, z up).
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from typing import NamedTuple, Protocol

import torch
from torch import nn

from latentrl.constants import GUIDANCE_SCALE
from latentrl.errors import LatentRLError, TextError
from latentrl.motion.canonical import WorldTransform, canonicalize, features_to_world
from latentrl.motion.contacts import foot_positions, skate_weights
from latentrl.motion.denoiser import Denoiser
from latentrl.motion.diffusion import DiffusionConfig, GaussianDiffusion
from latentrl.motion.representation import FEATURE_DIM, FUTURE_LENGTH, HISTORY_LENGTH, SLICES, Normalizer, joints_of
from latentrl.motion.skeleton import NUM_JOINTS
from latentrl.motion.text import TextEncoder
from latentrl.motion.vae import PrimitiveVAE

#: Contact band of the floor snap (metres): see :meth:`MotionModel._snap_to_floor`; ``None`` turns it off.
FLOOR_SNAP_M = 0.05
#: Highest a primitive's lowest joint may be above the floor (metres). The generated data's highest is
#: 0.129 m (a jump's flight, over every 8-frame window of the 200 default sequences).
FLIGHT_CAP_M = 0.15
#: The foot lock divides by the feet's summed contact weight, but never by less than this: a foot barely
#: touching (weight near 0) is corrected in proportion to its weight instead of locked outright. The envs'
#: ``foot_lock_min_weight`` overrides it (0.05 pins any foot inside DART's 3 cm band: docs/motion.md).
LOCK_MIN_WEIGHT = 0.5
#: Highest terrain a primitive steps onto (metres above the body's lowest joint before it): :func:`ground_under`.
MAX_STEP_UP_M = 0.3
#: A primitive crosses a step when the ground under its lowest joint changes by more than this (metres) over its
#: frames: :func:`follow_steps`.
STEP_M = 0.03


def lock_min_weight_problem(value: float) -> str | None:
    """Why ``value`` cannot be the lock's ``min_weight`` (outside (0, 2], two feet's summed weight), or None."""
    if not 0.0 < value <= 2.0:
        return f"must be in (0, 2] (a summed contact weight), got {value}"
    return None


AMP_DTYPES: dict[str, torch.dtype] = {"bf16": torch.bfloat16, "fp16": torch.float16}
"""Autocast dtypes by the names configs use (``env.amp``, ``bench rollout --amp``) for ``MotionModel.amp_dtype``."""


def amp_problem(value: str | None) -> str | None:
    """Why ``value`` cannot name an autocast dtype (None = float32), or None: the env's and the config's one check."""
    if value is None or value in AMP_DTYPES:
        return None
    return f"expected one of {tuple(AMP_DTYPES)} or null, got {value!r}"


class Terrain(Protocol):
    """Ground under the character for the floor snap; ``latentrl.scenes.SceneBatch`` is one (duck-typed here)."""

    def height(self, xy: torch.Tensor) -> torch.Tensor:
        """(B, ...) terrain z under (B, ..., 2) world points, metres."""
        ...


class PrimitiveSample(NamedTuple):
    """Result of sampling one primitive."""

    latent: torch.Tensor  # (B, 1, D) clean latent from the sampler (unit-variance space)
    future: torch.Tensor  # (B, 8, 276) unnormalized, canonical frame of the history
    future_normalized: torch.Tensor  # (B, 8, 276)


class RolloutState(NamedTuple):
    """Per-sequence state between primitives."""

    history: torch.Tensor  # (B, 2, 276) unnormalized canonical history
    world: WorldTransform  # canonical -> world
    airborne: torch.Tensor | None = None  # (B,) bool: the last primitive never came within the snap band

    def airborne_flags(self) -> torch.Tensor:
        """(B,) bool ``airborne``; all False where unknown (a fresh or hand-made state)."""
        if self.airborne is not None:
            return self.airborne
        return torch.zeros(self.history.shape[0], dtype=torch.bool, device=self.history.device)


class StepResult(NamedTuple):
    """One autoregressive step."""

    future: torch.Tensor  # (B, 8, 276) canonical frame of the *previous* state's history
    joints_world: torch.Tensor  # (B, 8, 22, 3) metres, z up
    latent: torch.Tensor  # (B, 1, D)
    state: RolloutState  # the next state (last 2 future frames, re-canonicalized)
    placement: WorldTransform  # canonical -> world transform that placed ``future`` (floor snap included)


class Rollout(NamedTuple):
    """A whole rollout: the 2 seed frames followed by 8 frames per step."""

    joints_world: torch.Tensor  # (B, 2 + 8 S, 22, 3) metres, z up
    features_world: torch.Tensor  # (B, 2 + 8 S, 276) unnormalized, world frame
    noise: torch.Tensor  # (S, B, 1, D) initial latents used (the actions)
    latents: torch.Tensor  # (S, B, 1, D) clean latents
    state: RolloutState  # final state, to continue


class MotionModel(nn.Module):
    """Frozen VAE + denoiser + diffusion + normalization + text encoder, ready to sample.

    Args:
        vae: the primitive VAE (eval mode, frozen).
        denoiser: the latent denoiser.
        diffusion_config: schedule; sampling visits ``respacing`` (default: all steps, DART's ddim10).
        normalizer: mean/std of the 276-D frames.
        text_encoder: prompt encoder, or ``None`` when the model ships no text table.
        rescale_latent: decode ``z * latent_std`` (DART's ``rescale_latent``).
        pelvis_delta: (3,) rest pelvis offset (``pelvis = transl + pelvis_delta``), or ``None``.
        seed_history: (K, 2, 276) canonical seed histories for resets, or ``None``.
        info: provenance (source path, content hash, training metadata).
    """

    def __init__(
        self,
        vae: PrimitiveVAE,
        denoiser: Denoiser,
        diffusion_config: DiffusionConfig,
        normalizer: Normalizer,
        text_encoder: TextEncoder | None = None,
        rescale_latent: bool = True,
        pelvis_delta: torch.Tensor | None = None,
        seed_history: torch.Tensor | None = None,
        info: dict | None = None,
    ):
        super().__init__()
        self.vae = vae.eval().requires_grad_(False)
        self.denoiser = denoiser.eval().requires_grad_(False)
        self.diffusion_config = diffusion_config
        self.diffusion = GaussianDiffusion(diffusion_config)
        self.denoiser.attach_schedule(self.diffusion.base_alphas_cumprod)
        self.register_buffer("mean", normalizer.mean.clone())
        self.register_buffer("std", normalizer.std.clone())
        self.text_encoder = text_encoder
        self.rescale_latent = bool(rescale_latent)
        self.register_buffer("pelvis_delta", None if pelvis_delta is None else torch.as_tensor(pelvis_delta).float())
        self.register_buffer("seed_history", None if seed_history is None else torch.as_tensor(seed_history).float())
        self.info = dict(info or {})
        self.amp_dtype: torch.dtype | None = None
        self.floor_snap: float | None = FLOOR_SNAP_M
        self.floor_snap_ramp = False
        """Spread each primitive's floor-snap shift over its frames (:func:`ramp_snap`) instead of one step."""
        self.follow_steps = True
        """On terrain, let a primitive that crosses a step follow it frame by frame (:func:`follow_steps`)."""
        self.foot_lock = False
        """Keep feet on the floor from sliding (:func:`lock_feet`); off by default, envs turn it on (``foot_lock``)."""
        self._text_cache: dict[str, torch.Tensor] = {}

    # ------------------------------------------------------------------ properties
    @property
    def device(self) -> torch.device:
        """The device the model's buffers and weights live on."""
        return self.mean.device

    @property
    def latent_shape(self) -> tuple[int, int]:
        """(tokens, width) of the latent = the RL action shape."""
        return tuple(self.denoiser.config.noise_shape)

    @property
    def latent_dim(self) -> int:
        """Size of the flat latent (tokens * width) = the RL action size."""
        return self.latent_shape[0] * self.latent_shape[1]

    @property
    def text_dim(self) -> int:
        """Size of the text embedding the denoiser is conditioned on."""
        return self.denoiser.config.clip_dim

    @property
    def normalizer(self) -> Normalizer:
        """The feature normalizer of the model's mean and std, on the model's device."""
        return Normalizer(self.mean, self.std).to(self.device)

    def pack_for_cpu(self, rows: int = 10) -> int:
        """Prepack every linear weight for oneDNN (CPU float32, frozen model); returns how many.

        Faster small-batch sampling on CPU (docs/benchmarks.md, "Prepacked weights"); ``rows`` picks the
        layout (10 = a batch-1 step with guidance). The parameters and state dict stay as they were.
        """
        from latentrl.motion.packed import pack_linears

        return pack_linears(self, rows)

    def prepare_compile(self) -> None:
        """Copy the diffusion tables to the model's device now (:meth:`MotionPrior.prepare_compile`)."""
        self.diffusion.warm(self.device)

    def set_respacing(self, respacing: str) -> None:
        """Visit fewer diffusion steps when sampling ('' = all, 'ddim5', ...)."""
        cfg = DiffusionConfig(**{**self.diffusion_config.__dict__, "respacing": respacing})
        self.diffusion = GaussianDiffusion(cfg)

    # ------------------------------------------------------------------ text
    def encode_text(self, texts: Sequence[str]) -> torch.Tensor:
        """(N,) prompts -> (N, E) embeddings on the model's device (cached per prompt)."""
        if isinstance(texts, str):
            texts = [texts]
        missing = [t for t in dict.fromkeys(texts) if t not in self._text_cache]
        if missing:
            if self.text_encoder is None:
                raise TextError("this motion model has no text encoder or table; pass text embeddings directly")
            vecs = self.text_encoder.encode(missing)
            if vecs.shape[-1] != self.text_dim:
                raise TextError(
                    f"text encoder '{self.text_encoder.name}' gives {vecs.shape[-1]} dims, "
                    f"the denoiser expects {self.text_dim}"
                )
            self._text_cache.update(zip(missing, vecs.float()))
        return torch.stack([self._text_cache[t] for t in texts]).to(self.device)

    # ------------------------------------------------------------------ sampling
    def _autocast(self):
        if self.amp_dtype is not None and self.device.type in ("cuda", "cpu"):
            return torch.autocast(self.device.type, dtype=self.amp_dtype)
        return contextlib.nullcontext()

    def _check_inputs(self, history: torch.Tensor, text_embedding: torch.Tensor, noise: torch.Tensor) -> None:
        b = history.shape[0]
        if history.shape[1:] != (HISTORY_LENGTH, FEATURE_DIM):
            raise ValueError(f"history must be (B, {HISTORY_LENGTH}, {FEATURE_DIM}), got {tuple(history.shape)}")
        if text_embedding.shape != (b, self.text_dim):
            raise ValueError(f"text_embedding must be ({b}, {self.text_dim}), got {tuple(text_embedding.shape)}")
        if noise.shape != (b, *self.latent_shape):
            raise ValueError(
                f"noise must be ({b}, {self.latent_shape[0]}, {self.latent_shape[1]}), got {tuple(noise.shape)}"
            )

    @torch.no_grad()
    def sample_primitive(
        self,
        history: torch.Tensor,
        text_embedding: torch.Tensor,
        noise: torch.Tensor,
        guidance_scale: float | torch.Tensor = GUIDANCE_SCALE,
        sampler: str = "ddim",
        step_noise: torch.Tensor | None = None,
        generator: torch.Generator | None = None,
        trace: list | None = None,
    ) -> PrimitiveSample:
        """Sample the next 8 frames.

        Args:
            history: (B, 2, 276) unnormalized canonical history.
            text_embedding: (B, E); zero rows mean "no text".
            noise: (B, 1, D) initial latent x_T (the RL action); DDIM maps it deterministically.
            guidance_scale: classifier-free guidance w (float or (B,) tensor); 1 disables the
                unconditional half (same result, half the work).
            sampler: 'ddim' (eta 0) or 'ddpm'.
            step_noise: (T, B, 1, D) DDPM per-step noises (else drawn from ``generator``).
            trace: optional list receiving ``(t, x_t, x0_pred)`` per step.
        """
        return self._sample(history, text_embedding, noise, guidance_scale, sampler, step_noise, generator, trace)

    def _sample(self, history, text_embedding, noise, guidance_scale=GUIDANCE_SCALE, sampler="ddim",
                step_noise=None, generator=None, trace=None) -> PrimitiveSample:
        """:meth:`sample_primitive` without its ``no_grad``: gradients flow to ``noise`` when autograd is on."""
        self._check_inputs(history, text_embedding, noise)
        with self._autocast():
            history_n = (history - self.mean) / self.std
            latent = self._denoise(
                history_n, text_embedding, noise, guidance_scale, sampler, step_noise, generator, trace
            )
            future_n = self.vae.decode(latent, history_n, FUTURE_LENGTH, scale_latent=self.rescale_latent)
        out = self.std.dtype  # autocast's half outputs come back in the model's dtype (float64 stays float64)
        future_n = future_n.to(out)
        return PrimitiveSample(latent.to(out), future_n * self.std + self.mean, future_n)

    def _denoise(self, history_n, text, noise, guidance_scale, sampler, step_noise, generator, trace):
        b = history_n.shape[0]
        scale_is_one = isinstance(guidance_scale, (int, float)) and guidance_scale == 1.0
        if scale_is_one:
            cond = self.denoiser.condition(history_n, text)

            def model_fn(x, t):
                return self.denoiser.denoise(x, t, cond)
        else:
            # a number stays a number (no tensor built from host data in the step: capture-safe on CUDA)
            if torch.is_tensor(guidance_scale):
                w = guidance_scale.to(device=noise.device, dtype=noise.dtype).reshape(-1, 1, 1)
            else:
                w = float(guidance_scale)
            cond2 = self.denoiser.condition(
                torch.cat((history_n, history_n)), torch.cat((text, torch.zeros_like(text)))
            )

            def model_fn(x, t):
                out = self.denoiser.denoise(torch.cat((x, x)), t, cond2)
                c, u = out[:b], out[b:]
                return u + w * (c - u)

        return self.diffusion.sample_loop(
            model_fn, noise, sampler=sampler, step_noise=step_noise, generator=generator, trace=trace
        )

    # ------------------------------------------------------------------ rollout
    def initial_state(
        self, batch: int, generator: torch.Generator | None = None, seed_index: torch.Tensor | None = None
    ) -> RolloutState:
        """Reset state: a seed history per sequence.

        The world starts at the pelvis xy origin facing +y, shifted up so the lowest joint touches
        the floor (z = 0), as DART's env does.
        """
        if self.seed_history is None:
            raise LatentRLError(
                "this motion model has no seed history; load one with seed_history=... "
                "(see docs/motion.md) or pass a history to rollout_step"
            )
        if seed_index is None:
            seed_index = torch.randint(
                self.seed_history.shape[0],
                (batch,),
                generator=generator,
                device=generator.device if generator is not None else "cpu",
            )
        history = self.seed_history[seed_index.to(self.device)]
        world = WorldTransform.identity(batch, self.device)
        lowest = joints_of(history)[..., 2].amin(dim=(1, 2))
        world = WorldTransform(world.rotation, torch.stack((torch.zeros_like(lowest),) * 2 + (-lowest,), dim=-1))
        return RolloutState(history, world, torch.zeros(batch, dtype=torch.bool, device=self.device))

    def rollout_step(
        self,
        state: RolloutState,
        text_embedding: torch.Tensor,
        noise: torch.Tensor,
        guidance_scale: float | torch.Tensor = GUIDANCE_SCALE,
        sampler: str = "ddim",
        generator: torch.Generator | None = None,
        foot_lock: bool | None = None,
        lock_min_weight: float = LOCK_MIN_WEIGHT,
        terrain: Terrain | None = None,
    ) -> StepResult:
        """Sample one primitive, place it in the world, and re-canonicalize its last 2 frames.

        ``foot_lock``: apply :func:`lock_feet` (None: the model's :attr:`foot_lock` setting) with
        ``lock_min_weight`` as its ``min_weight``. ``terrain``: the ground the floor snap measures against
        (:class:`Terrain`, e.g. a scene's ``SceneBatch``); None is the flat floor at z = 0.
        """
        if self.pelvis_delta is None:
            raise LatentRLError("this motion model has no pelvis_delta; load a seed history (docs/motion.md)")
        sample = self.sample_primitive(
            state.history, text_embedding, noise, guidance_scale, sampler, generator=generator
        )
        with torch.no_grad():
            return self._place(state, sample, self.foot_lock if foot_lock is None else foot_lock, lock_min_weight,
                               terrain)

    def _place(self, state: RolloutState, sample, foot_lock: bool, lock_min_weight: float,
               terrain: Terrain | None, floor_snap: bool = True) -> StepResult:
        """Place a sampled primitive in the world: floor snap (the model's setting), canonicalization, foot lock.

        Plain tensor maths: :meth:`rollout_step` runs it without gradients, :meth:`differentiable_step` with
        them (the snap's shift and the lock's slide are differentiable functions of the joints).
        """
        placement = state.world
        joints_world = placement.apply(joints_of(sample.future))
        airborne = state.airborne  # without the snap nothing lands: the flags pass through
        future = sample.future
        snap = floor_snap and self.floor_snap is not None
        follow = snap and terrain is not None and self.follow_steps and not self.floor_snap_ramp
        if snap:
            ground = None
            if terrain is not None:  # the snap moves z only: the ground under each joint stays the same
                stand = state.world.apply(joints_of(state.history))[..., 2].flatten(1).amin(dim=1)
                ground = ground_under(joints_world, terrain, stand)
            joints_world, placement, airborne = self._snap_to_floor(
                joints_world, placement, state.airborne_flags(), ground
            )
            lift = placement.translation[:, 2] - state.world.translation[:, 2]
            if self.floor_snap_ramp:
                joints_world, future = ramp_snap(future, joints_world, lift, ground)
        history, rotation, origin = canonicalize(sample.future[:, -HISTORY_LENGTH:], self.pelvis_delta)
        world = placement.compose(rotation, origin)
        if foot_lock:
            before = state.world.apply(foot_positions(joints_of(state.history[:, -1])))
            joints_world, future, shift = lock_feet(future, joints_world, placement, before, lock_min_weight,
                                                    terrain)
            world = WorldTransform(world.rotation, world.translation + shift)
        if follow:  # after the lock: the ground under each joint where the lock leaves it
            joints_world, future, drop = follow_steps(future, joints_world, lift, terrain, stand, airborne,
                                                      self.floor_snap)
            down = torch.nn.functional.pad(drop[:, None], (2, 0))  # (B, 3): z only
            placement = WorldTransform(placement.rotation, placement.translation + down)
            world = WorldTransform(world.rotation, world.translation + down)
        return StepResult(future, joints_world, sample.latent, RolloutState(history, world, airborne), placement)

    def differentiable_step(
        self,
        state: RolloutState,
        text_embedding: torch.Tensor,
        noise: torch.Tensor,
        guidance_scale: float | torch.Tensor = GUIDANCE_SCALE,
        post_process: bool = False,
        foot_lock: bool | None = None,
        lock_min_weight: float = LOCK_MIN_WEIGHT,
        terrain: Terrain | None = None,
    ) -> StepResult:
        """:meth:`rollout_step` with gradients from the world joints back to ``noise`` (DDIM, eta 0).

        ``post_process=True`` places the primitive exactly as :meth:`rollout_step` does (floor snap, and the
        foot lock with ``foot_lock``, ``lock_min_weight``, ``terrain`` as there), gradients flowing through
        both: what a closed-loop refiner (``latentrl.optim.refine``) needs to predict an env's next step.

        Why a second method: the RL path keeps its ``no_grad`` (no autograd cost per env step), while
        noise optimization (``latentrl.optim``) differentiates through sampler, decoder, canonicalization and
        placement. With ``post_process=False`` (``latentrl optimize``) the floor snap and the foot lock are left out
        (both are post-processes that move the placement; the optimizer scores the floor and the skate as losses
        instead, as DART's ``optim_mld`` does), so the motion returned is exactly the motion optimized.
        """
        if self.pelvis_delta is None:
            raise LatentRLError("this motion model has no pelvis_delta; load a seed history (docs/motion.md)")
        sample = self._sample(state.history, text_embedding, noise, guidance_scale)
        lock = post_process and (self.foot_lock if foot_lock is None else foot_lock)
        return self._place(state, sample, lock, lock_min_weight, terrain, floor_snap=post_process)

    def _snap_to_floor(
        self, joints_world: torch.Tensor, world: WorldTransform, airborne: torch.Tensor,
        ground: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, WorldTransform, torch.Tensor]:
        """Keep the world floor at z = 0: shift each primitive so its lowest joint touches it.

        Why: the canonical frame has its origin at the pelvis, so the model never sees where the
        floor is, and small per-primitive errors in height add up over a long rollout (a body that
        sinks or floats by decimetres in a minute). The shift changes only the world placement, never
        the model's input. A primitive whose lowest joint is below the floor is lifted; one within
        ``floor_snap`` metres above it (a foot on the floor) is lowered onto it; one higher up is in
        the air (a jump or a hop's flight) and keeps its height, but never more than
        :data:`FLIGHT_CAP_M`, and only for one primitive: one that follows an airborne primitive
        (``airborne``) lands. In the generated data no two 8-frame windows in a row are airborne and
        no lowest joint is above 0.129 m, so the rules bind only motion the data never shows
        (policies learned to fly without them: a run policy's pelvis reached 4.96 m). DART's
        ``rollout_mld.py`` has a ``fix_floor`` option of the same kind.

        ``airborne`` is the (B,) flags of the previous primitive; ``ground`` (B, F, J) the terrain height under
        each joint (a scene's stairs and box tops), None for the flat floor at z = 0: the lowest joint is then
        the one nearest the ground under it, so a foot on a tread carries the body. Returns the shifted
        joints, the shifted placement and the new flags.
        """
        height = joints_world[..., 2] if ground is None else joints_world[..., 2] - ground  # above the ground
        lowest = height.flatten(1).min(dim=1).values  # (B,)
        if ground is not None:  # every joint inside an obstacle (no ground counts): left where it is
            lowest = torch.where(torch.isinf(lowest), torch.zeros_like(lowest), lowest)
        land = (lowest <= self.floor_snap) | airborne
        target = torch.where(land, torch.zeros_like(lowest), lowest.clamp(max=FLIGHT_CAP_M))
        shift = target - lowest
        flat = torch.zeros_like(shift)
        offset = torch.stack((flat, flat, shift), dim=-1)  # (B, 3), z only
        joints_world = joints_world + offset[:, None, None, :]
        translation = world.translation + offset
        return joints_world, WorldTransform(world.rotation, translation), ~land

    def rollout(
        self,
        texts: Sequence[str] | Sequence[Sequence[str]],
        num_steps: int,
        batch: int = 1,
        noise: torch.Tensor | None = None,
        generator: torch.Generator | None = None,
        guidance_scale: float = GUIDANCE_SCALE,
        state: RolloutState | None = None,
    ) -> Rollout:
        """Autoregressive rollout.

        Args:
            texts: one prompt for everything, a list with one prompt per step, or per step a list
                of ``batch`` prompts.
            num_steps: primitives to generate (8 frames each).
            noise: (S, B, 1, D) initial latents per step; N(0, I) from ``generator`` if omitted.
        """
        if isinstance(texts, str):
            texts = [texts] * num_steps
        if len(texts) != num_steps:
            raise ValueError(f"got {len(texts)} step prompts for {num_steps} steps")
        state = state or self.initial_state(batch, generator)
        with torch.no_grad():
            joints = [state.world.apply(joints_of(state.history))]
            feats = [features_to_world(state.history, state.world, self.pelvis_delta)]
        latents, noises = [], []
        for step in range(num_steps):
            prompts = texts[step]
            prompts = [prompts] * batch if isinstance(prompts, str) else list(prompts)
            emb = self.encode_text(prompts)
            x_t = noise[step] if noise is not None else torch.randn(
                batch, *self.latent_shape, generator=generator,
                device=generator.device if generator is not None else "cpu").to(self.device)
            out = self.rollout_step(state, emb, x_t, guidance_scale)
            with torch.no_grad():
                feats.append(features_to_world(out.future, out.placement, self.pelvis_delta))
            joints.append(out.joints_world)
            latents.append(out.latent)
            noises.append(x_t)
            state = out.state
        return Rollout(torch.cat(joints, dim=1), torch.cat(feats, dim=1), torch.stack(noises), torch.stack(latents),
                       state)


def ground_under(joints_world: torch.Tensor, terrain: Terrain, stand: torch.Tensor,
                 step_up: float = MAX_STEP_UP_M) -> torch.Tensor:
    """(B, F, J) the terrain height under each joint of (B, F, J, 3) world joints, for the floor snap.

    Why not the height alone: a scene's height is the top of the highest object over a point, so a hand in
    a wall's footprint, or a foot walking into a 1 m box, would read the wall's or the box's top and the snap
    would lift the whole body onto it. Terrain more than ``step_up`` above ``stand`` ((B,) world z of the
    body's lowest joint in the frames before the primitive, where it stands) is an obstacle to collide with,
    not a step: it reads ``-inf`` (the joint never decides the snap).
    """
    return _steppable(terrain.height(joints_world[..., :2]), stand, step_up)


def _steppable(raw: torch.Tensor, stand: torch.Tensor, step_up: float = MAX_STEP_UP_M) -> torch.Tensor:
    """(B, F, J) terrain heights ``raw`` where a step reaches them from ``stand`` (B,), ``-inf`` (an obstacle) above."""
    return torch.where(raw <= stand[:, None, None] + step_up, raw, float("-inf"))


def ramp_snap(
    future: torch.Tensor, joints_world: torch.Tensor, lift: torch.Tensor, ground: torch.Tensor | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Let the floor snap's vertical shift grow over the primitive's frames instead of jumping at its start.

    Why: the snap moves each primitive as a whole, so the pelvis steps by the change in shift (millimetres)
    in the frame that enters the primitive: a vertical judder at the primitive rate (3.75 Hz), the largest
    part of the pelvis's boundary acceleration with the snap on (docs/motion.md, "Pops at primitive
    boundaries"). Here frame ``i`` of ``F`` keeps ``(i + 1) / F`` of ``lift``: the last frame, and so the next
    primitive's placement, is where the snap put it, and each frame takes ``lift / F`` of the step. Earlier
    frames sit up to ``lift (F - 1) / F`` short of the snapped height, but a lifted primitive's frames never
    below the floor (each goes down at most until its lowest joint touches it).

    Args:
        future: (B, F, 276) canonical features of the primitive; the canonical frame keeps z up, so its z
            values shift as the world's do.
        joints_world: (B, F, 22, 3) the primitive snapped as a whole.
        lift: (B,) metres the snap moved the primitive (z).
        ground: (B, F, J) terrain height under each joint (:func:`ground_under`), None for the floor at z = 0.

    Returns ``(joints_world, future)``, both with the ramped heights.
    """
    f = future.shape[1]
    frac = torch.arange(1, f + 1, device=future.device, dtype=future.dtype) / f
    off = lift[:, None] * (frac - 1.0)  # (B, F): 0 at the last frame
    # a lifted (sunk) primitive's early frames never go below the floor: each goes down at most until it touches it
    height = joints_world[..., 2] if ground is None else joints_world[..., 2] - ground
    lowest = height.amin(dim=-1)  # (B, F) each frame's lowest joint above the ground, snapped as a whole
    off = torch.maximum(off, -lowest.clamp(min=0.0))
    joints_world = joints_world.clone()
    joints_world[..., 2] += off[..., None]
    return joints_world, future + _height_edit(future, off)


def _height_edit(future: torch.Tensor, off: torch.Tensor) -> torch.Tensor:
    """(B, F, 276) the change of canonical features that raises frame k by ``off`` (B, F) metres (z up)."""
    delta = torch.cat((off[:, 1:], off[:, -1:]), dim=1) - off  # delta k = frame k+1 - frame k (last: 0)
    edit = torch.zeros_like(future)
    edit[..., SLICES["transl"].start + 2] = off
    edit[..., SLICES["transl_delta"].start + 2] = delta
    z_joints = torch.arange(SLICES["joints"].start + 2, SLICES["joints"].stop, 3, device=future.device)
    z_deltas = torch.arange(SLICES["joints_delta"].start + 2, SLICES["joints_delta"].stop, 3, device=future.device)
    edit[..., z_joints] = off[..., None].expand(-1, -1, NUM_JOINTS)
    edit[..., z_deltas] = delta[..., None].expand(-1, -1, NUM_JOINTS)
    return edit


def follow_steps(
    future: torch.Tensor, joints_world: torch.Tensor, lift: torch.Tensor, terrain: Terrain, stand: torch.Tensor,
    airborne: torch.Tensor, band: float,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """On a step, let a snapped primitive follow the ground frame by frame instead of moving as a whole.

    Why: the floor snap moves a primitive by its lowest joint over all its frames. Stepping up, the lift that
    stands the foot on the upper tread also lifts the frames before it, where the body still stands on the
    lower one: that foot floats by up to a riser. Stepping down, the foot still on the upper tread holds the
    whole primitive up, so the foot that steps down lands in the air and floats over the lower tread until a
    later primitive lets the body down. Here, in a primitive whose ground under its lowest joint changes by
    more than :data:`STEP_M` over its frames (a landed one, not a flight):

    - a lift grows over the frames (frame ``i`` of ``F`` keeps ``(i + 1) / F`` of it), as :func:`ramp_snap`;
    - the end comes down onto the lower ground: when the last frame's lowest joint is above the ground under
      it but no higher than ``band`` over the highest ground the primitive stood on, that ground at most
      :data:`MAX_STEP_UP_M` higher (a foot stepping down, not a flight or a ledge walked off), frame ``i`` goes
      down ``(i + 1) / F`` of that height, and the next primitive starts there;

    no frame ever below the ground under it, and no frame with a joint inside an obstacle (terrain too high to
    step on, :func:`ground_under`) lower than the snap put it. Primitives on even ground (every primitive on a
    flat floor) come back bit for bit as they went in.

    Args:
        future: (B, F, 276) canonical features of the primitive.
        joints_world: (B, F, 22, 3) the primitive snapped as a whole.
        lift: (B,) metres the snap moved it (z).
        terrain: the terrain (``height(xy)``).
        stand: (B,) world z of the body's lowest joint before the primitive (:func:`ground_under`).
        airborne: (B,) the snap's flags: the primitive is in flight (left as it is).
        band: the floor snap's contact band, metres.

    Returns ``(joints_world, future, drop)``: the followed joints and features, and (B,) the z the placement
    moves by (<= 0: the end's descent; the features are relative to the moved placement).
    """
    raw = terrain.height(joints_world[..., :2])
    ground = _steppable(raw, stand)  # as ground_under
    height = joints_world[..., 2] - ground  # (B, F, J); a joint over an obstacle reads +inf
    lowest, at = height.min(dim=-1)  # (B, F)
    blocked = ((joints_world[..., 2] < raw) & torch.isinf(ground)).any(dim=-1)  # (B, F) a joint inside an obstacle
    under = ground.gather(-1, at[..., None])[..., 0]
    finite = torch.isfinite(under)
    top = torch.where(finite, under, -torch.inf).amax(dim=1)  # the highest ground the primitive stood on
    step = (top - torch.where(finite, under, torch.inf).amin(dim=1) > STEP_M) & ~airborne
    f = future.shape[1]
    frac = torch.arange(1, f + 1, device=future.device, dtype=future.dtype) / f
    end = lowest[:, -1]
    down = top - under[:, -1]  # how far the ground under the end lies below the highest the primitive stood on
    landing = (end > 0) & torch.isfinite(end) & (end <= down + band) & (down <= MAX_STEP_UP_M)
    drop = torch.where(step & landing & ~blocked[:, -1], -end, torch.zeros_like(end))
    off = lift.clamp(min=0)[:, None] * (frac - 1.0) + drop[:, None] * frac
    off = torch.maximum(off, -lowest)
    off = torch.where(step[:, None] & ~(blocked & (off < 0)), off, torch.zeros_like(off))
    moved = joints_world.clone()
    moved[..., 2] += off[..., None]
    rows = step[:, None, None, None]
    joints_world = torch.where(rows, moved, joints_world)
    future = torch.where(step[:, None, None], future + _height_edit(future, off - drop[:, None]), future)
    return joints_world, future, drop


def lock_feet(
    future: torch.Tensor,
    joints_world: torch.Tensor,
    placement: WorldTransform,
    before: torch.Tensor,
    min_weight: float = LOCK_MIN_WEIGHT,
    terrain: Terrain | None = None,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Slide the whole body back under a planted foot, frame by frame (the *foot lock*).

    Why: the model's feet slide while on the floor (walk ~10 cm/s, docs/benchmarks.md), and a policy
    learns to use that slide to travel (a hop policy moved at 1.56 m/s on feet sliding at 16 cm/s).
    Games extract root motion from the planted foot; this does the same after sampling. Each frame's
    horizontal displacement of the foot joints (10, 11) is weighted by DART's contact ramp (1 on the
    floor, 0 from 3 cm up, the weight of its skate metric) and the body is shifted by minus the weighted
    mean, so a single planted foot stays where it landed; the shifts accumulate over the primitive and
    carry into the next one. Like the floor snap, it never changes the model's input: only the world
    placement of the frames, and the returned features in step with it. The next state's history is the
    unshifted last two frames placed with the last frame's shift, so its first frame sits one frame's
    correction (millimetres) away from where it was drawn.

    Args:
        future: (B, 8, 276) canonical features of the primitive.
        joints_world: (B, 8, 22, 3) its joints in the world (floor snap applied).
        placement: the canonical -> world transform that placed them (rotation about z only).
        before: (B, 2, 3) world foot joints of the frame before the primitive.
        min_weight: the summed contact weight from which a frame's slide is undone fully; below it the
            correction scales with the weight (:data:`LOCK_MIN_WEIGHT`). Why it matters: DART's skate
            counts a foot up to 3 cm high, and at 0.5 a foot in the band's upper half still slides (a run's
            skate 3.7 cm/s, 1.7 of it horizontal; at 0.05: 2.8 and 0.5, docs/motion.md).
        terrain: the ground a foot's height is measured from (a foot on a tread is planted); None: z = 0.

    Returns:
        ``(joints_world, future, shift)``: both shifted, and (B, 3) world shift of the last frame (what
        the next primitive's placement adds).
    """
    feet = torch.cat((before[:, None], foot_positions(joints_world)), dim=1)  # (B, 9, 2, 3)
    heights = feet[..., 2] if terrain is None else feet[..., 2] - terrain.height(feet[..., :2])
    weight = skate_weights(heights)  # (B, 8, 2)
    slide = feet[:, 1:, :, :2] - feet[:, :-1, :, :2]  # (B, 8, 2, 2)
    step = -(weight[..., None] * slide).sum(dim=2) / weight.sum(dim=2).clamp(min=min_weight)[..., None]
    moved = step.cumsum(dim=1)
    shift = torch.cat((moved, torch.zeros_like(moved[..., :1])), dim=-1)  # (B, 8, 3) world, z = 0
    joints_world = joints_world + shift[:, :, None, :]
    local = shift @ placement.rotation  # the same shifts in the canonical frame (R^T v)
    local_delta = torch.cat((local[:, 1:], local[:, -1:]), dim=1) - local  # delta k = frame k+1 - frame k
    repeat = (1, 1, NUM_JOINTS)
    edit = torch.zeros_like(future)
    edit[..., SLICES["transl"]] = local
    edit[..., SLICES["joints"]] = local.repeat(repeat)
    edit[..., SLICES["transl_delta"]] = local_delta
    edit[..., SLICES["joints_delta"]] = local_delta.repeat(repeat)
    return joints_world, future + edit, shift[:, -1]
