"""The evaluators of the shipped tasks (:class:`~latentrl.envs.tasks.Evaluator`), attached to their specs on import.

Reach and path policies are judged by DART's path protocol (:mod:`~latentrl.evaluation.runner`), joystick,
timed and joint-goal policies by their own evaluators (:mod:`~latentrl.evaluation.joystick`,
:mod:`~latentrl.evaluation.timed`, :mod:`~latentrl.evaluation.joint_goals`). ``latentrl eval`` and the
trainer's periodic evaluation only call the protocol's methods, so a task registered from outside the package
brings its own evaluator instead.

Every episode's motion goes to ``motions/<suite>_<entry>_ep<e>.npz``; the first ``render`` episodes of an
entry are also drawn as ``renders/*.gif`` (every :data:`GIF_STRIDE` th frame) or ``renders/*.mp4`` (every frame,
``render_format``), with the episode's scene and goals, and written as BVH.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from latentrl.envs.config import resolve_task_file
from latentrl.envs.path import load_paths
from latentrl.envs.tasks import attach_evaluator
from latentrl.errors import CheckpointError
from latentrl.evaluation import joint_goals, joystick, plots, report, sit, timed
from latentrl.evaluation.config import EvalConfig
from latentrl.evaluation.results import EpisodeResult, PathResult, SuiteResult, prompts_label
from latentrl.evaluation.runner import fit_policy, measure_speed, run_suites
from latentrl.evaluation.skills import match_share
from latentrl.evaluation.task_eval import aggregate, build_task_report, results_table, write_task_report
from latentrl.motion.clip import MotionClip
from latentrl.render import render_clip, save_bvh

GIF_STRIDE = 3
"""Rendered GIFs keep every 3rd frame (10 fps): a 60 s episode is 600 frames, about a minute to draw on CPU."""


RENDER_FORMATS = ("gif", "mp4")
"""What ``latentrl eval --render`` draws episodes as (MP4 needs ``latentrl[video]``)."""


def write_episode(out_dir: Path, name: str, clip: MotionClip, title: str, write_motion: bool,
                  render: bool, render_format: str = "gif") -> str | None:
    """Save one episode's motion (``motions/<name>.npz``) and, if ``render``, its GIF or MP4 and BVH; the motion."""
    written = None
    if write_motion:
        clip.save(out_dir / "motions" / f"{name}.npz")
        written = f"motions/{name}.npz"
    if render:
        gif = render_format == "gif"
        render_clip(out_dir / "renders" / f"{name}.{render_format}", clip, title, stride=GIF_STRIDE if gif else 1)
        save_bvh(out_dir / "renders" / f"{name}.bvh", clip.joints, clip.fps)
    return written


@dataclass
class PathRun:
    """What the path evaluator's :meth:`~PathEvaluator.run` hands to its report."""

    suites: list
    speed: dict
    motions: bool
    render: int
    render_format: str = "gif"


class PathEvaluator:
    """DART's path protocol (reach and path policies): success, reach time, skate, floor, skill per segment."""

    suite_kind = "paths"

    def load_suite(self, file: Path) -> list:
        """The waypoint paths of a DART path file."""
        return load_paths(file)

    def default_suites(self, suites: tuple[str, ...], texts: Sequence[str]) -> tuple[str, ...]:
        """DART's Table 4 suites whose every prompt the policy was trained on (all of them if none is).

        A walk policy is not judged on the hop suite: it would fail there after minutes per path.
        """
        from latentrl.resources import suites_folder

        known = set(texts)
        fits = [name for name in suites
                if all(set(p.texts) <= known for p in load_paths(suites_folder(self.suite_kind) / f"{name}.json"))]
        return tuple(fits) or suites

    def fit(self, policy: Any, motion: Any, files: Sequence[Path], settings: Any, observe_next: bool | None) -> bool:
        """The policy fits FollowPath; whether it observes the next waypoint (from its size when not stored)."""
        return fit_policy(policy.obs_dim, policy.action_dim, motion, settings, observe_next)

    def run(self, act: Callable, motion: Any, files: Sequence[Path], settings: Any, *, observe_next: bool,
            out_dir: Path | None = None, render: int = 0, motions: bool = False,
            after_entry: Callable[[PathRun], None] | None = None, render_format: str = "gif",
            wrap: Callable[[Any, Callable], Callable] | None = None) -> PathRun:
        """Every path of every file, then the controller's speed at batch 1 and at ``settings.episodes``.

        ``after_entry`` gets the paths done so far (no speed yet) after each path; ``wrap(env, act) -> act``: a
        policy function that also reads the env (``eval --avoid``; the speed is the policy's own).
        """
        def sink(ep: EpisodeResult, data: dict) -> str | None:
            clip = MotionClip.from_dict(data)
            if motions:
                clip.meta.update(suite=ep.suite, path_index=ep.path_index, episode=ep.episode, success=ep.success,
                                 end=ep.end, reach_time_s=ep.reach_time_s)
            return write_episode(out_dir, f"{ep.suite}_path{ep.path_index}_ep{ep.episode:03d}", clip,
                                 f"{ep.suite} path {ep.path_index} ep {ep.episode} ({ep.end})", motions,
                                 ep.episode < render, render_format)

        done: list[SuiteResult] = []
        file_of = {Path(f).stem: str(Path(f)) for f in files}

        def progress(result: PathResult) -> None:
            _path_progress(result)
            if not done or done[-1].name != result.suite:
                done.append(SuiteResult(result.suite, file_of[result.suite], []))
            done[-1].paths.append(result)
            if after_entry is not None:
                after_entry(PathRun(done, {}, motions, render, render_format))

        suites = run_suites(act, motion, files, settings, observe_next=observe_next,
                            sink=sink if out_dir is not None else None, progress=progress, wrap=wrap)
        first = load_paths(files[0])[0]
        speed = measure_speed(act, motion, first, settings, [1, settings.episodes], observe_next)
        return PathRun(suites, speed, motions, render, render_format)

    def report(self, results: PathRun, settings: Any, out_dir: Path, **info: Any) -> list[str]:
        """report.json, report.md and paths.png; the results (and skills) tables."""
        png = plots.save_paths_png(out_dir / report.PATHS_PNG, results.suites)
        outputs = {"paths_png": png.name, "motions": "motions/" if results.motions else None,
                   "renders": f"renders/*.{results.render_format}" if results.render else None}
        data = report.build_report(results.suites, settings, speed=results.speed, files=outputs, **info)
        js, md = report.write_report(out_dir, data)
        lines = report.results_table(data)
        if any(s.get("skills") for s in data["suites"].values()):
            lines += ["", *report.skills_table(data)]
        return [*lines, f"wrote {js}, {md}, {png}"]

    def training_files(self, paths: Sequence[str], suites: tuple[str, ...]) -> list[Path]:
        """``eval.paths`` as files (paths, packaged files or suite names)."""
        return [resolve_task_file(p) for p in paths]

    def training_hook(self, files: Sequence[Path], motion: Any, env_cfg: Any, eval_cfg: Any, device: str) -> Callable:
        """:func:`latentrl.evaluation.runner.training_eval_hook`."""
        from latentrl.evaluation.runner import training_eval_hook

        return training_eval_hook(files, motion, env_cfg, eval_cfg, device=device)


def _path_progress(result: PathResult) -> None:
    wins = sum(ep.success for ep in result.episodes)
    times = [ep.reach_time_s for ep in result.episodes if ep.success]
    reach = f", reach time of successes {sum(times) / len(times):.1f} s" if times else ""
    judged = [s for ep in result.episodes for s in ep.segments if s["match"] is not None]
    skill = f", skill matched in {match_share(judged):.0%} of {len(judged)} segments" if judged else ""
    _say(f"{result.suite} path {result.index} ({prompts_label(result.path.texts)}): {wins}/{len(result.episodes)} "
         f"reached{reach}{skill} ({result.wall_s:.0f} s)")


def _say(line: str) -> None:
    """Print one progress line above the progress bar (tqdm redraws the bar below it)."""
    import sys

    from tqdm import tqdm

    tqdm.write(line, file=sys.stdout)
    sys.stdout.flush()


@dataclass
class TaskRun:
    """What a suite evaluator's :meth:`~SuiteEvaluator.run` hands to its report."""

    suites: list
    criteria: Any


class SuiteEvaluator:
    """The joystick and timed evaluations: per-entry metrics of :mod:`~latentrl.evaluation.task_eval`'s format.

    ``module`` is :mod:`~latentrl.evaluation.joystick` or :mod:`~latentrl.evaluation.timed` (``load``,
    ``make_env``, ``run_suites``, ``training_eval_hook``, ``UNITS``, ``DEFINITIONS``), ``criteria`` its
    criteria class and ``entry_texts`` the prompts one suite entry uses.
    """

    def __init__(self, task: str, module: Any, load: Callable[[Path], list], criteria: type,
                 entry_texts: Callable[[Any], set[str]], takes_observe_next: bool):
        self.task, self.suite_kind, self.module, self._load = task, task, module, load
        self.criteria, self.entry_texts, self.takes_observe_next = criteria, entry_texts, takes_observe_next

    def load_suite(self, file: Path) -> list:
        """The entries of one suite file."""
        return self._load(file)

    def default_suites(self, suites: tuple[str, ...], texts: Sequence[str]) -> tuple[str, ...]:
        """The shipped suites whose every text the policy was trained on (all of them if none is)."""
        from latentrl.resources import suites_folder

        known = set(texts)
        fits = [name for name in suites
                if set().union(*map(self.entry_texts, self._load(suites_folder(self.suite_kind) / f"{name}.json")))
                <= known]
        return tuple(fits) or suites

    def _observe_next(self, observe_next: bool | None) -> dict[str, bool]:
        return {"observe_next": bool(observe_next)} if self.takes_observe_next else {}

    def fit(self, policy: Any, motion: Any, files: Sequence[Path], settings: Any, observe_next: bool | None) -> bool:
        """Refuse a policy whose sizes differ from the task env's; the stored ``observe_next`` (False if none)."""
        first = self._load(files[0])[0]
        probe = self.module.make_env(motion, first, 1, settings, **self._observe_next(observe_next))
        dims = (probe.single_observation_space.shape[0], probe.single_action_space.shape[0])
        if (policy.obs_dim, policy.action_dim) != dims:
            raise CheckpointError(f"the policy takes {policy.obs_dim}-D observations and gives {policy.action_dim}-D "
                                  f"actions, but the {self.task} env has {dims[0]} and {dims[1]}; evaluate with the "
                                  "motion model the policy was trained on (--motion)")
        return bool(observe_next)

    def run(self, act: Callable, motion: Any, files: Sequence[Path], settings: Any, *, observe_next: bool,
            out_dir: Path | None = None, render: int = 0, motions: bool = False,
            after_entry: Callable[[TaskRun], None] | None = None, render_format: str = "gif",
            wrap: Callable[[Any, Callable], Callable] | None = None) -> TaskRun:
        """Every entry of every suite file with the default criteria; ``after_entry`` gets those done so far.

        ``wrap(env, act) -> act``: a policy function that also reads the env (``eval --refine``, ``--avoid``).
        """
        def sink(ep, clip: MotionClip) -> str | None:
            if motions:
                clip.meta.update(suite=ep.suite, index=ep.index, episode=ep.episode, end=ep.end)
            return write_episode(out_dir, f"{ep.suite}_{ep.index}_ep{ep.episode:03d}", clip,
                                 f"{ep.suite} {ep.index} ep {ep.episode} ({ep.end})", motions, ep.episode < render,
                                 render_format)

        criteria = self.criteria()
        done: list[tuple[str, str, list]] = []
        file_of = {Path(f).stem: str(Path(f)) for f in files}

        def progress(result) -> None:
            _task_progress(result)
            if not done or done[-1][0] != result.suite:
                done.append((result.suite, file_of[result.suite], []))
            done[-1][2].append(result)
            if after_entry is not None:
                after_entry(TaskRun(done, criteria))

        suites = self.module.run_suites(act, motion, files, settings, criteria=criteria,
                                        sink=sink if out_dir is not None else None, progress=progress,
                                        **self._observe_next(observe_next), **({"wrap": wrap} if wrap else {}))
        return TaskRun(suites, criteria)

    def report(self, results: TaskRun, settings: Any, out_dir: Path, **info: Any) -> list[str]:
        """report.json (format ``latentrl.eval.task/1``) and report.md; the results table."""
        data = build_task_report(self.task, results.suites, settings, self.module.UNITS, self.module.DEFINITIONS,
                                 criteria=dataclasses.asdict(results.criteria), **info)
        js, md = write_task_report(out_dir, data)
        return [*results_table(data), f"wrote {js}, {md}"]

    def training_files(self, paths: Sequence[str], suites: tuple[str, ...]) -> list[Path]:
        """``eval.paths`` when the config names them, else the task's first shipped suite."""
        chosen = paths if list(paths) != EvalConfig().paths else list(suites[:1])
        return [resolve_task_file(p, self.suite_kind) for p in chosen]

    def training_hook(self, files: Sequence[Path], motion: Any, env_cfg: Any, eval_cfg: Any, device: str) -> Callable:
        """The module's ``training_eval_hook``."""
        return self.module.training_eval_hook(files, motion, env_cfg, eval_cfg, device=device)


def _task_progress(result) -> None:
    means = {k: v["mean"] for k, v in aggregate(result.episodes).items()}
    shown = ", ".join(f"{k} {v:.2f}" for k, v in means.items() if v == v)
    _say(f"{result.suite} {result.index} ({result.label}): {shown} ({result.wall_s:.0f} s)")


class JointGoalEvaluator(SuiteEvaluator):
    """The ReachJoint evaluation (:mod:`~latentrl.evaluation.joint_goals`).

    Its report adds paths.png, with each goal's target drawn as a marker of its joint.
    """

    def __init__(self):
        super().__init__("reach_joint", joint_goals, joint_goals.load_joint_goals, joint_goals.JointGoalCriteria,
                         lambda entry: {entry.text}, takes_observe_next=False)
        self.suite_kind = "joint_goals"

    def report(self, results: TaskRun, settings: Any, out_dir: Path, **info: Any) -> list[str]:
        """report.json, report.md and paths.png; the results table."""
        lines = super().report(results, settings, out_dir, **info)
        png = joint_goals.save_png(out_dir / report.PATHS_PNG, results.suites)
        return [*lines[:-1], f"{lines[-1]}, {png}"]


PATHS = PathEvaluator()
JOYSTICK = SuiteEvaluator("joystick", joystick, joystick.load_timelines, joystick.TrackingCriteria,
                          lambda entry: {entry.text}, takes_observe_next=False)
TIMED = SuiteEvaluator("timed", timed, timed.load_timed_paths, timed.TimingCriteria,
                       lambda entry: set(entry.texts), takes_observe_next=True)

JOINT_GOALS = JointGoalEvaluator()
SIT = SuiteEvaluator("sit", sit, sit.load_seats, sit.SitCriteria, lambda entry: set(), takes_observe_next=False)

for _task, _evaluator in (("reach", PATHS), ("path", PATHS), ("joystick", JOYSTICK), ("timed", TIMED),
                          ("reach_joint", JOINT_GOALS), ("sit", SIT)):
    attach_evaluator(_task, _evaluator)
