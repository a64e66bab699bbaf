"""Feet against stairs with the flat and the terrain-aware floor snap (docs/scenes.md, "Terrain-aware placement").

    python tools/terrain_snap_stairs.py

The default model walks ('walk', 16 rollouts of 14 primitives, seed 0, one thread) from the origin along +y onto
5 steps (0.15 m risers, 0.3 m treads, starting 0.6 m ahead). For the flat snap, the terrain-aware snap moving each
primitive as a whole, and the same following the steps frame by frame (``MotionModel.follow_steps``, the default),
it prints, over the stairs (frames whose pelvis is above a tread), how deep the lower foot is inside the tread
under it, how high it floats above it, and the highest pelvis; the snap moves z only, so the horizontal paths are
the same in every row.
"""

from __future__ import annotations

import torch

from latentrl.motion import load_motion_model
from latentrl.motion.contacts import foot_positions
from latentrl.motion.skeleton import PELVIS
from latentrl.scenes import Scene, SceneBatch, Stairs


def main() -> None:
    """Roll the walk out three times with the same noises and print one line each."""
    torch.set_num_threads(1)
    model = load_motion_model("default")
    scene = SceneBatch.from_scenes([Scene((Stairs((0.0, 0.6), 90.0, 3.0, 0.15, 0.3, 5),))])
    text = model.encode_text(["walk"] * 16)
    for name, terrain, follow in (("terrain off", None, False), ("terrain on, whole primitives", scene, False),
                                  ("terrain on, following steps", scene, True)):
        model.follow_steps = follow
        g = torch.Generator().manual_seed(0)
        state = model.initial_state(16, generator=g)
        frames = []
        for _ in range(14):
            out = model.rollout_step(state, text, torch.randn(16, *model.latent_shape, generator=g), terrain=terrain)
            frames.append(out.joints_world)
            state = out.state
        joints = torch.cat(frames, 1)
        feet = foot_positions(joints)  # (B, T, 2, 3)
        lower = (feet[..., 2] - scene.height(feet[..., :2])).amin(-1)  # the lower foot over its ground
        over = scene.height(joints[:, :, PELVIS, :2]) > 0
        depth, lift = (-lower[over]).clamp(min=0), lower[over].clamp(min=0)
        print(f"{name}: {int(over.sum())} frames over the stairs; "
              f"lower foot inside the tread mean {100 * depth.mean():.2f} cm, max {100 * depth.max():.2f} cm; "
              f"above it mean {100 * lift.mean():.2f} cm; highest pelvis {joints[..., PELVIS, 2].amax():.2f} m")


if __name__ == "__main__":
    main()
