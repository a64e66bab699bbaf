"""Bodies of ``latentrl eval`` and ``latentrl compare`` (arguments in :mod:`latentrl.app.cli`).

``latentrl eval POLICY`` writes into ``--out``::

    report.json     machine-readable results (schema in docs/evaluation.md)
    report.md       the tables a person reads
    paths.png       top-down pelvis tracks, one panel per path
    motions/<suite>_path<i>_ep<e>.npz    every episode in the shared motion format
    renders/<suite>_path<i>_ep<e>.gif    with --render gif (or .mp4 with --render mp4): the first
                                         --render-episodes episodes of each path drawn as a body
    renders/<suite>_path<i>_ep<e>.bvh    the same motions as BVH (SMPL-22, Y-up, centimetres)

Nothing is drawn unless ``--render`` asks (drawing costs more than simulating); ``latentrl quickstart`` draws GIFs.

The policy's task (its checkpoint's ``env.task``; the path task when it stores none) decides how it is
judged: its :class:`~latentrl.envs.tasks.TaskSpec` names the evaluator, the folder of ``tasks/`` in which
``--paths`` names resolve and the suites run without ``--paths`` (those of the task's suites whose every
prompt the policy was trained on: a walk policy is not judged on hops). The report files are rewritten
after every path, so an interrupted eval leaves the report of the paths it finished. A joystick or timed
policy runs command timelines (``tasks/joystick/``) or timed paths (``tasks/timed/``), its ``report.json``
has the format ``latentrl.eval.task/1`` and its motions are named ``<suite>_<i>_ep<e>``.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch
from tqdm import tqdm

from latentrl.envs.config import stored_env_config
from latentrl.envs.path import load_paths
from latentrl.envs.scene import resolve_scene
from latentrl.envs.tasks import task_spec
from latentrl.errors import CheckpointError, ConfigError, DataError, LatentRLError
from latentrl.evaluation.config import EvalSettings
from latentrl.evaluation.report import compare_reports
from latentrl.evaluation.runner import policy_fn
from latentrl.evaluation.tasks import RENDER_FORMATS  # (importing it attaches the shipped tasks' evaluators)
from latentrl.evaluation.trained import motion_of, stored_env, stored_eval_choices
from latentrl.motion.checkpoint import attach_seed_history, file_sha256, load_motion_model
from latentrl.motion.rollout import lock_min_weight_problem
from latentrl.optim.avoid import AvoidSettings, avoiding
from latentrl.optim.refine import RefineSettings, refining
from latentrl.optim.sit_plan import SitPlanSettings, sit_planning
from latentrl.ppo import load_policy
from latentrl.preflight import check_device, check_output_file, check_writable, locked_output
from latentrl.render import video_problem
from latentrl.resources import is_packaged, policy_file, suites_folder
from latentrl.safe_io import atomic_write_text
from latentrl.scenes.courses import POOLS
from latentrl.timing import hardware

UNNAMED_TASK = "path"
"""The task of a policy whose checkpoint stores no env config: judged by DART's path protocol."""
DEFAULT_SUITES = task_spec(UNNAMED_TASK).suites
"""What ``latentrl eval`` runs without ``--paths`` for a reach or path policy: DART's Table 4 suites."""


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
    """None: the value the policy stores for evaluation (``eval.foot_lock_min_weight``), else its training
    value. Else the foot lock pins from this contact weight (a deployment choice that differs from training;
    the report's settings record it)."""
    device: str | None = None
    seed: int = 0
    out: str | None = None
    render: str | int = "none"
    """``none``, ``gif`` or ``mp4`` (an integer is the former form: 0 draws nothing, N the first N episodes as GIF)."""
    render_episodes: int = 1
    """With ``render``: how many episodes of every path are drawn."""
    motions: bool = True
    progress: bool = True
    """Show a progress bar over paths x episodes."""
    scene: str | None = None
    """A scene to evaluate in (a ``latentrl.scene/1`` file or name in tasks/scenes, or ``random_obstacles``); None:
    the policy's training scene. A policy trained without a scene is evaluated blind to it (docs/scenes.md)."""
    physics: bool = False
    """Reach/path policies: every primitive executed by the physics tracker, its simulated frames the next history;
    writes ``physics.json`` beside the kinematic run of the same seeds instead of the usual report (docs/physics.md)."""
    refine: int | None = None
    """ReachJoint policies: optimizer steps on the policy's noise before every env step (``latentrl.optim.refine``;
    0: off; None: the policy's stored ``eval.refine``, else off)."""
    refine_horizon: int | None = None
    """With ``refine``: primitives predicted, the first executed (None: the stored ``eval.refine_horizon``, else 3)."""
    refine_skate: float | None = None
    """With ``refine``: the weight of the predicted frames' foot skate (m/s) in the refiner's loss (None: the stored
    ``eval.refine_skate``, else 0)."""
    refine_start: str | None = None
    """With ``refine``: each step's refinement starts from the policy's action or from zero noise (``zeros``; None:
    the stored ``eval.refine_start``, else ``policy``)."""
    refine_pace: float | None = None
    """With ``refine``: the weight of the pace target of a goal beyond the horizon (None: the stored
    ``eval.refine_pace``, else 0.5)."""
    refine_land: int | None = None
    """With ``refine``: frames after a footstep's time its foot is held down on its stone (None: the stored
    ``eval.refine_land``, else 0: 2 frames held in x and y)."""
    avoid: int | None = None
    """Evaluations among objects: optimizer steps that move the policy's noise off a predicted collision
    (``latentrl.optim.avoid``; 0: off; None: the policy's stored ``eval.avoid``, else off)."""
    avoid_horizon: int | None = None
    """With ``avoid``: primitives predicted (None: the stored ``eval.avoid_horizon``, else 2)."""
    avoid_margin: float | None = None
    """With ``avoid``: metres beyond each joint's skin kept from objects (None: the stored ``eval.avoid_margin``,
    else 0.1)."""
    avoid_samples: int | None = None
    """With ``avoid``: draws of the policy tried before the optimizer (None: the stored ``eval.avoid_samples``,
    else 0)."""
    sit_plan: int | None = None
    """Sit policies: optimizer steps of the planned sit that replaces the policy's actions while it sits
    (``latentrl.optim.sit_plan``; 0: off; None: the policy's stored ``eval.sit_plan``, else off)."""
    sit_plan_samples: int | None = None
    """With ``sit_plan``: plans drawn before the optimizer (None: the stored ``eval.sit_plan_samples``, else 32)."""
    sit_plan_getup: int | None = None
    """With ``sit_plan``: primitives per plan of the stand-up and the walk away (0: the policy's; None: the stored
    ``eval.sit_plan_getup``, else 3)."""
    sit_plan_approach: float | None = None
    """With ``sit_plan``: metres from the sit-down spot within which the approach's end is planned too (0: the
    policy's; None: the stored ``eval.sit_plan_approach``, else 0)."""
    route: float | None = None
    """Evaluations among objects: the policy sees the next point of the shortest route keeping this many metres
    from every object in place of its goal (``latentrl.envs.guide``; 0: off; None: the policy's stored
    ``eval.route``, else off)."""

    def argv(self) -> list[str]:
        """The ``latentrl eval`` arguments that make this request (what quickstart prints)."""
        args = ["eval", self.policy]
        options = (("--paths", self.paths), ("--episodes", self.episodes), ("--max-steps", self.max_steps),
                   ("--motion", self.motion), ("--foot-lock-min-weight", self.foot_lock_min_weight),
                   ("--device", self.device), ("--out", self.out),
                   ("--render", self.render), ("--render-episodes", self.render_episodes if self.render not in
                                                                   ("none", 0) and self.render_episodes != 1 else None),
                   ("--scene", self.scene), ("--refine", self.refine),
                   ("--refine-horizon", self.refine_horizon),
                   ("--refine-skate", self.refine_skate),
                   ("--refine-start", self.refine_start),
                   ("--refine-pace", self.refine_pace), ("--refine-land", self.refine_land),
                   ("--avoid", self.avoid),
                   ("--avoid-horizon", self.avoid_horizon), ("--avoid-margin", self.avoid_margin),
                   ("--avoid-samples", self.avoid_samples), ("--sit-plan", self.sit_plan),
                   ("--sit-plan-samples", self.sit_plan_samples), ("--sit-plan-getup", self.sit_plan_getup),
                   ("--sit-plan-approach", self.sit_plan_approach),
                   ("--route", self.route))
        for flag, value in options:
            if value is not None:
                args += [flag, *map(str, value)] if isinstance(value, list) else [flag, str(value)]
        return args


@dataclass
class CompareRequest:
    """``latentrl compare``: report files (or eval folders), and an optional markdown file to write."""

    reports: list[str] = field(default_factory=list)
    out: str | None = None


def resolve_path_files(specs: list[str] | None, kind: str = "paths",
                       defaults: tuple[str, ...] = DEFAULT_SUITES) -> list[Path]:
    """Suite files from ``--paths``: existing files, or suite names in ``tasks/<kind>`` (``sharp_turns``)."""
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
    device = device or req.device or ("cuda" if torch.cuda.is_available() else "cpu")
    check_device(device, "--device")
    settings = EvalSettings(episodes=req.episodes, max_steps=req.max_steps, deterministic=req.deterministic,
                            seed=req.seed, device=device)
    try:
        settings.validate()
    except ConfigError as exc:  # name the flag: "max_steps: ..." -> "--max-steps: ..."
        field_name, _, message = str(exc).partition(": ")
        raise ConfigError(f"--{field_name.replace('_', '-')}: {message}") from None
    if not isinstance(req.render, str):  # the former --render N: the first N episodes as GIF
        if req.render < 0:
            raise ConfigError(f"--render must be >= 0, got {req.render}")
        req.render, req.render_episodes = ("gif", req.render) if req.render else ("none", req.render_episodes)
    if req.render not in ("none", *RENDER_FORMATS):
        raise ConfigError(f"--render must be one of none, {', '.join(RENDER_FORMATS)}, got '{req.render}'")
    if req.render_episodes < 1:
        raise ConfigError(f"--render-episodes must be >= 1, got {req.render_episodes}")
    if req.render != "none" and (problem := video_problem(f"episode.{req.render}")):
        raise ConfigError(f"--render {req.render}: {problem.removeprefix(f'episode.{req.render}: ')}")
    if req.foot_lock_min_weight is not None and (problem := lock_min_weight_problem(req.foot_lock_min_weight)):
        raise ConfigError(f"--foot-lock-min-weight {problem}")
    return settings


def check_eval_request(req: EvalRequest) -> None:
    """What ``latentrl quickstart`` checks before it trains: the settings and path files of its evaluation."""
    _settings(req, device="cpu")
    for file in resolve_path_files(req.paths):
        load_paths(file)


def _load(req: EvalRequest, settings: EvalSettings) -> tuple[Any, Any, dict, dict, bool | None]:
    """Motion model, loaded policy, their identities, and the policy's ``observe_next`` (None: not stored).

    Refuses a policy trained on another model. The env config stored in the checkpoint sets the
    settings' guidance and action bound, so the eval env steps the motion as training did.
    """
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
    if req.scene is not None:
        # a policy trained without a scene, or blind among one (env.observe_scene: false), has no rays
        settings.observe_scene = settings.observe_scene and settings.scene is not None
        settings.scene = {"random_obstacles": {}} if req.scene == "random_obstacles" else req.scene
        try:
            resolve_scene(settings.scene)
        except LatentRLError as exc:
            raise ConfigError(f"--scene: {str(exc).removeprefix('scene: ')}") from None
    return model, loaded.policy, motion, policy, None if env is None else env.observe_next


SCENE_SUITES = ("paths", "joint_goals", "timed", "joystick")
"""Suite kinds whose evaluation runs in a scene given by ``--scene`` (sit brings its own seat)."""


def eval_suites(policy: str, paths: list[str] | None) -> tuple[Any, list[Path]]:
    """The policy's task spec and the suite files to run: ``paths``, else the task's suites of its prompts.

    A policy trained on a course pool runs that pool's shipped suite by default (random mazes: ``maze``, random
    stairs: ``stairs``).
    """
    env = stored_env(policy_file(policy))
    spec = task_spec(env.task if env is not None else UNNAMED_TASK)
    evaluator = spec.evaluator
    if evaluator is None:
        raise ConfigError(f"{policy}: task '{spec.name}' has no evaluator (give its TaskSpec an evaluator)")
    defaults = evaluator.default_suites(spec.suites, env.texts if env is not None else ())
    scene = env.scene if env is not None else None
    pool = next((POOLS[key] for key in scene if key in POOLS), None) if isinstance(scene, dict) else None
    if pool is not None and evaluator.suite_kind == "paths":  # its training courses came with their routes:
        defaults = (pool.suite,)  # judge it on the shipped courses of that kind
    return spec, resolve_path_files(paths, evaluator.suite_kind, defaults)


def evaluate(req: EvalRequest) -> int:
    """``latentrl eval``: run the suites of the policy's task, write the report and motions."""
    found = policy_file(req.policy)  # a file, or a shipped policy by name (reach_walk_default)
    if not found.is_file():  # before any line about suites or stored settings
        raise CheckpointError(f"PPO checkpoint file not found: {req.policy}")
    env = stored_env(found)
    if req.motion is None:  # the model the policy was trained with: no flag to repeat
        req.motion = motion_of(env)
    spec, files = eval_suites(req.policy, req.paths)
    evaluator = spec.evaluator
    if req.scene is not None and evaluator.suite_kind not in SCENE_SUITES:  # others would ignore it
        raise ConfigError(f"--scene: the {spec.name} task's evaluation runs without a scene (reach, path, timed, "
                          "joystick and ReachJoint policies are evaluated among objects); leave out --scene")
    if req.scene == "random_obstacles" and evaluator.suite_kind == "joystick":
        raise ConfigError("--scene: a joystick policy takes a scene file or name, e.g. maze_a (random obstacles are "
                          "cleared around each goal, and a joystick's goal sweeps ahead of the body)")
    stored = stored_eval_choices(found)
    choices = (("refine", "--refine", int), ("refine_horizon", "--refine-horizon", int),
               ("refine_skate", "--refine-skate", float), ("refine_start", "--refine-start", str),
               ("refine_pace", "--refine-pace", float), ("refine_land", "--refine-land", int),
               ("avoid", "--avoid", int),
               ("avoid_horizon", "--avoid-horizon", int), ("avoid_margin", "--avoid-margin", float),
               ("avoid_samples", "--avoid-samples", int), ("sit_plan", "--sit-plan", int),
               ("sit_plan_samples", "--sit-plan-samples", int),
               ("sit_plan_getup", "--sit-plan-getup", int), ("sit_plan_approach", "--sit-plan-approach", float),
               ("route", "--route", float))
    for name, flag, kind in choices:
        # what the policy's card used; not with --physics (its own check names the task), nor the rest when off
        head = next(h for h, _, _ in choices if name == h or name.startswith(h + "_"))  # the switch it belongs to
        if getattr(req, name) is None and name in stored and not req.physics and (name == head or getattr(req, head)):
            setattr(req, name, kind(stored[name]))
            print(f"{flag} {getattr(req, name)} (the policy's stored evaluation setting; {flag} overrides)", flush=True)
    trained = tuple(env.reach_joint.joints) if env is not None and env.reach_joint is not None else ("pelvis",)
    refiner = _refiner(req, evaluator, spec.name, trained)
    avoider = _avoider(req, evaluator, spec.name)
    sitter = _sit_planner(req, spec.name)
    _check_route(req, evaluator, spec.name)
    if req.foot_lock_min_weight is None and "foot_lock_min_weight" in stored:  # what the policy's card used
        req.foot_lock_min_weight = float(stored["foot_lock_min_weight"])
        print(f"foot lock pins from contact weight {req.foot_lock_min_weight:g} (the policy's stored evaluation "
              "setting; --foot-lock-min-weight overrides)", flush=True)
    settings = _settings(req)
    if req.physics:
        return _evaluate_physics(req, spec, files, settings)
    entries = sum(len(evaluator.load_suite(file)) for file in files)  # every file checked before models load
    if req.paths is None:
        print(f"evaluating on {', '.join(f.stem for f in files)} (the {spec.name} suites using only the policy's "
              "prompts; --paths chooses others)", flush=True)
    req.policy = str(found)
    beside = Path.cwd() if is_packaged(req.policy) else Path(req.policy).resolve().parent
    out_dir = Path(req.out) if req.out else beside / f"eval-{Path(req.policy).stem}"
    check_writable(out_dir, "--out")
    model, policy, motion, policy_info, observe_next = _load(req, settings)
    if req.route is not None:  # over the training env's own (--route 0: off)
        settings.route = float(req.route) or None
    observe_next = evaluator.fit(policy, model, files, settings, observe_next)
    act = policy_fn(policy, settings.deterministic)
    sample = policy_fn(policy, False)  # the scene filter's draws (--avoid-samples) are the policy's own
    info = {"policy": policy_info, "motion": motion, "hardware": hardware()}
    extra_run: dict[str, Any] = {}
    if refiner is not None or avoider is not None or sitter is not None:
        info.update({"refine": asdict(refiner)} if refiner is not None else {},
                    **({"avoid": asdict(avoider)} if avoider is not None else {}),
                    **({"sit_plan": asdict(sitter)} if sitter is not None else {}))

        def wrap(env: Any, policy_act: Callable) -> Callable:
            """The policy, then the refiner or the sit plan, then the scene filter (the last word is the filter's)."""
            out = refining(env, policy_act, refiner) if refiner is not None else policy_act
            out = sit_planning(env, out, sitter) if sitter is not None else out
            return avoiding(env, out, avoider, sample) if avoider is not None else out

        extra_run["wrap"] = wrap
    # an evaluator written before ``after_entry`` existed still runs, without the bar and the reports in between
    accepts = inspect.signature(evaluator.run).parameters
    stepwise = "after_entry" in accepts
    draw = 0 if req.render == "none" else req.render_episodes
    if draw and req.render != "gif" and "render_format" not in accepts:
        raise ConfigError(f"--render {req.render}: the {spec.name} task's evaluator draws GIFs only (--render gif)")
    extra = {"render_format": req.render} if draw and "render_format" in accepts else {}
    with locked_output(out_dir) as output:  # one eval per folder; a failure before the first report removes it
        # the bar starts once the folder is ours: a refused eval prints its one line and nothing else
        bar = tqdm(total=entries * settings.episodes, unit="episode", desc="eval", dynamic_ncols=True,
                   disable=not (req.progress and stepwise))

        def after_entry(done: Any) -> None:
            """After every path: the report of the paths so far (atomic), then the bar."""
            evaluator.report(done, settings, out_dir, **info)
            output.keep()  # an interrupted or failed eval leaves the report of the paths it finished
            bar.update(settings.episodes)

        try:
            results = evaluator.run(act, model, files, settings, observe_next=observe_next, out_dir=out_dir,
                                    render=draw, motions=req.motions,
                                    **({"after_entry": after_entry} if stepwise else {}), **extra, **extra_run)
        finally:
            bar.close()
        lines = evaluator.report(results, settings, out_dir, **info)
    if draw:
        lines.append(f"renders: {out_dir / 'renders'} (the first {draw} episode(s) of every path as "
                     f"{req.render.upper()} and BVH)")
    print("\n".join(lines))
    return 0


def _refiner(req: EvalRequest, evaluator: Any, task: str, policy_joints: tuple[str, ...] = ("pelvis",)
             ) -> RefineSettings | None:
    """``--refine``'s settings, checked; None when off. Only joint goals give the optimizer targets.

    ``policy_joints``: the joints the policy was trained on (``--refine-start auto`` starts from its action there).
    """
    if not req.refine:
        return None
    if getattr(evaluator, "suite_kind", None) != "joint_goals":
        raise ConfigError(f"--refine: only ReachJoint policies are refined (the optimizer lands joint goals); the "
                          f"policy's task is {task}; leave out --refine")
    if req.physics:
        raise ConfigError("--refine: not with --physics (the refiner predicts the kinematic step)")
    settings = RefineSettings.of(req.refine, req.refine_horizon, req.refine_start, req.refine_skate, req.refine_pace,
                                 req.refine_land, policy_joints)
    try:
        settings.check()
    except LatentRLError as exc:  # the flags' names, not the settings'
        flag = str(exc).replace("refine steps:", "--refine:").replace("refine horizon:", "--refine-horizon:") \
            .replace("refine skate:", "--refine-skate:").replace("refine start:", "--refine-start:") \
            .replace("refine pace:", "--refine-pace:").replace("refine land:", "--refine-land:")
        raise ConfigError(flag) from None
    return settings


def _check_route(req: EvalRequest, evaluator: Any, task: str) -> None:
    """``--route``'s clearance in range, for tasks with somewhere on the floor to go (reach, path, timed, joystick)."""
    if not req.route:
        return
    if getattr(evaluator, "suite_kind", None) not in ("paths", "timed", "joystick"):
        raise ConfigError(f"--route: the {task} task's goal is not a place on the floor to plan a route to (reach, "
                          "path, timed and joystick policies take one); leave out --route")
    if req.physics:
        raise ConfigError("--route: not with --physics")
    if not 0 < req.route <= 2:
        raise ConfigError(f"--route: expected the route's clearance in metres, in (0, 2], got {req.route}")


def _avoider(req: EvalRequest, evaluator: Any, task: str) -> AvoidSettings | None:
    """``--avoid``'s settings, checked; None when off. Only evaluations among objects have something to avoid."""
    if not req.avoid:
        return None
    if getattr(evaluator, "suite_kind", None) not in SCENE_SUITES:
        raise ConfigError(f"--avoid: the {task} task's evaluation is not filtered (the filter runs where --scene "
                          "does: reach, path, timed, joystick and ReachJoint policies); leave out --avoid")
    if req.physics:
        raise ConfigError("--avoid: not with --physics (the filter predicts the kinematic step)")
    settings = AvoidSettings.of(req.avoid, req.avoid_horizon, req.avoid_margin, req.avoid_samples)
    try:
        settings.check()
    except LatentRLError as exc:  # the flags' names, not the settings'
        raise ConfigError(str(exc).replace("avoid steps:", "--avoid:").replace("avoid horizon:", "--avoid-horizon:")
                          .replace("avoid margin:", "--avoid-margin:")
                          .replace("avoid samples:", "--avoid-samples:")) from None
    if settings.samples and req.refine:
        raise ConfigError("--avoid-samples: not with --refine (the draws would drop the refinement); "
                          "leave out one of them")
    return settings


def _sit_planner(req: EvalRequest, task: str) -> SitPlanSettings | None:
    """``--sit-plan``'s settings, checked; None when off. Only the sit task has a sit to plan."""
    if not req.sit_plan and not req.sit_plan_samples:
        return None
    if task != "sit":
        raise ConfigError(f"--sit-plan: only sit policies plan their sits; the policy's task is {task}; leave out "
                          "--sit-plan")
    settings = SitPlanSettings.of(req.sit_plan or 0, req.sit_plan_samples, req.sit_plan_getup, req.sit_plan_approach)
    try:
        settings.check()
    except LatentRLError as exc:  # the flags' names, not the settings'
        raise ConfigError(str(exc).replace("sit plan steps:", "--sit-plan:")
                          .replace("sit plan samples:", "--sit-plan-samples:")
                          .replace("sit plan getup primitives:", "--sit-plan-getup:")
                          .replace("sit plan approach:", "--sit-plan-approach:")) from None
    return settings


PHYSICS_TASKS = ("reach", "path")
"""Tasks whose policies ``--physics`` runs (judged on waypoint paths)."""


def _evaluate_physics(req: EvalRequest, spec: Any, files: list[Path], settings: EvalSettings) -> int:
    """``latentrl eval --physics``: each path's episodes with physics in the loop and kinematically, same seeds."""
    import json
    import time

    from latentrl.physics import require_mujoco

    if spec.name not in PHYSICS_TASKS:
        raise ConfigError(f"--physics: runs reach or path policies, this policy's task is '{spec.name}'")
    if req.scene is not None or settings.scene is not None:
        raise ConfigError("--physics: the humanoid walks on the flat floor; evaluate without a scene")
    from latentrl.evaluation.runner import load_suites, path_seed

    suites = load_suites(files)
    for file, suite in suites:  # a suite whose paths name their scene (maze, stairs) is not flat either
        if any(p.scene is not None for p in suite):
            raise ConfigError(f"--physics: {file.stem}'s paths run in a scene; the humanoid walks on the flat floor")
    require_mujoco()
    from latentrl.evaluation.physics_episodes import run_episode, summarize
    from latentrl.motion.canonical import features_to_world
    from latentrl.physics.humanoid import build_humanoid
    from latentrl.physics.reference import fit_height
    from latentrl.physics.tracker import ASSIST_HZ

    req.policy = str(policy_file(req.policy))
    beside = Path.cwd() if is_packaged(req.policy) else Path(req.policy).resolve().parent
    out_dir = Path(req.out) if req.out else beside / f"eval-{Path(req.policy).stem}-physics"
    check_writable(out_dir, "--out")
    model, policy, motion, policy_info, observe_next = _load(req, settings)
    observe_next = spec.evaluator.fit(policy, model, files, settings, observe_next)
    act = policy_fn(policy, settings.deterministic)
    seed = model.initial_state(1, torch.Generator(device=settings.device).manual_seed(0))
    seed_world = features_to_world(seed.history, seed.world, model.pelvis_delta)[0]
    humanoid = build_humanoid(fit_height(seed_world[:, 144:210].reshape(-1, 22, 3).cpu().double().numpy()))
    began = time.perf_counter()
    paths = []
    with locked_output(out_dir) as output:
        for file, suite in suites:
            for index, path in enumerate(suite):
                seeds = [path_seed(settings.seed, file.stem, index) + e for e in range(settings.episodes)]
                kin = [run_episode(act, model, path, settings, s, observe_next) for s in seeds]
                phys = [run_episode(act, model, path, settings, s, observe_next, humanoid, ASSIST_HZ) for s in seeds]
                paths.append({"suite": file.stem, "path_index": index, "kinematic": summarize(kin),
                              "physics": summarize(phys), "episodes": {"kinematic": kin, "physics": phys}})
                report = {"format": "latentrl.eval.physics/1", "command": " ".join(["latentrl", *req.argv(),
                                                                                    "--physics"]),
                          "date": time.strftime("%Y-%m-%d", time.gmtime()), "batch": 1,
                          "humanoid": {"height_m": humanoid.height, "mass_kg": round(humanoid.mass, 3)},
                          "assist_hz": ASSIST_HZ, "policy": policy_info, "motion": motion, "hardware": hardware(),
                          "wall_seconds": time.perf_counter() - began, "paths": paths}
                atomic_write_text(out_dir / "physics.json", json.dumps(report, indent=1))
                output.keep()
    for p in paths:
        for run in ("kinematic", "physics"):
            m = p[run]
            extra = (f", falls {m['falls_total']}, assist {m['assist_percent_body_weight']:.1f} % body weight"
                     if run == "physics" else "")
            print(f"{p['suite']} path {p['path_index']} {run}: success {m['success_rate']:.2f}, time "
                  f"{m['reach_time_s']:.2f} s, penetration {m['penetration_mm']:.3f} mm, floating "
                  f"{m['floating_mm']:.1f} mm, skating {m['skating_mm']:.3f} mm{extra}")
    print(f"wrote {out_dir / 'physics.json'}")
    return 0


def compare(req: CompareRequest) -> int:
    """``latentrl compare``: print (and optionally write) several reports side by side."""
    if req.out:
        check_output_file(req.out)
    table = compare_reports(req.reports)
    print(table, end="")
    if req.out:
        atomic_write_text(req.out, table)
        print(f"wrote {req.out}")
    return 0
