"""The motion training pipeline on a seconds-long config (real data generator, real models)."""

from pathlib import Path

import pytest
import torch

from latentrl.config import load_config
from latentrl.errors import ConfigError
from latentrl.motion import load_motion_model
from latentrl.motion.representation import FEATURE_DIM
from latentrl.motion_training.losses import StageConfig, consistency_losses
from latentrl.motion_training.trainer import MotionTrainConfig, MotionTrainer

ROOT = Path(__file__).resolve().parents[2]
TINY = ROOT / "configs" / "motion" / "tiny.yaml"


def tiny_config(**overrides) -> MotionTrainConfig:
    return load_config(MotionTrainConfig, TINY, [f"{k}={v}" for k, v in overrides.items()])


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    run = tmp_path_factory.mktemp("motion_run")
    trainer = MotionTrainer(tiny_config(), run, progress=False)
    out = trainer.run()
    return run, out


def test_run_writes_model_log_events_and_checkpoint(trained):
    run, out = trained
    assert out.is_file() and (run / "config.yaml").is_file() and (run / "checkpoints" / "state.pt").is_file()
    assert any(p.name.startswith("events.out.tfevents") for p in run.iterdir())
    lines = (run / "train.log").read_text().splitlines()
    assert lines[0].startswith("vae step 0:") and any(line.startswith("denoiser step") for line in lines)
    model = load_motion_model(out)
    assert model.latent_shape == (1, 16) and model.text_dim == 64
    assert model.seed_history is not None and model.seed_history.shape[1:] == (2, FEATURE_DIM)
    assert 0.0 < float(model.vae.latent_std) < 10.0
    roll = model.rollout("walk", num_steps=3, batch=2, generator=torch.Generator().manual_seed(0))
    assert torch.isfinite(roll.joints_world).all()


def test_tensorboard_scalars(trained):
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    run, _ = trained
    acc = EventAccumulator(str(run))
    acc.Reload()
    tags = set(acc.Tags()["scalars"])
    assert {"motion/vae/rec", "motion/vae/kl", "motion/vae/joints_delta", "motion/denoiser/latent_rec",
            "motion/denoiser/feature_rec", "motion/denoiser/learning_rate"} <= tags


def test_seeded_runs_are_identical(trained, tmp_path):
    _, out = trained
    again = MotionTrainer(tiny_config(), tmp_path / "again", progress=False).run()
    a, b = torch.load(out, weights_only=True), torch.load(again, weights_only=True)
    for key in a["denoiser_state"]:
        assert torch.equal(a["denoiser_state"][key], b["denoiser_state"][key]), key


def test_resume_continues_to_the_same_result(trained, tmp_path):
    _, out = trained
    run = tmp_path / "resumed"
    trainer = MotionTrainer(tiny_config(), run, progress=False)
    trainer._train_vae(_NullBar(), 0.0)  # a run killed right after its VAE stage
    trainer.stage, trainer.step = "denoiser", 0
    trainer.save_checkpoint()
    fresh = MotionTrainer(tiny_config(), run, progress=False)
    fresh.load_checkpoint(run / "checkpoints" / "state.pt")
    assert fresh.stage == "denoiser" and fresh.step == 0
    result = fresh.run()
    a, b = torch.load(out, weights_only=True), torch.load(result, weights_only=True)
    for key in a["vae_state"]:
        assert torch.equal(a["vae_state"][key], b["vae_state"][key]), key


def test_resume_refuses_other_config(trained, tmp_path):
    run, _ = trained
    other = MotionTrainer(tiny_config(seed=1), tmp_path / "other", progress=False)
    with pytest.raises(Exception, match="different config"):
        other.load_checkpoint(run / "checkpoints" / "state.pt")


class _NullBar:
    def update(self, n):
        pass

    def set_postfix(self, **kw):
        pass


def test_config_errors_name_the_field(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("vae_train: {stepz: 10}\n")
    with pytest.raises(ConfigError, match=r"(?i)bad.yaml: vae_train.stepz: .*did you mean.*steps"):
        load_config(MotionTrainConfig, bad)
    with pytest.raises(ConfigError, match=r"vae_train.learning_rate: must be > 0"):
        load_config(MotionTrainConfig, TINY, ["vae_train.learning_rate=-1"])
    with pytest.raises(ConfigError, match="text_encoder"):
        load_config(MotionTrainConfig, TINY, ["text_encoder=clip"])
    with pytest.raises(ConfigError, match=r"model.denoiser.prediction: expected one of \['x0', 'v'\], got 'eps'"):
        load_config(MotionTrainConfig, TINY, ["model.denoiser.prediction=eps"])


def test_v_prediction_trains_on_a_given_vae_saves_and_reloads(trained, tmp_path):
    """A v-predicting denoiser trains on the VAE of a finished run (``--vae-from``), and the saved model
    samples the same after loading.

    The schedule buffers are not saved (the diffusion config is): loading must re-attach them.
    """
    _, first = trained
    run = tmp_path / "v"
    trainer = MotionTrainer(tiny_config(**{"model.denoiser.prediction": "v"}), run, progress=False)
    trainer.start_from_vae(first)
    out = trainer.run()
    assert not any(line.startswith("vae step") for line in (run / "train.log").read_text().splitlines())
    source, saved = torch.load(first, weights_only=True), torch.load(out, weights_only=True)
    assert all(torch.equal(source["vae_state"][k], saved["vae_state"][k]) for k in source["vae_state"])
    assert saved["meta"]["vae_from"]["path"] == str(first)
    model = load_motion_model(out)
    assert model.denoiser.config.prediction == "v"
    assert "v_signal" not in torch.load(out, weights_only=True)["denoiser_state"]
    built = trainer.build_model()
    noise = torch.randn(3, *model.latent_shape, generator=torch.Generator().manual_seed(1))
    history = model.seed_history[:1].expand(3, -1, -1)
    text = model.encode_text(["walk"] * 3)
    a = model.sample_primitive(history, text, noise).future
    b = built.sample_primitive(history, text, noise).future
    assert torch.isfinite(a).all() and torch.allclose(a, b, atol=1e-5)


def test_vae_from_refuses_another_vae_or_other_data(trained, tmp_path):
    _, first = trained
    other_shape = MotionTrainer(tiny_config(**{"model.vae.h_dim": 48}), tmp_path / "shape", progress=False)
    with pytest.raises(ConfigError, match=r"--vae-from .*model.vae in \['h_dim'\] \(h_dim: 32 vs 48\)"):
        other_shape.start_from_vae(first)
    other_data = MotionTrainer(tiny_config(**{"data.locomotion.num_sequences": 5}), tmp_path / "data", progress=False)
    with pytest.raises(ConfigError, match="trained on other data"):
        other_data.start_from_vae(first)


def test_rollout_probability_schedule():
    cfg = StageConfig(steps=300, supervised_fraction=1 / 3, scheduled_fraction=1 / 3)
    assert cfg.rollout_probability(0) == 0.0 and cfg.rollout_probability(99) == 0.0
    assert cfg.rollout_probability(150) == pytest.approx(0.5)
    assert cfg.rollout_probability(200) == 1.0 and cfg.rollout_probability(299) == 1.0


def test_consistency_losses_zero_for_consistent_frames():
    from latentrl.motion.representation import compute_features
    from tests.helpers import walking_clip

    clip = walking_clip(12, seed=2)
    feats = compute_features(clip["transl"], clip["rotations"], clip["joints"])[None]
    terms = consistency_losses(feats[:, 1:2], feats[:, 2:10])
    for value in terms.values():
        assert float(value) < 1e-10
    shifted = feats.clone()
    shifted[:, 3:10, 144:210] += 0.5
    assert float(consistency_losses(shifted[:, 1:2], shifted[:, 2:10])["joints_delta"]) > 1e-3


def test_seam_loss_known_answer():
    """The step from the last history frame to the first future frame, against the data's, in m^2."""
    from latentrl.motion_training.losses import seam_loss

    history, target = torch.zeros(1, 2, FEATURE_DIM), torch.zeros(1, 8, FEATURE_DIM)
    assert float(seam_loss(history, target, history, target)) == 0.0
    popped = target.clone()
    popped[:, :, 144:210] += torch.tensor([0.03, 0.04, 0.0]).repeat(22)  # the whole future 5 cm off the history
    assert float(seam_loss(history, popped, history, target)) == pytest.approx(0.05**2)
    later = target.clone()
    later[:, 1:, 144:210] += 0.5  # only later frames differ: not the seam's business
    assert float(seam_loss(history, later, history, target)) == 0.0
    # a rollout history placed elsewhere: only the step counts, not where the history is
    moved = history.clone()
    moved[:, :, 144:210] += 0.2
    assert float(seam_loss(moved, target, history, target)) == pytest.approx(3 * 0.2**2)
    shifted = target.clone()
    shifted[:, :, 144:210] += 0.2
    assert float(seam_loss(moved, shifted, history, target)) == pytest.approx(0.0, abs=1e-12)


def test_vae_step_adds_the_weighted_seam_term():
    from latentrl.motion.representation import Normalizer, compute_features
    from latentrl.motion.vae import PrimitiveVAE, VAEConfig
    from latentrl.motion_training.losses import VAETrainConfig, vae_step
    from tests.helpers import walking_clip

    clips = [walking_clip(11, seed=s) for s in range(4)]
    motion = torch.stack([compute_features(c["transl"], c["rotations"], c["joints"]) for c in clips])
    norm = Normalizer.from_data(motion)
    hist, fut = norm.normalize(motion[:, :2]), norm.normalize(motion[:, 2:])
    torch.manual_seed(0)
    vae = PrimitiveVAE(VAEConfig(latent_dim=(1, 8), h_dim=16, ff_size=32, num_layers=1, dropout=0.0))
    base, terms0, _ = vae_step(vae, hist, fut, norm, VAETrainConfig(), torch.Generator().manual_seed(1))
    loss, terms, _ = vae_step(vae, hist, fut, norm, VAETrainConfig(seam_weight=10.0), torch.Generator().manual_seed(1))
    assert "seam" not in terms0 and float(terms["seam"]) > 0.0
    assert float(loss) == pytest.approx(float(base) + 10.0 * float(terms["seam"]), rel=1e-5)
    with pytest.raises(ConfigError, match=r"vae_train.seam_weight: must be >= 0"):
        load_config(MotionTrainConfig, TINY, ["vae_train.seam_weight=-1"])
    with pytest.raises(ConfigError, match=r"denoiser_train.seam_weight: must be >= 0"):
        load_config(MotionTrainConfig, TINY, ["denoiser_train.seam_weight=-1"])


def test_denoiser_step_adds_the_weighted_seam_term_against_the_data_history(tiny_model):
    from latentrl.motion.representation import compute_features
    from latentrl.motion_training.losses import DenoiserTrainConfig, denoiser_step
    from tests.helpers import walking_clip

    clips = [walking_clip(11, seed=s) for s in range(3)]
    motion = torch.stack([compute_features(c["transl"], c["rotations"], c["joints"]) for c in clips])
    norm = tiny_model.normalizer
    hist, fut = norm.normalize(motion[:, :2]), norm.normalize(motion[:, 2:])
    text = torch.zeros(3, tiny_model.text_dim)
    den, vae, diff = tiny_model.denoiser, tiny_model.vae, tiny_model.diffusion

    def run(weight, gt_history):
        return denoiser_step(den, vae, diff, hist, gt_history, fut, text, norm,
                             DenoiserTrainConfig(seam_weight=weight), torch.Generator().manual_seed(2))

    base, terms0 = run(0.0, hist)
    loss, terms = run(5.0, hist)
    assert "seam" not in terms0 and float(terms["seam"]) > 0.0
    assert float(loss) == pytest.approx(float(base) + 5.0 * float(terms["seam"]), rel=1e-5)
    moved = hist.clone()
    moved[..., 144:210] += 0.1 / norm.std[144:210]  # the data's history 10 cm off: another target step
    assert float(run(5.0, moved)[1]["seam"]) != pytest.approx(float(terms["seam"]))
