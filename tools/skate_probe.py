"""Where a motion model's foot skate comes from: the data, the VAE's reconstruction, or the sampler.

    python tools/skate_probe.py MODEL.pt [MODEL.pt ...] --data RUN_DIR/data [--json out.json]

Per prompt (walk, run, hop on left leg), on up to 256 primitives of the models' training data (``--data``,
a ``latentrl motion train`` run's ``data/``), over the last history frame and the 8 future frames:

- ``skate`` / ``skate_xy``: DART's skate metric (cm/s) and its horizontal part, with the floor at the lowest
  foot joint of the data primitive (the canonical frame keeps z up, so one floor serves data and model);
- ``band``: the share of future foot-frames inside DART's 3 cm contact band but off the floor (> 2 mm),
  where the metric counts feet that merely lift or land;

for the data itself (``data``), the VAE's reconstruction of each data primitive from its posterior mean
(``vae``, with ``joint_error_cm``: its mean joint position error against the data's future frames), and one
DDIM sample per primitive from the data history with N(0, I) noise at guidance 5 (``sampled``). A model
whose reconstruction already skates cannot be fixed by its denoiser or its policies.
"""

from __future__ import annotations

import sys
from pathlib import Path

import torch

from latentrl.evaluation.metrics import foot_skate_cm_s
from latentrl.motion import load_motion_model
from latentrl.motion.representation import HISTORY_LENGTH, joints_of
from latentrl.motion.skeleton import FOOT_JOINTS

sys.path.insert(0, str(Path(__file__).resolve().parent))  # the sibling script, however this one is loaded
from denoiser_probe import probe_inputs, write_json  # noqa: E402

PROMPTS = ("walk", "run", "hop on left leg")
BAND_M = 0.03
OFF_FLOOR_M = 0.002


def figures(frames: torch.Tensor, floor: torch.Tensor) -> dict[str, float]:
    """``skate``, ``skate_xy`` and ``band`` of (B, H + F, 276) unnormalized frames above per-primitive floors."""
    joints = joints_of(frames)[:, HISTORY_LENGTH - 1 :].clone()
    joints[..., 2] -= floor[:, None, None]
    feet_z = joints[:, 1:, list(FOOT_JOINTS), 2]
    return {"skate": float(foot_skate_cm_s(joints).mean()),
            "skate_xy": float(foot_skate_cm_s(joints, horizontal=True).mean()),
            "band": float(((feet_z > OFF_FLOOR_M) & (feet_z < BAND_M)).float().mean())}


def probe(model, motion: torch.Tensor, text: str) -> dict[str, dict[str, float]]:
    history = motion[:, :HISTORY_LENGTH]
    floor = joints_of(motion)[:, :, list(FOOT_JOINTS), 2].amin(dim=(1, 2))
    with torch.no_grad():
        history_n = (history - model.mean) / model.std
        future_n = (motion[:, HISTORY_LENGTH:] - model.mean) / model.std
        mean = model.vae.encode(future_n, history_n)[0]
        recon = model.vae.decode(mean, history_n, future_n.shape[1], scale_latent=False) * model.std + model.mean
        noise = torch.randn(motion.shape[0], *model.latent_shape, generator=torch.Generator().manual_seed(1))
        sampled = model.sample_primitive(history, model.encode_text([text] * motion.shape[0]), noise, 5.0).future
    error_cm = (joints_of(recon) - joints_of(motion[:, HISTORY_LENGTH:])).norm(dim=-1).mean() * 100.0
    return {"data": figures(motion, floor),
            "vae": {**figures(torch.cat((history, recon), 1), floor), "joint_error_cm": float(error_cm)},
            "sampled": figures(torch.cat((history, sampled), 1), floor)}


def main() -> None:
    args, data, motion, text_index = probe_inputs(__doc__, 6000)
    results: dict = {}
    for name in args.models:
        model = load_motion_model(name)
        for text in PROMPTS:
            rows = probe(model, motion[text_index == data.texts.index(text)][:256], text)
            results.setdefault(name, {})[text] = rows
            for label, row in rows.items():
                print(f"{name} | {text:16s} | {label:8s} | " + " ".join(f"{k} {v:.3f}" for k, v in row.items()),
                      flush=True)
    write_json(args.json, results)


if __name__ == "__main__":
    main()
