"""Where a sit policy's episodes end up, read from a `latentrl eval` run's saved motions (docs/training_history.md).

    python tools/sit_phases.py EVAL_DIR

For the `sit_seats` episodes under EVAL_DIR/motions it prints how many finished the approach (their prompts reach
the sit), and over those: the pelvis's distance from the seat centre when the sit begins and its nearest after,
the body's facing against the sitter's (cosine, 1 = its back to the seat), and the pelvis height against the
seated height (seat top + 0.09 m) at its nearest.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from latentrl.envs.sit import SEATED_PELVIS_ABOVE_SEAT_M

SIT_TEXTS = ("sit down", "stand still")


def main(eval_dir: str) -> None:
    """One summary line, then one line per finished approach."""
    files = sorted(Path(eval_dir, "motions").glob("*.npz"))
    rows = []
    for path in files:
        data = np.load(path, allow_pickle=True)
        texts, joints = [str(t) for t in data["texts"]], data["joints"]
        starts = [i for i, t in enumerate(texts) if t in SIT_TEXTS]
        if not starts:
            continue
        seat = json.loads(str(data["scene"]))["objects"][0]
        centre, top, yaw = np.array(seat["center"]), seat["size"][2], np.radians(seat.get("yaw_deg", 0.0))
        k = starts[0]
        pelvis = joints[k:, 0]
        dist = np.linalg.norm(pelvis[:, :2] - centre, axis=1)
        hips = joints[k, 2, :2] - joints[k, 1, :2]  # right hip - left hip: the body's right
        forward = np.array([-hips[1], hips[0]]) / np.linalg.norm(hips)
        near = int(dist.argmin())
        rows.append((path.stem, top, dist[0], dist[near], float(forward @ [np.cos(yaw), np.sin(yaw)]),
                     pelvis[near, 2] - (top + SEATED_PELVIS_ABOVE_SEAT_M)))
    print(f"{len(rows)} of {len(files)} episodes finished the approach")
    for name, top, d0, dmin, cos, err in rows:
        print(f"{name}: seat {top:.2f} m; from the centre {d0:.2f} m at the sit, nearest {dmin:.2f} m; facing cos "
              f"{cos:.2f}; pelvis {err:+.2f} m from the seated height there")


if __name__ == "__main__":
    main(sys.argv[1])
