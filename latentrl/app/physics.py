"""``latentrl physics track``: execute a motion .npz on the MuJoCo humanoid; write the simulated motion and a report."""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from latentrl.errors import ConfigError, DataError
from latentrl.motion.skeleton import FOOT_JOINTS

CLOSD_METRICS = ("penetration_mm", "floating_mm", "skating_mm")
FELL_EXIT = 4
"""Exit status of ``physics track`` / ``physics loop`` when the body fell: the outputs are written, but a
script must not read the run as a clean execution of the motion."""


def report_falls(command: str, runs: list[tuple[str, list[int]]], report: Path) -> int:
    """0 when no run fell; else one stderr line naming each run's fall count and frames, and :data:`FELL_EXIT`.

    ``runs``: (label, fall frames) per simulated run (label "" for a command's only run).
    """
    import sys

    fell = [(label, falls) for label, falls in runs if falls]
    if not fell:
        return 0

    def frames(falls: list[int]) -> str:
        return ", ".join(map(str, falls[:10])) + (f", ... ({len(falls) - 10} more)" if len(falls) > 10 else "")

    parts = " and ".join(f"{len(f)} time{'s' * (len(f) != 1)}{' in the ' + label if label else ''} (frames "
                         f"{frames(f)})" for label, f in fell)
    print(f"latentrl: {command}: the humanoid fell {parts}; after each fall it was put back on the reference and "
          f"went on; see {report}; exit {FELL_EXIT}", file=sys.stderr)
    return FELL_EXIT


@dataclass
class TrackRequest:
    """``latentrl physics track``: a motion file, the output folder and the humanoid's settings."""

    motion: str
    out: str
    height: float | None = None
    assist_hz: float = 2.0
    tracker: str | None = None
    """A ``physics train-tracker`` checkpoint: track with the learned tracker instead of the untrained PD."""


def _check(req: TrackRequest) -> None:
    if req.height is not None and not 1.0 <= req.height <= 2.5:  # also refuses nan
        raise ConfigError(f"--height must be in [1.0, 2.5] m, got {req.height}")
    if not 0.0 <= req.assist_hz <= 50.0:
        raise ConfigError(f"--assist-hz must be in [0, 50] (0 switches the root assist off), got {req.assist_hz}")


def load_tracked_motion(path: str):
    """The :class:`MotionClip` at ``path``; its optional 276-D features, when present, must be finite (T, 276)."""
    from latentrl.motion.clip import MotionClip

    clip = MotionClip.load(path)
    if clip.frames < 2:
        raise DataError(f"{path}: a motion of {clip.frames} frame cannot be tracked (need at least 2)")
    if clip.features is None:
        return clip
    features = np.asarray(clip.features)
    if features.dtype.kind != "f" or features.shape != (clip.frames, 276):
        raise DataError(f"{path}: field 'features' must be ({clip.frames}, 276) floating point, got "
                        f"{features.dtype} {features.shape}")
    if not np.isfinite(features).all():
        bad = int((~np.isfinite(features)).any(axis=1).sum())
        raise DataError(f"{path}: field 'features' holds NaN or inf in {bad} of {clip.frames} frames")
    return clip


def quality(joints: np.ndarray, floor: float = 0.0) -> dict[str, float]:
    """CLoSD's penetration, floating and skating (mm, docs/physics.md) of (T, 22, 3) joints."""
    from latentrl.evaluation.metrics import closd_floating_mm, closd_penetration_mm, closd_skating_mm

    return {"penetration_mm": float(closd_penetration_mm(joints, floor)),
            "floating_mm": float(closd_floating_mm(joints, floor)),
            "skating_mm": float(closd_skating_mm(joints, floor))}


def sole_quality(joints: np.ndarray, soles: np.ndarray, floor: float = 0.0) -> dict[str, float]:
    """CLoSD's metrics at the humanoid's soles: (T, 22, 3) joints, (T, 4, 3) :meth:`Simulator.soles` rows.

    Why: the humanoid's toe-base joints sit 2 cm above a flat sole, so at the joints its contacts never come
    within CLoSD's 5 mm. Here each foot box (rear foot, toes) stands in for a foot joint: its lowest corner
    decides penetration, floating and contact, its sole centre's horizontal displacement is the skating.
    """
    pseudo = np.array(joints, dtype=np.float64, copy=True)
    pseudo[:, [7, 8, 10, 11]] = soles
    out = quality(pseudo, floor)
    rear = pseudo.copy()
    rear[:, list(FOOT_JOINTS)] = soles[:, :2]
    out["skating_mm"] = (out["skating_mm"] + quality(rear, floor)["skating_mm"]) / 2  # all four boxes
    return out


def track_report(clip, result, kinematic: np.ndarray, humanoid, assist_hz: float, source: str) -> dict:
    """The report.json of one tracked motion (fields in docs/physics.md)."""
    from latentrl.timing import hardware

    ref = np.asarray(clip.joints, dtype=np.float64)
    sim = result.joints
    err = np.linalg.norm(sim - ref, axis=-1)
    local = np.linalg.norm((sim - sim[:, :1]) - (ref - ref[:, :1]), axis=-1)
    return {
        "motion": source,
        "frames": int(clip.frames),
        "fps": float(clip.fps),
        "seconds": float(result.seconds),
        "humanoid": {"height_m": round(humanoid.height, 4), "mass_kg": round(humanoid.mass, 3)},
        "falls": len(result.falls),
        "fall_frames": [int(f) for f in result.falls],
        "assist": {"hz": float(assist_hz), **result.assist_summary()},
        "tracking": {
            "mpjpe_mm": float(err.mean() * 1000),
            "mpjpe_local_mm": float(local.mean() * 1000),
            "max_joint_error_mm": float(err.max() * 1000),
            "retarget_mpjpe_mm": float(np.linalg.norm(kinematic - ref, axis=-1).mean() * 1000),
        },
        "reference": quality(ref, clip.floor),
        "simulation": quality(sim, clip.floor),
        "simulation_soles": sole_quality(sim, result.soles, clip.floor),
        "speed": {"sim_seconds": float(result.sim_seconds),
                  "real_time_factor": float(result.seconds / max(result.sim_seconds, 1e-9))},
        "hardware": hardware(),
    }


def simulated_clip(clip, result, pelvis_delta: np.ndarray, source: str):
    """The simulated motion as a :class:`MotionClip` with world features (the reference's ``transl`` convention)."""
    import torch

    from latentrl.motion.clip import MotionClip
    from latentrl.motion.representation import compute_features

    joints = np.concatenate((result.joints, result.joints[-1:]))
    rotations = np.concatenate((result.rotations, result.rotations[-1:]))
    transl = joints[:, 0] - pelvis_delta
    features = compute_features(torch.as_tensor(transl), torch.as_tensor(rotations), torch.as_tensor(joints))
    return MotionClip(result.joints, clip.fps, clip.texts, features=features.numpy().astype(np.float32),
                      primitive=clip.primitive, floor=clip.floor,
                      meta={"source_motion": source, "physics": "latentrl physics track"})


def track_command(req: TrackRequest) -> int:
    """Load, simulate, write ``motion.npz`` and ``report.json`` into ``--out``; print a one-line summary."""
    from latentrl.physics import require_mujoco
    from latentrl.physics.humanoid import build_humanoid
    from latentrl.physics.reference import build_reference, fit_height, kinematic_joints
    from latentrl.physics.tracker import track
    from latentrl.preflight import check_writable, locked_output
    from latentrl.safe_io import atomic_write_text

    _check(req)
    clip = load_tracked_motion(req.motion)
    require_mujoco()
    out = Path(req.out)
    check_writable(out, "--out")
    if req.tracker and req.height is None:  # the body the tracker learned on
        from latentrl.app.physics_tracker import load_tracker

        req.height = load_tracker(req.tracker)[1].tracking.height
    height = req.height if req.height is not None else fit_height(clip.joints)
    if not 1.0 <= height <= 2.5:
        raise DataError(f"{req.motion}: its bone lengths give a body height of {height:.2f} m, outside the "
                        f"humanoid's [1.0, 2.5] m (set --height)")
    with locked_output(out):
        humanoid = build_humanoid(height)
        ref = build_reference(clip.joints, clip.features, clip.fps, humanoid)
        start = time.perf_counter()
        extra = {}
        if req.tracker:
            from latentrl.app.physics_tracker import track_with_tracker

            result, extra = track_with_tracker(clip, req, humanoid, ref)
        else:
            result = track(humanoid, ref, req.assist_hz or None)
        if not np.isfinite(result.joints).all():
            raise DataError(f"{req.motion}: the simulation diverged (non-finite state)")
        report = track_report(clip, result, kinematic_joints(humanoid.rest_joints, ref), humanoid, req.assist_hz,
                              req.motion)
        report["rotations"] = "joints only" if clip.features is None else "features, swung onto the joints"
        report.update(extra)
        report["command"] = f"latentrl physics track {req.motion} --out {req.out}" + (
            f" --tracker {req.tracker}" if req.tracker else "")
        report["date"] = time.strftime("%Y-%m-%d", time.gmtime())
        report["wall_seconds"] = round(time.perf_counter() - start, 3)
        pelvis_delta = humanoid.rest_joints[0] if clip.features is None else (
            np.asarray(clip.joints[:, 0], dtype=np.float64) - np.asarray(clip.features[:, :3], dtype=np.float64)
        ).mean(axis=0)
        simulated_clip(clip, result, pelvis_delta, req.motion).save(out / "motion.npz")
        atomic_write_text(out / "report.json", json.dumps(report, indent=2, allow_nan=False) + "\n")
    a, t = report["assist"], report["tracking"]
    rtf = report["speed"]["real_time_factor"]
    print(f"tracked {clip.frames} frames ({report['seconds']:.1f} s): MPJPE {t['mpjpe_mm']:.0f} mm, "
          f"falls {report['falls']}, assist {a['force_Ns_per_s']:.0f} N s/s ({a['force_percent_body_weight']:.0f} % "
          f"of body weight), {rtf:.1f}x real time; wrote {out / 'motion.npz'} and {out / 'report.json'}")
    if not math.isfinite(rtf):
        return 1
    return report_falls("physics track", [("", result.falls)], out / "report.json")


@dataclass
class LoopRequest:
    """``latentrl physics loop``: a text timeline planned by a motion model and executed in closed loop."""

    out: str
    text: list[str] | None = None
    seconds: float | None = None
    seed: int = 0
    motion: str = "default"
    height: float = 1.72
    assist_hz: float = 2.0


def loop_command(req: LoopRequest) -> int:
    """Closed loop beside the open loop of the same noise: ``closed.npz``, ``open_kinematic.npz``, ``report.json``."""
    import torch

    from latentrl.app.motion import timeline
    from latentrl.config import seed_problem
    from latentrl.motion.checkpoint import load_motion_model
    from latentrl.motion.clip import MotionClip, primitive_layout
    from latentrl.motion.text import prompt_problem
    from latentrl.physics import require_mujoco
    from latentrl.physics.humanoid import GRAVITY, build_humanoid
    from latentrl.physics.loop import closed_loop
    from latentrl.physics.reference import build_reference, kinematic_joints
    from latentrl.physics.tracker import track
    from latentrl.preflight import check_writable, locked_output
    from latentrl.safe_io import atomic_write_text
    from latentrl.timing import hardware

    _check(TrackRequest(motion="", out=req.out, height=req.height, assist_hz=req.assist_hz))
    if req.seconds is not None and not 0 < req.seconds <= 3600:  # also refuses nan
        raise ConfigError(f"--seconds must be in (0, 3600], got {req.seconds}")
    per_step = timeline(req.text or ["walk"], req.seconds)
    if seed_problem(req.seed) is not None:
        raise ConfigError(f"--seed: {seed_problem(req.seed)}")
    for text in dict.fromkeys(per_step):
        if prompt_problem(text) is not None:
            raise ConfigError(f"--text: {prompt_problem(text)}")
    require_mujoco()
    out = Path(req.out)
    check_writable(out, "--out")
    model = load_motion_model(req.motion)
    model.encode_text(list(dict.fromkeys(per_step)))  # fail early on unknown prompts
    steps = len(per_step)
    noise = torch.randn(steps, 1, *model.latent_shape, generator=torch.Generator().manual_seed(req.seed))
    with locked_output(out):
        humanoid = build_humanoid(req.height)
        start = torch.Generator().manual_seed(req.seed)
        state = model.initial_state(1, start)
        roll = model.rollout(per_step, steps, noise=noise, state=state)
        kin = roll.joints_world[0].double().numpy()
        kin_clip = MotionClip(kin, texts=[""] * 2 + [t for t in per_step for _ in range(8)],
                              features=roll.features_world[0].numpy(), primitive=primitive_layout(steps))
        ref = build_reference(kin, kin_clip.features, kin_clip.fps, humanoid)
        tracked = track(humanoid, ref, req.assist_hz or None)
        begin = time.perf_counter()
        closed = closed_loop(model, humanoid, per_step, noise=noise, assist_hz=req.assist_hz or None,
                             state=model.initial_state(1, torch.Generator().manual_seed(req.seed)))
        loop_seconds = time.perf_counter() - begin
        weight = humanoid.mass * GRAVITY
        seconds = (len(closed.simulated) - 1) / kin_clip.fps
        closed_assist = float(closed.assist_force[2:].mean())
        report = {
            "command": f"latentrl physics loop --out {req.out} --seed {req.seed}",
            "date": time.strftime("%Y-%m-%d", time.gmtime()),
            "motion_model": req.motion,
            "texts": list(dict.fromkeys(per_step)),
            "primitives": steps,
            "seconds": seconds,
            "humanoid": {"height_m": humanoid.height, "mass_kg": round(humanoid.mass, 3)},
            "open_loop": {
                "kinematic": quality(kin),
                "tracked": quality(tracked.joints),
                "tracked_soles": sole_quality(tracked.joints, tracked.soles),
                "falls": len(tracked.falls),
                "assist": tracked.assist_summary(),
                "mpjpe_mm": float(np.linalg.norm(tracked.joints - kin, axis=-1).mean() * 1000),
                "retarget_mpjpe_mm": float(np.linalg.norm(kinematic_joints(humanoid.rest_joints, ref) - kin,
                                                          axis=-1).mean() * 1000),
                "pelvis_travel_m": _travel(kin),
            },
            "closed_loop": {
                "planned": quality(closed.planned),
                "simulated": quality(closed.simulated),
                "simulated_soles": sole_quality(closed.simulated, closed.soles),
                "falls": len(closed.falls),
                "assist": {"force_Ns_per_s": closed_assist,
                           "force_percent_body_weight": 100.0 * closed_assist / weight},
                "plan_vs_simulation_mpjpe_mm": float(np.linalg.norm(closed.planned - closed.simulated,
                                                                    axis=-1).mean() * 1000),
                "pelvis_travel_m": _travel(closed.simulated),
                "real_time_factor": seconds / max(loop_seconds, 1e-9),
            },
            "hardware": hardware(),
        }
        frame_texts = kin_clip.texts
        MotionClip(closed.simulated, texts=frame_texts, features=closed.features.astype(np.float32),
                   primitive=primitive_layout(steps), actions=noise[:, 0, 0].numpy(),
                   meta={"physics": "latentrl physics loop", "seed": req.seed}).save(out / "closed.npz")
        MotionClip(closed.planned, texts=frame_texts, primitive=primitive_layout(steps),
                   meta={"physics": "latentrl physics loop (plans)", "seed": req.seed}).save(out / "closed_plans.npz")
        kin_clip.save(out / "open_kinematic.npz")
        atomic_write_text(out / "report.json", json.dumps(report, indent=2, allow_nan=False) + "\n")
    c, o = report["closed_loop"], report["open_loop"]
    print(f"closed loop, {steps} primitives ({seconds:.1f} s): falls {c['falls']}, assist "
          f"{c['assist']['force_percent_body_weight']:.0f} % of body weight, pelvis travel "
          f"{c['pelvis_travel_m']:.2f} m (open loop {o['pelvis_travel_m']:.2f} m); wrote {out}")
    return report_falls("physics loop", [("open loop", tracked.falls), ("closed loop", closed.falls)],
                        out / "report.json")


def _travel(joints: np.ndarray) -> float:
    """Horizontal pelvis path length, metres."""
    return float(np.linalg.norm(np.diff(np.asarray(joints)[:, 0, :2], axis=0), axis=-1).sum())
