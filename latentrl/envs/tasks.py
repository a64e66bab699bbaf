"""The task registry: one :class:`TaskSpec` per task, and the :class:`Evaluator` protocol its evaluation implements.

A task is its env class, the dataclass of its ``env.<task>`` config section, an optional Gymnasium id,
the suites ``latentrl eval`` runs by default and its evaluator. Commands look tasks up here and never
name one, so a task defined outside the package works after one :func:`register_task` call::

    register_task(TaskSpec("toy", ToyEnv, ToyConfig, suite_kind="toy", suites=("toy_walk",), evaluator=ToyEval()))

The shipped tasks name their env class and section as ``"module:attr"`` strings, loaded on first use,
so that ``import latentrl`` (which registers the Gymnasium ids) loads no torch. Their evaluators live one
floor up, in :mod:`latentrl.evaluation`, which attaches them (:mod:`latentrl.evaluation.tasks`).
"""

from __future__ import annotations

import dataclasses
import importlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import gymnasium


class Evaluator(Protocol):
    """How ``latentrl eval`` and the trainer's periodic evaluation judge a policy of one task.

    ``latentrl eval`` calls, in order: :meth:`load_suite` on every suite file (all checked before a model
    loads), :meth:`fit` (does the policy fit the task's env), :meth:`run` (episodes of every entry of every
    suite) and :meth:`report` (the files written into the output folder and the lines printed).
    """

    suite_kind: str
    """Folder of ``tasks/`` in which suite names resolve (``paths``, ``joystick``, ``timed``)."""

    def load_suite(self, file: Path) -> list:
        """Parse and check one suite file; its entries (paths, timelines, ...)."""

    def default_suites(self, suites: tuple[str, ...], texts: Sequence[str]) -> tuple[str, ...]:
        """Which of the task's shipped ``suites`` to run for a policy trained on ``texts``."""

    def fit(self, policy: Any, motion: Any, files: Sequence[Path], settings: Any, observe_next: bool | None) -> bool:
        """Refuse a policy that does not fit the task's env (probed on ``files``); whether it observes the next goal.

        ``observe_next`` is what the policy's stored env config says (None: it stores none).
        """

    def run(self, act: Callable, motion: Any, files: Sequence[Path], settings: Any, *, observe_next: bool,
            out_dir: Path | None = None, render: int = 0, motions: bool = False,
            after_entry: Callable[[Any], None] | None = None) -> Any:
        """Episodes of every entry of every suite file (one progress line printed per entry); their results.

        With ``out_dir``, each episode's motion goes to ``motions/`` (if ``motions``) and the first ``render``
        episodes of an entry to ``renders/`` as GIF and BVH. ``after_entry`` (optional: ``latentrl eval``
        passes it only to a ``run`` that takes it) gets the results so far, as :meth:`report` takes them,
        after each entry: the eval rewrites its report and moves its progress bar.
        """

    def report(self, results: Any, settings: Any, out_dir: Path, **info: Any) -> list[str]:
        """Write the report files of ``results`` into ``out_dir``; the lines to print (tables, files written).

        ``info`` holds ``policy``, ``motion`` and ``hardware`` (what the report records of the run).
        """

    def training_files(self, paths: Sequence[str], suites: tuple[str, ...]) -> list[Path]:
        """The suite files of the trainer's periodic evaluation from ``eval.paths``."""

    def training_hook(self, files: Sequence[Path], motion: Any, env_cfg: Any, eval_cfg: Any,
                      device: str) -> Callable:
        """The trainer's periodic evaluation: ``policy -> EvalReport``."""


@dataclass(frozen=True)
class TaskSpec:
    """One task: everything the commands need to build, train and evaluate it."""

    name: str
    """``env.task`` in configs."""
    env: type | str
    """The env class (a ``LatentMotionVectorEnv`` subclass), or ``"module:Class"`` loaded on first use."""
    config: type | str
    """Dataclass of the task's constructor arguments with ``kwargs()`` (and ``validate()``), or ``"module:Class"``.
    Its values come from ``env.<name>`` when :class:`~latentrl.envs.config.EnvConfig` has that section, else
    from ``env.options``."""
    gym_id: str | None = None
    """A Gymnasium id (registered by :func:`register_task`): ``make_vec`` builds the env, ``make`` one ``SingleEnv``."""
    max_episode_steps: int = 32
    """Steps before truncation that the Gymnasium id passes to the constructor."""
    suite_kind: str = "paths"
    """Folder of ``tasks/`` holding the task's suite files."""
    suites: tuple[str, ...] = ()
    """Shipped suites ``latentrl eval`` runs without ``--paths`` (the evaluator picks those the policy knows)."""
    evaluator: Evaluator | None = None
    """How its policies are evaluated; None: ``latentrl eval`` refuses them."""

    def env_class(self) -> type:
        """The env class (imported now if it was named by a string)."""
        return _load(self.env)

    def config_class(self) -> type:
        """The section dataclass (imported now if it was named by a string)."""
        return _load(self.config)


def _load(ref: type | str) -> Any:
    if not isinstance(ref, str):
        return ref
    module, _, attr = ref.partition(":")
    return getattr(importlib.import_module(module), attr)


TASKS: dict[str, TaskSpec] = {}
"""Task name -> its spec, in registration order (the shipped tasks first)."""


def register_task(spec: TaskSpec, *, replace: bool = False) -> TaskSpec:
    """Add ``spec`` to :data:`TASKS` (and its Gymnasium id); ``replace`` allows re-registering a name."""
    if spec.name in TASKS and not replace:
        raise ValueError(f"task '{spec.name}' is registered already; pass replace=True to replace it")
    TASKS[spec.name] = spec
    if spec.gym_id is not None and (replace or spec.gym_id not in gymnasium.registry):
        from latentrl.envs.single import SingleEntryPoint  # gymnasium.make's single env

        gymnasium.register(id=spec.gym_id, entry_point=SingleEntryPoint(spec.env, spec.max_episode_steps),
                           vector_entry_point=spec.env, max_episode_steps=spec.max_episode_steps)
    return spec


def attach_evaluator(name: str, evaluator: Evaluator) -> None:
    """Give a registered task its evaluator (how :mod:`latentrl.evaluation` equips the shipped tasks)."""
    TASKS[name] = dataclasses.replace(task_spec(name), evaluator=evaluator)


def task_spec(name: str) -> TaskSpec:
    """The spec of a registered task (``KeyError`` naming the known ones otherwise)."""
    try:
        return TASKS[name]
    except KeyError:
        raise KeyError(f"unknown task '{name}'; known: {', '.join(TASKS)}") from None


for _spec in (
    TaskSpec("reach", "latentrl.envs.reach:ReachLocationEnv", "latentrl.envs.config:ReachConfig",
             "latentrl/ReachLocation-v0", 32, "paths", ("dart_walk_long", "dart_run_long", "dart_hop_long")),
    TaskSpec("path", "latentrl.envs.path:FollowPathEnv", "latentrl.envs.config:PathConfig",
             "latentrl/FollowPath-v0", 256, "paths", ("dart_walk_long", "dart_run_long", "dart_hop_long")),
    TaskSpec("joystick", "latentrl.envs.joystick:JoystickEnv", "latentrl.envs.config:JoystickConfig",
             "latentrl/Joystick-v0", 75, "joystick", ("joystick_walk", "joystick_run")),
    TaskSpec("timed", "latentrl.envs.timed:TimedPathEnv", "latentrl.envs.config:TimedConfig",
             "latentrl/TimedPath-v0", 256, "timed", ("timed_walk",)),
    TaskSpec("reach_joint", "latentrl.envs.reach_joint:ReachJointEnv", "latentrl.envs.reach_joint:ReachJointConfig",
             "latentrl/ReachJoint-v0", 64, "joint_goals", ("pelvis_near", "pelvis_far")),
    TaskSpec("sit", "latentrl.envs.sit:SitEnv", "latentrl.envs.sit:SitConfig", "latentrl/Sit-v0", 64, "sit",
             ("sit_seats",)),
):
    TASKS[_spec.name] = _spec
