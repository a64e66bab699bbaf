"""Where a motion model's foot skate comes from: the data, the VAE's reconstruction, or the sampler.

    python tools/skate_probe.py MODEL.pt [MODEL.pt ...] --data RUN_DIR/data [--json out.json] [--integrate]

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

``--integrate`` adds ``vae_integrated`` and ``sampled_integrated``: the same decoded primitives with their joint
positions rebuilt from the last history frame's joints and the decoded ``joints_delta`` summed frame by frame
(the history frame's delta first), so a foot the decoder says is still stays where it was instead of taking each
frame's own position estimate.
"""

from __future__ import annotations

import sys
from pathlib import Path

import torch

from latentrl.evaluation.metrics import foot_skate_cm_s
from latentrl.motion import load_motion_model
from latentrl.motion.representation import HISTORY_LENGTH, SLICES, joints_of
from latentrl.motion.skeleton import FOOT_JOINTS, NUM_JOINTS

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


def integrated(frames: torch.Tensor) -> torch.Tensor:
    """(B, H + F, 276) frames whose future joints are the last history frame's plus the summed ``joints_delta``."""
    out = frames.clone()
    joints, delta = joints_of(out), out[..., SLICES["joints_delta"]].unflatten(-1, (NUM_JOINTS, 3))
    for t in range(HISTORY_LENGTH, out.shape[1]):
        joints[:, t] = joints[:, t - 1] + delta[:, t - 1]
    return out


def probe(model, motion: torch.Tensor, text: str, integrate: bool = False) -> dict[str, dict[str, float]]:
    history = motion[:, :HISTORY_LENGTH]
    floor = joints_of(motion)[:, :, list(FOOT_JOINTS), 2].amin(dim=(1, 2))
    with torch.no_grad():
        history_n = (history - model.mean) / model.std
        future_n = (motion[:, HISTORY_LENGTH:] - model.mean) / model.std
        mean = model.vae.encode(future_n, history_n)[0]
        recon = model.vae.decode(mean, history_n, future_n.shape[1], scale_latent=False) * model.std + model.mean
        noise = torch.randn(motion.shape[0], *model.latent_shape, generator=torch.Generator().manual_seed(1))
        sampled = model.sample_primitive(history, model.encode_text([text] * motion.shape[0]), noise, 5.0).future
    truth = joints_of(motion[:, HISTORY_LENGTH:])
    rows = {"data": figures(motion, floor)}
    for label, future in (("vae", recon), ("sampled", sampled)):
        for suffix, frames in (("", torch.cat((history, future), 1)),
                               *((("_integrated", integrated(torch.cat((history, future), 1))),) if integrate else ())):
            error_cm = (joints_of(frames[:, HISTORY_LENGTH:]) - truth).norm(dim=-1).mean() * 100.0
            rows[label + suffix] = {**figures(frames, floor), "joint_error_cm": float(error_cm)}
    return rows


def main() -> None:
    integrate = "--integrate" in sys.argv
    if integrate:
        sys.argv.remove("--integrate")
    args, data, motion, text_index = probe_inputs(__doc__, 6000)
    results: dict = {}
    for name in args.models:
        model = load_motion_model(name)
        for text in PROMPTS:
            rows = probe(model, motion[text_index == data.texts.index(text)][:256], text, integrate)
            results.setdefault(name, {})[text] = rows
            for label, row in rows.items():
                print(f"{name} | {text:16s} | {label:8s} | " + " ".join(f"{k} {v:.3f}" for k, v in row.items()),
                      flush=True)
    write_json(args.json, results)


if __name__ == "__main__":
    main()
