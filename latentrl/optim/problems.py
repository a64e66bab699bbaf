"""Constraint problems for noise optimization and their suite file (``latentrl.constraints/1``).

A problem is a start (a seed history of the model, or two frames of a motion ``.npz``), a text per
primitive, a number of primitives and constraints on world joints at generated frames (frame 0 is the
first generated frame, so ``primitives: 8`` gives frames 0-63). Every constraint type compiles to the
same rows, *point targets*: (frame, joint, target xyz, axis mask, weight). One loss kernel and one
metric (:mod:`latentrl.optim.losses`) then serve keyframes, joint targets and trajectories alike.

Suite file (docs/optimize.md)::

    {"format": "latentrl.constraints/1",
     "problems": [{"name": "walk_a", "start": {"seed": 3}, "text": "walk", "primitives": 8,
                   "constraints": [{"type": "keyframe", "frame": 63, "joints": [[x, y, z], ... 22 rows]},
                                   {"type": "joint", "frame": 40, "joint": "left_wrist",
                                    "position": [0.5, 1.2, 1.1]}]}]}

A problem may also carry a scene (``"scene"``: a ``latentrl.scene/1`` object, or a scene file named relative
to the suite file; docs/scenes.md) and the weights of its two costs (``"scene_weights": {"collision": 0.1,
"contact": 0.1}``, DART's 0.1 each by default): the motion is then kept out of the objects and its feet on the
terrain (:func:`latentrl.optim.losses.scene_loss`).

Everything is checked on load; a bad value is one line naming the file, the problem and the field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from latentrl.errors import DataError, closest
from latentrl.motion.representation import FUTURE_LENGTH
from latentrl.motion.skeleton import JOINT_NAMES, NUM_JOINTS
from latentrl.motion.text import prompt_problem
from latentrl.safe_io import read_json_file
from latentrl.scenes.scene import Scene, SceneBatch
from latentrl.scenes.spec import load_scene, parse_scene

FORMAT = "latentrl.constraints/1"
"""The ``format`` value a suite file must carry."""
MAX_PRIMITIVES = 64
"""Longest problem (primitives): 512 frames, 17 s at 30 fps."""
MAX_PROBLEMS = 1000
MAX_SUITE_BYTES = 16 * 1024 * 1024
MAX_COORD_M = 1000.0
"""Targets farther than this from the origin are refused (no character walks there in 17 s)."""
CONSTRAINT_TYPES = ("keyframe", "joint", "trajectory")
SCENE_WEIGHTS = {"collision": 0.1, "contact": 0.1}
"""Default weights of a problem's scene costs (DART's ``weight_collision`` and ``weight_contact``)."""
AXES = "xyz"


@dataclass(frozen=True)
class Start:
    """Where a problem starts: a seed history of the model (``seed``) or two frames of a motion file."""

    seed: int | None = None
    motion: str | None = None
    frame: int = -1
    """Last of the two history frames taken from ``motion`` (-1: the file's last frame)."""


@dataclass
class Problem:
    """One constraint problem; ``rows`` are its point targets (see the module docstring)."""

    name: str
    start: Start
    texts: list[str]
    primitives: int
    constraints: list[dict]
    frames: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    joints: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    targets: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float32))
    masks: np.ndarray = field(default_factory=lambda: np.zeros((0, 3), np.float32))
    weights: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    scene: Scene | None = None
    """Objects the motion must keep out of, and the terrain its feet stand on (None: the flat floor alone)."""
    scene_weights: tuple[float, float] = (SCENE_WEIGHTS["collision"], SCENE_WEIGHTS["contact"])
    """Weights of the scene's collision and contact costs."""

    @property
    def num_frames(self) -> int:
        """Frames the problem generates (8 per primitive)."""
        return self.primitives * FUTURE_LENGTH


class _Where:
    """Builds error lines that name the file, the problem and the field."""

    def __init__(self, source: str, problem: str | int | None = None):
        self.source, self.problem = source, problem

    def error(self, fld: str, what: str) -> DataError:
        at = f" problem {self.problem!r}" if self.problem is not None else ""
        return DataError(f"{self.source}:{at} {fld}: {what}")


def _number(value, where: _Where, fld: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise where.error(fld, f"expected a number, got {value!r:.40}")
    if isinstance(value, int) and abs(value) > MAX_COORD_M:  # compared as an integer: 400 digits overflow a float
        raise where.error(fld, f"an integer of {len(str(abs(value)))} digits is more than {MAX_COORD_M:g} m "
                                "from the origin")
    if not math.isfinite(value):
        raise where.error(fld, f"expected a finite number, got {value}")
    if abs(value) > MAX_COORD_M:
        raise where.error(fld, f"{value} is more than {MAX_COORD_M:g} m from the origin")
    return float(value)


def _integer(value, where: _Where, fld: str, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise where.error(fld, f"expected an integer, got {value!r:.40}")
    if not low <= value <= high:
        raise where.error(fld, f"{value} is outside [{low}, {high}]")
    return value


def _point(value, where: _Where, fld: str) -> list[float]:
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise where.error(fld, f"expected [x, y, z] (metres), got {str(value)[:40]}")
    return [_number(v, where, f"{fld}[{i}]") for i, v in enumerate(value)]


def _joint(value, where: _Where, fld: str) -> int:
    if not isinstance(value, str) or value not in JOINT_NAMES:
        hint = closest(value, JOINT_NAMES) if isinstance(value, str) else ""
        raise where.error(fld, f"unknown joint {value!r}{hint}; expected one of {', '.join(JOINT_NAMES)}")
    return JOINT_NAMES.index(value)


def _axes(value, where: _Where, fld: str) -> list[float]:
    if value is None:
        return [1.0, 1.0, 1.0]
    if not isinstance(value, str) or not value or any(a not in AXES for a in value) or len(set(value)) != len(value):
        raise where.error(fld, f"expected some of 'xyz' (e.g. 'xy'), got {value!r:.20}")
    return [1.0 if a in value else 0.0 for a in AXES]


Row = tuple[int, int, list[float], list[float], float]
"""(frame, joint, target, axis mask, weight): one point target."""


def _rows_of(c: dict, where: _Where, fld: str, frames_total: int) -> list[Row]:
    """(frame, joint, target, mask, weight) rows of one constraint, checked."""
    if not isinstance(c, dict):
        raise where.error(fld, f"expected an object, got {str(c)[:40]}")
    kind = c.get("type")
    if kind not in CONSTRAINT_TYPES:
        raise where.error(f"{fld}.type", f"expected one of {', '.join(CONSTRAINT_TYPES)}, got {kind!r:.30}")
    allowed = {"keyframe": {"type", "frame", "joints", "weight"},
               "joint": {"type", "frame", "joint", "position", "axes", "weight"},
               "trajectory": {"type", "frames", "joint", "positions", "axes", "weight"}}[kind]
    extra = sorted(set(c) - allowed)
    if extra:
        raise where.error(f"{fld}.{extra[0]}", f"unknown field for a {kind} constraint; expected {sorted(allowed)}")
    weight = _number(c.get("weight", 1.0), where, f"{fld}.weight")
    if weight <= 0:
        raise where.error(f"{fld}.weight", f"must be > 0, got {weight}")
    last = frames_total - 1
    if kind == "keyframe":
        frame = _integer(c.get("frame"), where, f"{fld}.frame", 0, last)
        joints = c.get("joints")
        if isinstance(joints, dict):
            if not joints:
                raise where.error(f"{fld}.joints", "is empty")
            pairs = [(_joint(k, where, f"{fld}.joints"), _point(v, where, f"{fld}.joints.{k}"))
                     for k, v in joints.items()]
        elif isinstance(joints, list) and len(joints) == NUM_JOINTS:
            pairs = [(j, _point(v, where, f"{fld}.joints[{j}]")) for j, v in enumerate(joints)]
        else:
            raise where.error(f"{fld}.joints", f"expected {NUM_JOINTS} rows [x, y, z] or an object joint name -> "
                                               f"[x, y, z], got {str(joints)[:40]}")
        return [(frame, j, p, [1.0, 1.0, 1.0], weight) for j, p in pairs]
    joint = _joint(c.get("joint"), where, f"{fld}.joint")
    mask = _axes(c.get("axes"), where, f"{fld}.axes")
    if kind == "joint":
        frame = _integer(c.get("frame"), where, f"{fld}.frame", 0, last)
        return [(frame, joint, _point(c.get("position"), where, f"{fld}.position"), mask, weight)]
    span = c.get("frames")
    if not isinstance(span, list) or len(span) != 2:
        raise where.error(f"{fld}.frames", f"expected [first, last] frames, got {str(span)[:40]}")
    first = _integer(span[0], where, f"{fld}.frames[0]", 0, last)
    end = _integer(span[1], where, f"{fld}.frames[1]", first, last)
    positions = c.get("positions")
    count = end - first + 1
    if not isinstance(positions, list) or len(positions) != count:
        got = len(positions) if isinstance(positions, list) else type(positions).__name__
        raise where.error(f"{fld}.positions", f"expected {count} rows [x, y, z] (frames {first}-{end}), got {got}")
    return [(first + i, joint, _point(p, where, f"{fld}.positions[{i}]"), mask, weight)
            for i, p in enumerate(positions)]


def parse_problem(raw, source: str, index: int, base: Path | None = None) -> Problem:
    """One problem object of a suite, checked (``base``: folder that relative ``start.motion`` paths are in)."""
    where = _Where(source, index)
    if not isinstance(raw, dict):
        raise where.error("problem", f"expected an object, got {str(raw)[:40]}")
    extra = sorted(set(raw) - {"name", "start", "text", "primitives", "constraints", "scene", "scene_weights"})
    if extra:
        raise where.error(extra[0], "unknown field; expected name, start, text, primitives, constraints, scene, "
                                    "scene_weights")
    name = raw.get("name", f"problem_{index}")
    if not isinstance(name, str) or not name or len(name) > 80 or not all(ch.isalnum() or ch in "_-." for ch in name):
        raise where.error("name", f"expected 1-80 letters, digits, '_', '-' or '.', got {name!r:.40}")
    where = _Where(source, name)
    primitives = _integer(raw.get("primitives"), where, "primitives", 1, MAX_PRIMITIVES)
    start_raw = raw.get("start", {"seed": 0})
    if not isinstance(start_raw, dict) or not ({"seed"} <= set(start_raw) <= {"seed"}
                                                or {"motion"} <= set(start_raw) <= {"motion", "frame"}):
        raise where.error("start", 'expected {"seed": K} or {"motion": "file.npz", "frame": F}')
    if "seed" in start_raw:
        start = Start(seed=_integer(start_raw["seed"], where, "start.seed", 0, 10**6))
    else:
        motion = start_raw["motion"]
        if not isinstance(motion, str) or not motion:
            raise where.error("start.motion", f"expected a motion .npz path, got {motion!r:.40}")
        path = Path(motion)
        if base is not None and not path.is_absolute():
            path = base / path
        start = Start(motion=str(path), frame=_integer(start_raw.get("frame", -1), where, "start.frame", -1, 10**7))
    text = raw.get("text", "walk")
    texts = [text] * primitives if isinstance(text, str) else text
    if not isinstance(texts, list) or len(texts) != primitives:
        raise where.error("text", f"expected one prompt or a list of {primitives} (one per primitive), "
                                  f"got {str(text)[:40]}")
    for i, t in enumerate(texts):
        why = prompt_problem(t)
        if why:
            raise where.error(f"text[{i}]" if not isinstance(text, str) else "text", why)
    constraints = raw.get("constraints")
    if not isinstance(constraints, list) or not constraints:
        raise where.error("constraints", "expected a non-empty list of constraints")
    rows = []
    for i, c in enumerate(constraints):
        rows += _rows_of(c, where, f"constraints[{i}]", primitives * FUTURE_LENGTH)
    frames, joints, targets, masks, weights = zip(*rows)
    scene, scene_weights = _scene_of(raw, where, base)
    return Problem(name, start, list(texts), primitives, constraints,
                   np.asarray(frames, np.int64), np.asarray(joints, np.int64), np.asarray(targets, np.float32),
                   np.asarray(masks, np.float32), np.asarray(weights, np.float32), scene, scene_weights)


def _scene_of(raw: dict, where: _Where, base: Path | None) -> tuple[Scene | None, tuple[float, float]]:
    """A problem's ``scene`` (inline or a file beside the suite) and ``scene_weights``, checked."""
    weights = raw.get("scene_weights", {})
    if not isinstance(weights, dict) or set(weights) - set(SCENE_WEIGHTS):
        raise where.error("scene_weights", f"expected an object with some of {', '.join(SCENE_WEIGHTS)}, "
                                           f"got {str(weights)[:40]}")
    pair = []
    for k, default in SCENE_WEIGHTS.items():
        w = _number(weights.get(k, default), where, f"scene_weights.{k}")
        if w < 0:
            raise where.error(f"scene_weights.{k}", f"must be >= 0, got {w}")
        pair.append(w)
    value = raw.get("scene")
    if value is None:
        return None, (pair[0], pair[1])
    source = f"{where.source}: problem {where.problem!r}: scene"
    if isinstance(value, str) and value:
        path = Path(value)
        if base is not None and not path.is_absolute():
            path = base / path
        return load_scene(path), (pair[0], pair[1])
    if isinstance(value, dict):
        return parse_scene(value, source), (pair[0], pair[1])
    raise where.error("scene", f"expected a scene file name or a latentrl.scene/1 object, got {str(value)[:40]}")


def load_suite(path: str | Path) -> list[Problem]:
    """Read and check a ``latentrl.constraints/1`` suite file (one-line :class:`DataError` on bad input)."""
    path = Path(path)
    source = str(path)
    if not path.is_file():
        raise DataError(f"{source}: no such suite file (a latentrl.constraints/1 JSON, docs/optimize.md)")
    raw = read_json_file(path, "constraint suite", MAX_SUITE_BYTES, DataError)  # size, JSON, UTF-8, nesting
    return parse_suite(raw, source, path.parent)


def parse_suite(raw, source: str = "<suite>", base: Path | None = None) -> list[Problem]:
    """A suite from its decoded JSON (``base``: folder for relative ``start.motion`` paths)."""
    where = _Where(source)
    if not isinstance(raw, dict):
        raise where.error("suite", "expected a JSON object with 'format' and 'problems'")
    if raw.get("format") != FORMAT:
        raise where.error("format", f"expected {FORMAT!r}, got {raw.get('format')!r:.40}")
    extra = sorted(set(raw) - {"format", "problems", "description"})
    if extra:
        raise where.error(extra[0], "unknown field; expected format, problems, description")
    problems = raw.get("problems")
    if not isinstance(problems, list) or not problems:
        raise where.error("problems", "expected a non-empty list")
    if len(problems) > MAX_PROBLEMS:
        raise where.error("problems", f"{len(problems)} problems, more than the {MAX_PROBLEMS} allowed")
    out = [parse_problem(p, source, i, base) for i, p in enumerate(problems)]
    names = [p.name for p in out]
    dup = next((n for n in names if names.count(n) > 1), None)
    if dup:
        raise where.error("problems", f"the name {dup!r} is used twice; names become file names")
    return out


@dataclass
class Targets:
    """A batch of problems' point targets padded to one length (``valid`` marks real rows)."""

    frames: torch.Tensor  # (B, K) int64, generated-frame index
    joints: torch.Tensor  # (B, K) int64
    points: torch.Tensor  # (B, K, 3) world metres
    masks: torch.Tensor  # (B, K, 3) 1 = the axis counts
    weights: torch.Tensor  # (B, K), 0 on padding
    scene: SceneBatch | None = None
    """The problems' scenes (an empty one for a problem without), or None when no problem has one."""
    scene_weights: torch.Tensor | None = None
    """(B, 2) collision and contact weights (0 for a problem without a scene)."""

    @property
    def valid(self) -> torch.Tensor:
        """(B, K) mask of real target rows (padding has weight 0)."""
        return self.weights > 0


def stack_targets(problems: list[Problem], device: str | torch.device = "cpu") -> Targets:
    """The point targets of ``problems`` as one padded batch."""
    k = max(len(p.frames) for p in problems)
    b = len(problems)
    frames = torch.zeros(b, k, dtype=torch.long)
    joints = torch.zeros(b, k, dtype=torch.long)
    points = torch.zeros(b, k, 3)
    masks = torch.zeros(b, k, 3)
    weights = torch.zeros(b, k)
    for i, p in enumerate(problems):
        n = len(p.frames)
        frames[i, :n] = torch.from_numpy(p.frames)
        joints[i, :n] = torch.from_numpy(p.joints)
        points[i, :n] = torch.from_numpy(p.targets)
        masks[i, :n] = torch.from_numpy(p.masks)
        weights[i, :n] = torch.from_numpy(p.weights)
    out = Targets(*(t.to(device) for t in (frames, joints, points, masks, weights)))
    if any(p.scene is not None for p in problems):
        out.scene = SceneBatch.from_scenes([p.scene or Scene() for p in problems], device)
        out.scene_weights = torch.tensor([p.scene_weights if p.scene is not None else (0.0, 0.0) for p in problems],
                                         dtype=torch.float32, device=device)
    return out
