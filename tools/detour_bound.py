"""How much of an obstacle policy's reach time is detour and how much is a slower walk.

    python tools/detour_bound.py OBSTACLE_EVAL [--flat FLAT_EVAL] [--clearance 0.25] [--cell 0.05] [--all]
                                 [--write-suite ROUTES.json]

OBSTACLE_EVAL and FLAT_EVAL are `latentrl eval` output folders of reach suites (their ``motions/*.npz`` carry
each episode's scene, goals and joints). For every successful episode of OBSTACLE_EVAL this computes the
shortest route of the pelvis (xy) from its start to within the success radius (0.3 m) of the goal that stays
``--clearance`` metres clear of every object (Dijkstra on a ``--cell`` grid, 8-connected), the straight line's
length, and the policy's own pelvis route until it reached the goal, then prints per-path and overall means:
the detour (shortest clear route / straight line), the policy's route / straight line, and its speed along its
route. With ``--flat`` (the obstacle-free policy on the same goals without a scene) it prints that policy's
speed, route and reach time too, and the reach time a walk at the flat policy's pace would need on the
shortest clear route (the detour's share of the reach-time ratio). ``--write-suite`` writes each episode's
route as a path suite (its corners as waypoints, the goal last, the episode's scene inline), for a path-following
policy: `latentrl eval path_maze_default --paths ROUTES.json --episodes 1`.
"""

from __future__ import annotations

import argparse
import heapq
import json
import math
from collections import defaultdict
from pathlib import Path

import numpy as np
import torch

from latentrl.constants import SUCCESS_RADIUS_M
from latentrl.scenes.scene import SceneBatch
from latentrl.scenes.spec import scene_from_json

PROBE_Z = (0.1, 0.4, 0.8, 1.2)
"""Heights (m) at which the scene is probed: the random obstacles stand 0.5-1.5 m tall on the floor."""


def clear_route(scene_json: str, start: np.ndarray, goal: np.ndarray, clearance: float, cell: float
                ) -> tuple[float, list[np.ndarray]]:
    """Length (m) and corners of the shortest clear grid route from ``start`` to near ``goal``.

    Near: within the success radius; clear: ``clearance`` from every object (the start cell is allowed); (inf,
    []) when there is none. The corners: the route pulled taut (each kept point the farthest route point in
    clear sight of the last), then the goal itself.
    """
    scene = SceneBatch.from_scenes([scene_from_json(scene_json)])
    lo = np.minimum(start, goal) - 3.0
    hi = np.maximum(start, goal) + 3.0
    nx, ny = (np.ceil((hi - lo) / cell).astype(int) + 1).tolist()
    xs, ys = lo[0] + cell * np.arange(nx), lo[1] + cell * np.arange(ny)
    gx, gy = np.meshgrid(xs, ys, indexing="ij")
    sdf = np.full(gx.shape, np.inf)
    for z in PROBE_Z:
        pts = torch.tensor(np.stack((gx, gy, np.full_like(gx, z)), -1).reshape(1, -1, 3), dtype=torch.float32)
        sdf = np.minimum(sdf, scene.sdf(pts).reshape(gx.shape).numpy())
    free = sdf > clearance
    si, sj = (np.round((start - lo) / cell).astype(int)).tolist()
    free[si, sj] = True
    done = np.hypot(gx - goal[0], gy - goal[1]) <= SUCCESS_RADIUS_M
    dist = np.full(gx.shape, np.inf)
    dist[si, sj] = 0.0
    came: dict[tuple[int, int], tuple[int, int]] = {}
    heap = [(0.0, si, sj)]
    steps = [(di, dj, cell * math.hypot(di, dj)) for di in (-1, 0, 1) for dj in (-1, 0, 1) if di or dj]
    while heap:
        d, i, j = heapq.heappop(heap)
        if d > dist[i, j]:
            continue
        if done[i, j]:
            cells = [(i, j)]
            while cells[-1] != (si, sj):
                cells.append(came[cells[-1]])
            points = [np.array([xs[a], ys[b]]) for a, b in reversed(cells)]
            return d, taut(points, free, lo, cell) + [goal]
        for di, dj, w in steps:
            a, b = i + di, j + dj
            if 0 <= a < nx and 0 <= b < ny and free[a, b] and d + w < dist[a, b]:
                dist[a, b] = d + w
                came[(a, b)] = (i, j)
                heapq.heappush(heap, (d + w, a, b))
    return math.inf, []


def taut(points: list[np.ndarray], free: np.ndarray, lo: np.ndarray, cell: float) -> list[np.ndarray]:
    """The corners of a grid route: from each kept point, the farthest later point in clear sight of it."""
    def sight(p: np.ndarray, q: np.ndarray) -> bool:
        n = max(2, int(np.ceil(np.hypot(*(q - p)) / (cell / 2))))
        for t in np.linspace(0.0, 1.0, n):
            a, b = np.round((p + (q - p) * t - lo) / cell).astype(int)
            if not free[a, b]:
                return False
        return True

    kept, k = [], 0
    while k < len(points) - 1:
        far = next(m for m in range(len(points) - 1, k, -1) if m == k + 1 or sight(points[k], points[m]))
        kept.append(points[far])
        k = far
    return kept[:-1]


def episodes(folder: Path, every: bool = False):
    """(path index, start xy, goal xy, pelvis route until reached (m), reach time (s), scene JSON or None)."""
    for f in sorted((folder / "motions").glob("*.npz")):
        d = np.load(f, allow_pickle=True)
        if not (every or bool(d["success"])):
            continue
        pelvis = d["joints"][:, 0, :2].astype(np.float64)
        goal = d["waypoints"][0, :2].astype(np.float64)
        near = np.nonzero(np.hypot(*(pelvis - goal).T) <= SUCCESS_RADIUS_M)[0]
        end = int(near[0]) if len(near) else len(pelvis) - 1
        start = int(np.argmax(d["primitive"] >= 0)) if "primitive" in d.files else 0
        route = float(np.hypot(*np.diff(pelvis[start:end + 1], axis=0).T).sum())
        scene = str(d["scene"]) if "scene" in d.files and str(d["scene"]) else None
        yield int(d["path_index"]), pelvis[start], goal, route, float(d["reach_time_s"]), scene


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("obstacle_eval")
    ap.add_argument("--flat", help="the obstacle-free policy's evaluation on the same goals")
    ap.add_argument("--clearance", type=float, default=0.25, help="metres the pelvis route keeps from objects")
    ap.add_argument("--cell", type=float, default=0.05)
    ap.add_argument("--all", action="store_true", help="every episode, not only the successful ones")
    ap.add_argument("--write-suite", help="write the routes' corners as a path suite (JSON), one path per episode")
    args = ap.parse_args()
    rows, suite = defaultdict(list), []
    for path, start, goal, route, t, scene in episodes(Path(args.obstacle_eval), args.all):
        line = max(float(np.hypot(*(goal - start))) - SUCCESS_RADIUS_M, 1e-6)
        best, corners = clear_route(scene, start, goal, args.clearance, args.cell) if scene else (line, [goal])
        best = max(best, 1e-6)
        if args.write_suite:
            suite.append({"goal_location": [[float(c[0]), float(c[1]), 0.0] for c in corners],
                          "goal_text": ["walk"] * len(corners), "scene": json.loads(scene) if scene else None})
        rows[path].append((line, best, route, t))
    flat = defaultdict(list)
    if args.flat:
        for path, start, goal, route, t, _ in episodes(Path(args.flat)):
            line = max(float(np.hypot(*(goal - start))) - SUCCESS_RADIUS_M, 1e-6)
            flat[path].append((line, route, t))
    if args.write_suite:
        Path(args.write_suite).write_text(json.dumps(suite))
        print(f"wrote {len(suite)} routes ({np.mean([len(e['goal_location']) for e in suite]):.1f} waypoints "
              f"on average) to {args.write_suite}")
    print(f"clearance {args.clearance} m, cell {args.cell} m; {'all' if args.all else 'successful'} episodes")
    all_rows = [r for p in sorted(rows) for r in rows[p]]
    for label, group, fl in [*((f"path {p}", rows[p], flat.get(p, [])) for p in sorted(rows)),
                             ("all", all_rows, [r for p in sorted(flat) for r in flat[p]])]:
        a = np.array(group)
        detour, own, speed = (a[:, 1] / a[:, 0]).mean(), (a[:, 2] / a[:, 0]).mean(), (a[:, 2] / a[:, 3]).mean()
        text = (f"{label}: n {len(a)}, straight {a[:, 0].mean():.2f} m, shortest clear route x{detour:.3f}, "
                f"policy route x{own:.3f}, policy speed {speed:.2f} m/s, reach {a[:, 3].mean():.2f} s")
        if fl:
            b = np.array(fl)
            pace = (b[:, 1] / b[:, 2]).mean()
            text += (f" | flat: route x{(b[:, 1] / b[:, 0]).mean():.3f}, speed {pace:.2f} m/s, reach "
                     f"{b[:, 2].mean():.2f} s; flat pace on the clear route {(a[:, 1] / pace).mean():.2f} s "
                     f"(x{(a[:, 1] / pace).mean() / b[:, 2].mean():.2f} the flat reach time)")
        print(text)


if __name__ == "__main__":
    main()
