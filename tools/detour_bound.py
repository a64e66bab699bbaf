"""How much of an obstacle policy's reach time is detour and how much is a slower walk.

    python tools/detour_bound.py OBSTACLE_EVAL [--flat FLAT_EVAL] [--clearance 0.25] [--cell 0.05] [--all]
                                 [--write-suite ROUTES.json]

OBSTACLE_EVAL and FLAT_EVAL are `latentrl eval` output folders of reach suites (their ``motions/*.npz`` carry
each episode's scene, goals and joints). For every successful episode of OBSTACLE_EVAL this computes the
shortest route of the pelvis (xy) from its start to within the success radius (0.3 m) of the goal that stays
``--clearance`` metres clear of every object (:class:`latentrl.scenes.route.RouteMap`: Dijkstra on a ``--cell``
grid, 16-connected), the straight line's
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
import json
import math
from collections import defaultdict
from pathlib import Path

import numpy as np

from latentrl.constants import SUCCESS_RADIUS_M
from latentrl.scenes.route import RouteMap, RouteSettings
from latentrl.scenes.scene import SceneBatch
from latentrl.scenes.spec import scene_from_json


def clear_route(scene_json: str, start: np.ndarray, goal: np.ndarray, clearance: float, cell: float
                ) -> tuple[float, list[np.ndarray]]:
    """Length (m) and corners of the shortest route from ``start`` to near ``goal`` keeping ``clearance`` from objects.

    Near: within the success radius; the clearance is hard (``band_cost`` inf: no leg enters it; a start inside
    it may keep its own distance). (inf, []) when there is none. The corners: the route pulled taut, the goal last.
    """
    scene = SceneBatch.from_scenes([scene_from_json(scene_json)])
    route = RouteMap(scene, start, goal, RouteSettings(clearance=clearance, cell=cell, band_cost=math.inf,
                                                      reach=SUCCESS_RADIUS_M))
    return route.length(start), route.corners(start)


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
