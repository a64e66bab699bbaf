"""Faults in ``latentrl motion train``: a NaN loss stops it (exit 3) keeping the last good ``state.pt``, and a
resume continues after the last saved step instead of repeating it."""

import math
import re
from pathlib import Path

import torch

from latentrl.app.cli import main
from latentrl.motion_training import trainer as trainer_module
from latentrl.safe_io import load_torch

ROOT = Path(__file__).resolve().parents[2]
MTINY = str(ROOT / "configs" / "motion" / "tiny.yaml")
SMALL = ["--set", "data.locomotion.num_sequences=3", "--set", "vae_train.steps=6", "--set", "denoiser_train.steps=2",
         "--set", "checkpoint_every=2", "--set", "log_every=1", "--no-progress"]



def test_nan_loss_stops_motion_training_and_resume_continues_after_the_last_saved_step(tmp_path, monkeypatch, capsys):
    run = tmp_path / "run"
    original, calls = trainer_module.vae_step, []

    def poisoned(*args, **kwargs):
        loss, terms, pred = original(*args, **kwargs)
        calls.append(1)
        return (loss * math.nan if len(calls) == 4 else loss), terms, pred  # step 3 (0-based)

    monkeypatch.setattr(trainer_module, "vae_step", poisoned)
    assert main(["motion", "train", MTINY, "--run-dir", str(run), *SMALL]) == 3
    err = capsys.readouterr().err
    state_file = run / "checkpoints" / "state.pt"
    last = re.escape(str(state_file))
    assert re.fullmatch(r"latentrl: error: motion train: vae step 3: loss is nan; training stopped without saving "
                        rf"\(last good checkpoint: {last}\); lower vae_train.learning_rate\n", err)
    state = load_torch(state_file)
    assert (state["stage"], state["step"]) == ("vae", 2)  # saved after 2 steps; steps 2 and 3 were not saved
    assert all(torch.isfinite(v).all() for v in state["vae"].values())

    monkeypatch.setattr(trainer_module, "vae_step", original)
    assert main(["motion", "train", "--resume", str(run), "--no-progress"]) == 0
    steps = [int(m) for m in re.findall(r"^vae step (\d+):", (run / "train.log").read_text(), re.M)]
    assert steps == [0, 1, 2, 3, 2, 3, 4, 5]  # the killed run logged 0-3; the resume redid 2, 3 (unsaved), then on
    assert load_torch(state_file)["stage"] == "denoiser" and (run / "motion_model.pt").is_file()
