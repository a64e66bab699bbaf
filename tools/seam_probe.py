"""Where the pop at primitive boundaries comes from: the data chain, the VAE, or the sampler.

    python tools/seam_probe.py MODEL.pt --data RUN_DIR/data [--json out.json]

Each figure compares the frame that crosses a primitive boundary (the last history frame -> the first
decoded frame) with the frames inside a primitive:

- ``canon_feet_cm``: in the canonical frame of the primitive, before any placement, the mean distance of
  the two foot joints between consecutive frames (boundary / inside), as the model outputs them;
- ``planted_cm``: the horizontal step of a foot joint on the floor (both frames within 3 cm of the
  lowest foot joint of the window), boundary / inside, after chaining primitives as the rollout does.

Rows: ``data`` (windows of 8 consecutive data primitives chained with the rollout's re-canonicalization,
whose hand-off must reproduce the data: ``history_feature_max_err``), ``vae`` (each data primitive decoded from
its posterior mean with its true history; canonical figures and the first / later frames' foot error against the
data), ``vae_chain`` (decoded primitives feeding their own last frames back as the next history, latents
encoded with that history), and ``sampled`` / ``sampled_snap`` / ``sampled_snap_ramp`` (the model's own rollout
of ``--text`` from its seed histories, 16 x 9 primitives, guidance 5: floor snap off / on / on and ramped, with
the pelvis acceleration at boundaries against the rest, ``seam_ratios``; ``--vae-only`` leaves them out).
"""

from __future__ import annotations

import argparse
import json

import torch

from latentrl.datasets.primitives import PrimitiveDataset
from latentrl.evaluation import metrics as M
from latentrl.motion import load_motion_model
from latentrl.motion.canonical import WorldTransform, canonicalize
from latentrl.motion.representation import HISTORY_LENGTH, joints_of
from latentrl.motion.skeleton import FOOT_JOINTS

FEET = list(FOOT_JOINTS)


def canon_feet(prims: torch.Tensor) -> dict[str, float]:
    """(B, N, H + F, 276) canonical primitives -> foot distance at the seam (history -> first future) vs inside."""
    feet = joints_of(prims)[..., FEET, :]
    step = (feet[:, :, 1:] - feet[:, :, :-1]).norm(dim=-1).mean(dim=-1)  # (B, N, H + F - 1)
    seam = step[..., HISTORY_LENGTH - 1]
    inside = step[..., HISTORY_LENGTH:]
    return {"boundary": float(seam.mean() * 100), "inside": float(inside.mean() * 100),
            "ratio": float(seam.mean() / inside.mean())}


def chain(prims: torch.Tensor, pelvis_delta: torch.Tensor) -> torch.Tensor:
    """(B, N, H + F, 276) primitives, each in its own canonical frame -> (B, H + N F, 22, 3) world joints.

    Places them as ``MotionModel.rollout_step`` does: the next frame is the canonical frame of the last H frames.
    """
    b, n = prims.shape[:2]
    world = WorldTransform.identity(b)
    out = [world.apply(joints_of(prims[:, 0, :HISTORY_LENGTH]))]
    for k in range(n):
        future = prims[:, k, HISTORY_LENGTH:]
        out.append(world.apply(joints_of(future)))
        _, rot, origin = canonicalize(future[:, -HISTORY_LENGTH:], pelvis_delta)
        world = world.compose(rot, origin)
    return torch.cat(out, dim=1)


def planted(joints: torch.Tensor, future: int = 8, contact_m: float = 0.03) -> dict[str, float]:
    """(B, T, 22, 3) world joints, 2 history frames then ``future`` per primitive -> planted-foot steps."""
    feet = joints[:, :, FEET, :]
    floor = feet[..., 2].amin(dim=(1, 2), keepdim=True)
    h = feet[..., 2] - floor
    down = (h[:, 1:] < contact_m) & (h[:, :-1] < contact_m)  # (B, T-1, 2)
    step = (feet[:, 1:, :, :2] - feet[:, :-1, :, :2]).norm(dim=-1)
    t = torch.arange(joints.shape[1] - 1)
    seam = ((t + 1 - HISTORY_LENGTH) % future == 0)[None, :, None] & down
    inside = (~(t + 1 - HISTORY_LENGTH).remainder(future).eq(0))[None, :, None] & down
    b = float(step[seam].mean() * 100)
    i = float(step[inside].mean() * 100)
    return {"boundary": b, "inside": i, "ratio": b / i, "n_boundary": int(seam.sum()), "n_inside": int(inside.sum())}


@torch.no_grad()
def vae_decode(model, history: torch.Tensor, future: torch.Tensor) -> torch.Tensor:
    """Decode ``future``'s posterior mean with ``history`` (both unnormalized canonical) -> unnormalized future."""
    hn, fn = (history - model.mean) / model.std, (future - model.mean) / model.std
    mu = model.vae.encode(fn, hn)[0]
    return model.vae.decode(mu, hn, fn.shape[1], scale_latent=False) * model.std + model.mean


@torch.no_grad()
def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("model")
    ap.add_argument("--data", required=True)
    ap.add_argument("--windows", type=int, default=64)
    ap.add_argument("--text", default="walk")
    ap.add_argument("--vae-only", action="store_true", help="skip the sampled rows (a VAE-stage model)")
    ap.add_argument("--json")
    args = ap.parse_args()
    torch.manual_seed(0)
    model = load_motion_model(args.model)
    data = PrimitiveDataset.from_folder(args.data)
    n = 8
    batch = data.sample(args.windows, n, generator=torch.Generator().manual_seed(0))
    prims = batch.motion  # (B, N, 10, 276)
    pd = data.pelvis_delta
    res: dict[str, dict] = {}

    # (a) data: the rollout's re-canonicalization of the last H frames must give the next primitive's history
    nxt, _, _ = canonicalize(prims[:, :-1, -HISTORY_LENGTH:].reshape(-1, HISTORY_LENGTH, 276), pd)
    hist_err = (nxt - prims[:, 1:, :HISTORY_LENGTH].reshape(-1, HISTORY_LENGTH, 276)).abs().max()
    world = chain(prims, pd)
    # the same window straight from the world-frame features, expressed in the first primitive's frame
    res["data"] = {"canon_feet_cm": canon_feet(prims), "planted_cm": planted(world),
                   "history_feature_max_err": float(hist_err)}

    # (b) VAE reconstruction with the true history
    rec = torch.stack([vae_decode(model, prims[:, k, :HISTORY_LENGTH], prims[:, k, HISTORY_LENGTH:])
                       for k in range(n)], dim=1)
    rec_prims = torch.cat((prims[:, :, :HISTORY_LENGTH], rec), dim=2)
    # no planted_cm here: each primitive is decoded from the data's history, not from what the previous one showed
    res["vae"] = {"canon_feet_cm": canon_feet(rec_prims),
                  "first_frame_feet_err_cm": float((joints_of(rec[:, :, 0])[..., FEET, :]
                                                    - joints_of(prims[:, :, HISTORY_LENGTH])[..., FEET, :])
                                                   .norm(dim=-1).mean() * 100),
                  "later_frames_feet_err_cm": float((joints_of(rec[:, :, 1:])[..., FEET, :]
                                                     - joints_of(prims[:, :, HISTORY_LENGTH + 1:])[..., FEET, :])
                                                    .norm(dim=-1).mean() * 100)}

    # (b') VAE chained on its own output (the data's world motion re-expressed in each chained frame)
    hist = prims[:, 0, :HISTORY_LENGTH]
    chained = []
    for k in range(n):
        # the data future is in the data history's frame; the chained history is close to it
        out = vae_decode(model, hist, prims[:, k, HISTORY_LENGTH:])
        chained.append(torch.cat((hist, out), dim=1))
        hist, _, _ = canonicalize(out[:, -HISTORY_LENGTH:], pd)
    chained = torch.stack(chained, dim=1)
    res["vae_chain"] = {"canon_feet_cm": canon_feet(chained), "planted_cm": planted(chain(chained, pd))}

    # (c) the model's own rollout
    variants = {"sampled": (None, False), "sampled_snap": (0.05, False), "sampled_snap_ramp": (0.05, True)}
    for key, (snap, ramp) in ({} if args.vae_only else variants).items():
        model.floor_snap, model.floor_snap_ramp = snap, ramp
        g = torch.Generator().manual_seed(0)
        steps = 9
        state = model.initial_state(16, g)
        hists, futs = [], []
        joints = [state.world.apply(joints_of(state.history))]
        emb = model.encode_text([args.text] * 16)
        for _ in range(steps):
            out = model.rollout_step(state, emb, torch.randn(16, *model.latent_shape, generator=g), 5.0)
            hists.append(state.history)
            futs.append(out.future)
            joints.append(out.joints_world)
            state = out.state
        sp = torch.cat((torch.stack(hists, 1), torch.stack(futs, 1)), dim=2)
        world = torch.cat(joints, dim=1)
        seams = M.seam_ratios(world)
        res[key] = {"canon_feet_cm": canon_feet(sp), "planted_cm": planted(world),
                    "pelvis_acc": {"boundary": seams["pelvis_acc_boundary"], "rest": seams["pelvis_acc_rest"],
                                   "ratio": seams["pelvis_acc_ratio"]},
                    "penetration_cm": float(M.lowest_joint_penetration_cm(world[:, HISTORY_LENGTH:]).mean())}
    print(json.dumps(res, indent=1))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=1)


if __name__ == "__main__":
    main()
