"""Bodies of ``latentrl eval`` and ``latentrl compare`` (arguments in :mod:`latentrl.app.cli`).

``latentrl eval POLICY`` writes into ``--out``::

    report.json     machine-readable results (schema in docs/evaluation.md)
    report.md       the tables a person reads
    paths.png       top-down pelvis tracks, one panel per path
    motions/<suite>_path<i>_ep<e>.npz    every episode in the shared motion format
    renders/<suite>_path<i>_ep<e>.gif    skeleton animations of the first --render episodes of each path
    renders/<suite>_path<i>_ep<e>.bvh    the same motions as BVH (SMPL-22, Y-up, centimetres)

A policy trained on the joystick or timed task (its checkpoint's ``env.task``) is evaluated by that
task's evaluator instead (:func:`evaluate_task`): ``--paths`` then names command-timeline files
(``tasks/joystick/``) or timed path files (``tasks/timed/``), and ``report.json`` has the format
``latentrl.eval.task/1``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from latentrl.errors import ConfigError, DataError
from latentrl.evaluation.config import EvalSettings
from latentrl.evaluation.results import EpisodeResult, PathResult
from latentrl.motion.rollout import lock_min_weight_problem

DEFAULT_SUITES = ("dart_walk_long", "dart_run_long", "dart_hop_long")
"""What ``latentrl eval`` runs without ``--paths``: DART's Table 4 suites."""
GIF_STRIDE = 3
"""Rendered GIFs keep every 3rd frame (10 fps): a 60 s episode is 600 frames, about a minute to draw on CPU."""


@dataclass
class EvalRequest:
    """``latentrl eval``: a policy checkpoint, the suites to run it on and what to write."""

    policy: str
    paths: list[str] | None = None
    episodes: int = 32
    max_steps: int = 256
    deterministic: bool = False
    motion: str | None = None
    """None: the model named in the policy's stored env config (``"default"`` when it names none)."""
    allow_motion_mismatch: bool = False
    foot_lock_min_weight: float | None = None
    """None: the policy's training value. Else the foot lock pins from this contact weight (a deployment choice
    that differs from training; the report's settings record it)."""
    device: str | None = None
    seed: int = 0
    out: str | None = None
    render: int = 1
    motions: bool = True

    def argv(self) -> list[str]:
        """The ``latentrl eval`` arguments that make this request (what quickstart prints)."""
        args = ["eval", self.policy]
        options = (("--paths", self.paths), ("--episodes", self.episodes), ("--max-steps", self.max_steps),
                   ("--motion", self.motion), ("--foot-lock-min-weight", self.foot_lock_min_weight),
                   ("--device", self.device), ("--out", self.out),
                   ("--render", self.render))
        for flag, value in options:
            if value is not None:
                args += [flag, *map(str, value)] if isinstance(value, list) else [flag, str(value)]
        return args


@dataclass
class CompareRequest:
    """``latentrl compare``: report files (or eval folders), and an optional markdown file to write."""

    reports: list[str] = field(default_factory=list)
    out: str | None = None


TASK_SUITES: dict[str, tuple[str, ...]] = {"joystick": ("joystick_walk", "joystick_run"), "timed": ("timed_walk",)}
"""Shipped suites of the tasks with their own evaluator; ``latentrl eval`` runs those whose texts the policy knows."""


def resolve_path_files(specs: list[str] | None, kind: str = "paths",
                       defaults: tuple[str, ...] = DEFAULT_SUITES) -> list[Path]:
    """Suite files from ``--paths``: existing files, or suite names in ``tasks/<kind>`` (``sharp_turns``)."""
    from latentrl.resources import suites_folder

    folder, files = suites_folder(kind), []
    for spec in specs or defaults:
        path = Path(spec)
        if not path.is_file():
            named = folder / f"{spec.removesuffix('.json')}.json"
            if not named.is_file():
                known = sorted(p.stem for p in folder.glob("*.json")) if folder.is_dir() else []
                raise DataError(f"path file not found: {spec} (give a file, or one of the suites {known})")
            path = named
        files.append(path)
    stems = [p.stem for p in files]
    dupes = sorted({s for s in stems if stems.count(s) > 1})
    if dupes:
        raise ConfigError(f"--paths: file names must differ (reports are keyed by them), repeated: {dupes}")
    return files


def _settings(req: EvalRequest, device: str | None = None) -> EvalSettings:
    import torch

    from latentrl.preflight import check_device

    device = device or req.device or ("cuda" if torch.cuda.is_available() else "cpu")
    check_device(device, "--device")
    settings = EvalSettings(episodes=req.episodes, max_steps=req.max_steps, deterministic=req.deterministic,
                            seed=req.seed, device=device)
    try:
        settings.validate()
    except ConfigError as exc:  # name the flag: "max_steps: ..." -> "--max-steps: ..."
        field_name, _, message = str(exc).partition(": ")
        raise ConfigError(f"--{field_name.replace('_', '-')}: {message}") from None
    if req.render < 0:
        raise ConfigError(f"--render must be >= 0, got {req.render}")
    if req.foot_lock_min_weight is not None and (problem := lock_min_weight_problem(req.foot_lock_min_weight)):
        raise ConfigError(f"--foot-lock-min-weight {problem}")
    return settings


def check_eval_request(req: EvalRequest) -> None:
    """What ``latentrl quickstart`` checks before it trains: the settings and path files of its evaluation."""
    from latentrl.envs import load_paths

    _settings(req, device="cpu")
    for file in resolve_path_files(req.paths):
        load_paths(file)


def _load(req: EvalRequest, settings: EvalSettings) -> tuple[Any, Any, dict, dict, bool | None]:
    """Motion model, loaded policy, their identities, and the policy's ``observe_next`` (None: not stored).

    Refuses a policy trained on another model. The env config stored in the checkpoint sets the
    settings' guidance and action bound, so the eval env steps the motion as training did.
    """
    from latentrl.envs.config import stored_env_config
    from latentrl.motion.checkpoint import attach_seed_history, file_sha256, load_motion_model
    from latentrl.ppo import load_policy

    model = load_motion_model(req.motion, device=settings.device)
    motion = {"source": model.info.get("source"), "sha256": model.info.get("sha256")}
    loaded = load_policy(req.policy, settings.device, motion={"path": motion["source"], "sha256": motion["sha256"]},
                         allow_motion_mismatch=req.allow_motion_mismatch)
    meta = loaded.checkpoint
    policy = {"path": str(req.policy), "sha256": file_sha256(req.policy), "iteration": meta.get("iteration"),
              "env_steps": meta.get("env_steps"), "trainer": meta.get("trainer"), "version": meta.get("version"),
              "config_hash": meta.get("config_hash"), "trained_on": meta.get("motion")}
    env = stored_env_config(meta.get("config"))
    if env is not None:
        settings.take_training_env(env)
        if env.seed_history:  # episodes start from the seeds the policy was trained on
            attach_seed_history(model, env.seed_history)
    if req.foot_lock_min_weight is not None:
        settings.foot_lock_min_weight = float(req.foot_lock_min_weight)
    return model, loaded.policy, motion, policy, None if env is None else env.observe_next


def _sink(out_dir: Path, render: int, write_motions: bool):
    """Per-episode writer: the motion ``.npz`` and, for the first ``render`` episodes of a path, GIF + BVH."""
    from latentrl.motion.clip import MotionClip
    from latentrl.render import render_gif, save_bvh

    def sink(ep: EpisodeResult, motion: dict) -> str | None:
        name = f"{ep.suite}_path{ep.path_index}_ep{ep.episode:03d}"
        clip = MotionClip.from_dict(motion)
        written = None
        if write_motions:
            clip.meta.update(suite=ep.suite, path_index=ep.path_index, episode=ep.episode, success=ep.success,
                             end=ep.end, reach_time_s=ep.reach_time_s)
            clip.save(out_dir / "motions" / f"{name}.npz")
            written = f"motions/{name}.npz"
        if ep.episode < render:
            title = f"{ep.suite} path {ep.path_index} ep {ep.episode} ({ep.end})"
            render_gif(out_dir / "renders" / f"{name}.gif", clip.joints, texts=clip.texts, title=title,
                       stride=GIF_STRIDE, goals=clip.waypoints)
            save_bvh(out_dir / "renders" / f"{name}.bvh", clip.joints, clip.fps)
        return written

    return sink


def _progress(result: PathResult) -> None:
    wins = sum(ep.success for ep in result.episodes)
    times = [ep.reach_time_s for ep in result.episodes if ep.success]
    reach = f", reach time of successes {sum(times) / len(times):.1f} s" if times else ""
    from latentrl.evaluation.results import prompts_label
    from latentrl.evaluation.skills import match_share

    judged = [s for ep in result.episodes for s in ep.segments if s["match"] is not None]
    skill = f", skill matched in {match_share(judged):.0%} of {len(judged)} segments" if judged else ""
    print(f"{result.suite} path {result.index} ({prompts_label(result.path.texts)}): {wins}/{len(result.episodes)} "
          f"reached{reach}{skill} ({result.wall_s:.0f} s)", flush=True)


def evaluate(req: EvalRequest) -> int:
    """``latentrl eval``: run the suites, measure speed, write the report, plot and motions."""
    from latentrl.envs import load_paths
    from latentrl.evaluation import plots, report
    from latentrl.evaluation.runner import fit_policy, measure_speed, policy_fn, run_suites
    from latentrl.evaluation.trained import motion_of, stored_env
    from latentrl.preflight import NewOutput, check_writable
    from latentrl.resources import is_packaged, policy_file
    from latentrl.timing import hardware

    env = stored_env(policy_file(req.policy))
    if req.motion is None:  # the model the policy was trained with: no flag to repeat
        req.motion = motion_of(env)
    if env is not None and env.task in TASK_SUITES:
        return evaluate_task(req, env)
    settings = _settings(req)
    files = resolve_path_files(req.paths)
    first_path = [load_paths(f) for f in files][0][0]  # check every file before loading models
    req.policy = str(policy_file(req.policy))  # a file, or a shipped policy by name (reach_walk_default)
    beside = Path.cwd() if is_packaged(req.policy) else Path(req.policy).resolve().parent
    out_dir = Path(req.out) if req.out else beside / f"eval-{Path(req.policy).stem}"
    check_writable(out_dir, "--out")
    model, policy, motion, policy_info, observe_next = _load(req, settings)
    observe_next = fit_policy(policy.obs_dim, policy.action_dim, model, settings, observe_next)
    act = policy_fn(policy, settings.deterministic)
    with NewOutput(out_dir):  # a failure from here on removes the output folder this command created
        suites = run_suites(act, model, files, settings, observe_next=observe_next,
                            sink=_sink(out_dir, req.render, req.motions), progress=_progress)
        speed = measure_speed(act, model, first_path, settings, [1, settings.episodes], observe_next)
        png = plots.save_paths_png(out_dir / report.PATHS_PNG, suites)
        outputs = {"paths_png": png.name, "motions": "motions/" if req.motions else None,
                   "renders": "renders/" if req.render else None}
        data = report.build_report(suites, settings, policy=policy_info, motion=motion, speed=speed,
                                   hardware=hardware(), files=outputs)
        js, md = report.write_report(out_dir, data)
    print("\n".join(report.results_table(data)))
    if any(s.get("skills") for s in data["suites"].values()):
        print("\n" + "\n".join(report.skills_table(data)))
    print(f"wrote {js}, {md}, {png}")
    return 0


def _task_entries(task: str, file) -> list:
    """The entries of a suite file of ``task``: command timelines (joystick) or timed paths (timed)."""
    from latentrl.evaluation import joystick, timed

    return joystick.load_timelines(file) if task == "joystick" else timed.load_timed_paths(file)


def _task_suites(task: str, texts) -> tuple[str, ...]:
    """The shipped suites of ``task`` whose every text the policy was trained on (all of them if none is)."""
    from latentrl.resources import suites_folder

    known, fits = set(texts), []
    for name in TASK_SUITES[task]:
        entries = _task_entries(task, suites_folder(task) / f"{name}.json")
        used = {e.text for e in entries} if task == "joystick" else {t for e in entries for t in e.texts}
        if used <= known:
            fits.append(name)
    return tuple(fits) or TASK_SUITES[task]


def _task_sink(out_dir: Path, render: int, write_motions: bool):
    """Per-episode writer of the task evaluations: the motion ``.npz`` and, for the first ``render``, GIF + BVH."""
    from latentrl.render import render_gif, save_bvh

    def sink(ep, clip) -> str | None:
        name = f"{ep.suite}_{ep.index}_ep{ep.episode:03d}"
        written = None
        if write_motions:
            clip.meta.update(suite=ep.suite, index=ep.index, episode=ep.episode, end=ep.end)
            clip.save(out_dir / "motions" / f"{name}.npz")
            written = f"motions/{name}.npz"
        if ep.episode < render:
            render_gif(out_dir / "renders" / f"{name}.gif", clip.joints, texts=clip.texts,
                       title=f"{ep.suite} {ep.index} ep {ep.episode} ({ep.end})", stride=GIF_STRIDE,
                       goals=clip.waypoints)
            save_bvh(out_dir / "renders" / f"{name}.bvh", clip.joints, clip.fps)
        return written

    return sink


def evaluate_task(req: EvalRequest, env_cfg) -> int:
    """``latentrl eval`` of a joystick or timed policy: its task's suites, report.json/.md and motions."""
    from latentrl.errors import CheckpointError
    from latentrl.evaluation import joystick, timed
    from latentrl.evaluation.runner import policy_fn
    from latentrl.evaluation.task_eval import aggregate, build_task_report, results_table, write_task_report
    from latentrl.preflight import NewOutput, check_writable
    from latentrl.resources import is_packaged, policy_file
    from latentrl.timing import hardware

    task = env_cfg.task
    module = joystick if task == "joystick" else timed
    settings = _settings(req)
    files = resolve_path_files(req.paths, task, _task_suites(task, env_cfg.texts))
    entries = [_task_entries(task, f) for f in files]  # check every file before loading models
    req.policy = str(policy_file(req.policy))
    beside = Path.cwd() if is_packaged(req.policy) else Path(req.policy).resolve().parent
    out_dir = Path(req.out) if req.out else beside / f"eval-{Path(req.policy).stem}"
    check_writable(out_dir, "--out")
    model, policy, motion, policy_info, observe_next = _load(req, settings)
    first = entries[0][0]
    probe = (joystick.make_env(model, first, 1, settings) if task == "joystick"
             else timed.make_env(model, first, 1, settings, observe_next=bool(observe_next)))
    dims = (probe.single_observation_space.shape[0], probe.single_action_space.shape[0])
    if (policy.obs_dim, policy.action_dim) != dims:
        raise CheckpointError(f"the policy takes {policy.obs_dim}-D observations and gives {policy.action_dim}-D "
                              f"actions, but the {task} env has {dims[0]} and {dims[1]}; evaluate with the motion "
                              "model the policy was trained on (--motion)")
    act = policy_fn(policy, settings.deterministic)
    extra = {"observe_next": bool(observe_next)} if task == "timed" else {}
    criteria = module.TrackingCriteria() if task == "joystick" else module.TimingCriteria()

    def progress(result) -> None:
        means = {k: v["mean"] for k, v in aggregate(result.episodes).items()}
        shown = ", ".join(f"{k} {v:.2f}" for k, v in means.items() if v == v)
        print(f"{result.suite} {result.index} ({result.label}): {shown} ({result.wall_s:.0f} s)", flush=True)

    with NewOutput(out_dir):
        suites = module.run_suites(act, model, files, settings, criteria=criteria,
                                   sink=_task_sink(out_dir, req.render, req.motions), progress=progress, **extra)
        data = build_task_report(task, suites, settings, module.UNITS, module.DEFINITIONS,
                                 criteria=dataclasses.asdict(criteria), policy=policy_info, motion=motion,
                                 hardware=hardware())
        js, md = write_task_report(out_dir, data)
    print("\n".join(results_table(data)))
    print(f"wrote {js}, {md}")
    return 0


def compare(req: CompareRequest) -> int:
    """``latentrl compare``: print (and optionally write) several reports side by side."""
    from latentrl.evaluation.report import compare_reports
    from latentrl.preflight import check_output_file

    if req.out:
        check_output_file(req.out)
    table = compare_reports(req.reports)
    print(table, end="")
    if req.out:
        from latentrl.safe_io import atomic_write_text

        atomic_write_text(req.out, table)
        print(f"wrote {req.out}")
    return 0
