"""Write a motion model file from a motion-training checkpoint, e.g. to probe a VAE stage before the denoiser ends.

    python tools/checkpoint_model.py RUN_DIR STATE.pt OUT.pt

RUN_DIR holds the run's ``config.yaml`` and ``data/``; STATE.pt is a ``checkpoints/state.pt`` of that run (or a copy
taken when its VAE stage ended). The file carries the EMA weights as ``latentrl motion train`` would write them at
that point; its denoiser is only as trained as the checkpoint's step.
"""

from __future__ import annotations

import sys
from pathlib import Path

from latentrl.config import load_config
from latentrl.motion.checkpoint import save_motion_model
from latentrl.motion_training.trainer import MotionTrainConfig, MotionTrainer


def main(run: Path, state: Path, out: Path) -> None:
    """Rebuild the trainer of ``run``, load ``state`` and save its model to ``out``."""
    cfg = load_config(MotionTrainConfig, run / "config.yaml")
    trainer = MotionTrainer(cfg, run, progress=False)
    trainer.load_checkpoint(state)
    meta = {"from_checkpoint": str(state), "stage": trainer.stage, "step": trainer.step,
            "texts": trainer.dataset.texts}
    save_motion_model(trainer.build_model(), out, meta=meta)
    print(f"wrote {out} (stage {trainer.stage}, step {trainer.step})")


if __name__ == "__main__":
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    main(Path(sys.argv[1]), Path(sys.argv[2]), Path(sys.argv[3]))
