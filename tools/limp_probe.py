"""Does a model's walk limp? Each foot's share of frames alone on the floor, in chained rollouts and in one primitive.

    python tools/limp_probe.py MODEL.pt [MODEL.pt ...] --data RUN_DIR/data [--seconds 20] [--json out.json]

A foot is down within 5 cm of the floor (the bench's contact rule). Per model:

- ``rollout``: 8 chained ``walk`` rollouts of ``--seconds`` (guidance 5, seed 0, floor snap on): left foot alone,
  right foot alone, and each foot's mean height;
- ``primitive``: one DDIM sample (N(0, I) noise, guidance 5) from each of up to 512 data ``walk`` primitives'
  true history, the feet measured over the primitive's 8 future frames above the data primitive's lowest foot;
  ``data``: the same frames of the data itself.

A walk that limps in the rollout but not in one primitive falls into the limp as it chains its own output.
"""

from __future__ import annotations

import argparse
import json

import torch

from latentrl.datasets.primitives import PrimitiveDataset
from latentrl.evaluation import metrics as M
from latentrl.motion import load_motion_model
from latentrl.motion.representation import HISTORY_LENGTH, joints_of
from latentrl.motion.skeleton import FOOT_JOINTS
from latentrl.safe_io import atomic_write_text

DOWN_M = 0.05


def shares(feet_z: torch.Tensor) -> dict[str, float]:
    """(..., 2) foot heights above the floor -> left alone, right alone, mean heights (cm)."""
    left, right = feet_z[..., 0] < DOWN_M, feet_z[..., 1] < DOWN_M
    return {"left_alone": float((left & ~right).float().mean()), "right_alone": float((right & ~left).float().mean()),
            "left_height_cm": float(feet_z[..., 0].mean()) * 100, "right_height_cm": float(feet_z[..., 1].mean()) * 100}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("models", nargs="+")
    ap.add_argument("--data", required=True, help="the models' training data folder (a run's data/)")
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--json")
    args = ap.parse_args()
    data = PrimitiveDataset.from_folder(args.data)
    batch = data.sample(6000, 1, generator=torch.Generator().manual_seed(0))
    walk = batch.motion[:, 0][batch.text_index[:, 0] == data.texts.index("walk")][:512]
    history = walk[:, :HISTORY_LENGTH]
    floor = joints_of(walk)[:, :, list(FOOT_JOINTS), 2].amin(dim=(1, 2))

    def future_feet(frames: torch.Tensor) -> torch.Tensor:
        return joints_of(frames)[:, :, list(FOOT_JOINTS), 2] - floor[:, None, None]

    results = {"data": shares(future_feet(walk[:, HISTORY_LENGTH:]))}
    print(f"data | primitive | {results['data']}", flush=True)
    for name in args.models:
        model = load_motion_model(name)
        with torch.no_grad():
            roll = model.rollout("walk", round(args.seconds * 30 / 8), batch=8,
                                 generator=torch.Generator().manual_seed(0))
            noise = torch.randn(len(walk), *model.latent_shape, generator=torch.Generator().manual_seed(1))
            sampled = model.sample_primitive(history, model.encode_text(["walk"] * len(walk)), noise, 5.0).future
        feet = roll.joints_world[:, HISTORY_LENGTH:, list(FOOT_JOINTS), 2]
        results[name] = {"rollout": shares(feet), "primitive": shares(future_feet(sampled)),
                         "rollout_contact_shares": {k: float(v.mean()) for k, v in
                                                    M.foot_contact_shares(roll.joints_world).items()}}
        for kind in ("rollout", "primitive"):
            print(f"{name} | {kind} | {results[name][kind]}", flush=True)
    if args.json:
        atomic_write_text(args.json, json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
