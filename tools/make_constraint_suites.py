"""Rebuild the shipped constraint suites (latentrl/tasks/constraints/*.json) from the default model's rollouts.

Each problem starts from one of the model's seed histories; its targets are joints of a rollout of the
model from that start under the problem's prompt, with noise drawn from a seed the optimizer never sees
(``--seed``, default 2026). The targets are therefore reachable by the model, and the optimizer must find
noise that reaches them (DART builds its in-betweening problems from held-out dataset clips instead).

    python tools/make_constraint_suites.py            # writes latentrl/tasks/constraints/
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch

from latentrl.motion.checkpoint import load_motion_model
from latentrl.motion.skeleton import JOINT_NAMES
from latentrl.optim.solver import rollout

SKILLS = ("walk", "run", "hop on left leg", "turn left", "walk backwards", "sidestep left", "stand")
OUT = Path(__file__).resolve().parents[1] / "latentrl" / "tasks" / "constraints"


def _roll(model, seed_index: int, text: str, primitives: int, noise_seed: int) -> torch.Tensor:
    g = torch.Generator().manual_seed(noise_seed)
    z = torch.randn(primitives, 1, *model.latent_shape, generator=g)
    start = model.initial_state(1, seed_index=torch.tensor([seed_index]))
    with torch.no_grad():
        joints, _ = rollout(model, start, [model.encode_text([text])] * primitives, z, 5.0)
    return joints[0, 2:]  # generated frames only


def _rows(frame_joints: torch.Tensor) -> list[list[float]]:
    return [[round(float(v), 4) for v in p] for p in frame_joints]


def _slug(text: str) -> str:
    return text.replace(" ", "_")


def build(seed: int) -> dict[str, dict]:
    """The three suites: end keyframe (2.1 s and 4 s), middle + end keyframes, joint targets."""
    model = load_motion_model("default")
    k = model.seed_history.shape[0]
    inbetween, middle, joints = [], [], []
    for i, text in enumerate(SKILLS):
        for primitives in (8, 15):
            gen = _roll(model, (3 * i + primitives) % k, text, primitives, seed + 100 * i + primitives)
            last = primitives * 8 - 1
            inbetween.append({"name": f"{_slug(text)}_{primitives * 8}f", "start": {"seed": (3 * i + primitives) % k},
                              "text": text, "primitives": primitives,
                              "constraints": [{"type": "keyframe", "frame": last, "joints": _rows(gen[last])}]})
        gen = _roll(model, (5 * i + 1) % k, text, 8, seed + 7 + 100 * i)
        middle.append({"name": f"{_slug(text)}_mid", "start": {"seed": (5 * i + 1) % k}, "text": text, "primitives": 8,
                       "constraints": [{"type": "keyframe", "frame": 31, "joints": _rows(gen[31])},
                                       {"type": "keyframe", "frame": 63, "joints": _rows(gen[63])}]})
        gen = _roll(model, (7 * i + 2) % k, text, 8, seed + 13 + 100 * i)
        foot = JOINT_NAMES.index("left_foot")
        wrist = JOINT_NAMES.index("right_wrist")
        joints.append({"name": f"{_slug(text)}_joints", "start": {"seed": (7 * i + 2) % k}, "text": text,
                       "primitives": 8,
                       "constraints": [
                           {"type": "joint", "frame": 40, "joint": "left_foot", "position": _rows(gen[40, [foot]])[0]},
                           {"type": "joint", "frame": 50, "joint": "right_wrist",
                            "position": _rows(gen[50, [wrist]])[0]},
                           {"type": "joint", "frame": 63, "joint": "pelvis", "position": _rows(gen[63, [0]])[0]}]})
    note = (f"Made by tools/make_constraint_suites.py --seed {seed} from the embedded default model's rollouts "
            "(targets reachable by the model; the noise that made them is not given).")
    fmt = "latentrl.constraints/1"
    return {
        "inbetween": {"format": fmt, "description": "Start + end keyframe (all 22 joints), 2.1 s and 4 s. " + note,
                      "problems": inbetween},
        "inbetween_mid": {"format": fmt, "description": "Start, middle and end keyframes, 2.1 s. " + note,
                          "problems": middle},
        "joint_targets": {"format": fmt, "description": "Left foot at frame 40, right wrist at frame 50, pelvis at "
                                                        "frame 63, 2.1 s. " + note, "problems": joints},
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    for name, suite in build(args.seed).items():
        path = args.out / f"{name}.json"
        path.write_text(json.dumps(suite, indent=1) + "\n", encoding="utf-8")
        print(f"wrote {path} ({len(suite['problems'])} problems)")


if __name__ == "__main__":
    main()
