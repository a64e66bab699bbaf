"""How far a motion model's noise reaches, and why: figures that compare denoiser levers.

    python tools/denoiser_probe.py MODEL.pt [MODEL.pt ...] --data RUN_DIR/data [--json out.json]

Per prompt (walk, run, both hops), on primitives of the model's own training data (``--data``):

- ``steer`` / ``box4``: ``latentrl bench motion``'s steer spread (N(0, I) noise, and noise uniform in
  the policy's +-4 box), degrees over 32 frames;
- ``cond_var``: the variance of the sampled latent over 64 noises from one data history (mean over 8
  histories, guidance 5) -- how much the noise changes the primitive at all;
- ``x0_err_t0/t5/t9``: mean squared error of the denoiser's clean-latent prediction for data latents
  noised to the least noisy, a middle and the noisiest step. An error at t0 close to the one at t9
  means the network ignores ``x_t`` and its samples collapse toward the mean given the history.
"""

from __future__ import annotations

import argparse
import json

import torch

from latentrl.app.bench.motion import steering_spread_deg
from latentrl.datasets.primitives import PrimitiveDataset
from latentrl.motion import load_motion_model

PROMPTS = ("walk", "run", "hop on left leg", "hop on right leg")


def probe(model, motion: torch.Tensor, text_index: torch.Tensor, texts: list[str]) -> dict:
    g = torch.Generator().manual_seed(0)
    out = {}
    for text in PROMPTS:
        sel = text_index == texts.index(text)
        h, f = motion[sel][:128, :2], motion[sel][:128, 2:]
        n = h.shape[0]
        with torch.no_grad():
            hn, fn = (h - model.mean) / model.std, (f - model.mean) / model.std
            z = model.vae.encode(fn, hn)[0] / model.vae.latent_std
            cond = model.denoiser.condition(hn, model.encode_text([text] * n))
            err = {}
            for t in (0, 5, model.diffusion.num_timesteps - 1):
                steps = torch.full((n,), t)
                x_t = model.diffusion.q_sample(z, steps, torch.randn(z.shape, generator=g))
                err[f"x0_err_t{t}"] = float(((model.denoiser.denoise(x_t, steps, cond) - z) ** 2).mean())
            emb, var = model.encode_text([text] * 64), []
            for k in range(8):
                hist = h[k : k + 1].expand(64, -1, -1)
                noise = torch.randn(64, *model.latent_shape, generator=g)
                var.append(float(model.sample_primitive(hist, emb, noise, 5.0).latent.var(0).mean()))
        out[text] = {"steer": steering_spread_deg(model, text),
                     "box4": steering_spread_deg(model, text, action_box=4.0),
                     "cond_var": sum(var) / len(var), **err}
    return out


def probe_inputs(doc: str, primitives: int) -> tuple[argparse.Namespace, PrimitiveDataset, torch.Tensor, torch.Tensor]:
    """The probes' shared command line (MODELS, ``--data``, ``--json``) and a seeded sample of data primitives.

    Returns ``(args, data, motion (P, 10, 276), text_index (P,))``; ``tools/skate_probe.py`` uses it too.
    """
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("models", nargs="+", help="motion model files or names ('default', 'default-v4')")
    ap.add_argument("--data", required=True, help="the models' training data folder (a run's data/)")
    ap.add_argument("--json", help="write the figures here")
    args = ap.parse_args()
    data = PrimitiveDataset.from_folder(args.data)
    batch = data.sample(primitives, 1, generator=torch.Generator().manual_seed(0))
    return args, data, batch.motion[:, 0], batch.text_index[:, 0]


def write_json(path: str | None, results: dict) -> None:
    """Write the figures atomically where ``--json`` says, if it says."""
    if path:
        from latentrl.safe_io import atomic_write_text

        atomic_write_text(path, json.dumps(results, indent=2) + "\n")


def main() -> None:
    args, data, motion, text_index = probe_inputs(__doc__, 4000)
    results = {}
    for name in args.models:
        results[name] = probe(load_motion_model(name), motion, text_index, data.texts)
        for text, row in results[name].items():
            print(f"{name} | {text:16s} | " + " ".join(f"{k} {v:.3f}" for k, v in row.items()), flush=True)
    write_json(args.json, results)


if __name__ == "__main__":
    main()
