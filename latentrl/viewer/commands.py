"""Bodies of ``latentrl view`` and ``latentrl play``, taking plain arguments (the CLI only parses flags).

Both check their input first (one-line errors, exit 2), then start a Viser server on ``host:port``,
print the URL, and serve until Ctrl-C, which stops the server and returns 0.
"""

from __future__ import annotations

from pathlib import Path

from latentrl.errors import CheckpointError, ConfigError

DEFAULT_HOST = "127.0.0.1"
DEFAULT_PORT = 8080
PLAY_TASKS = ("reach", "path", "joystick", "reach_joint")
"""Tasks ``latentrl play`` steers: reach and path policies toward clicked goals and waypoints (a path policy
that also observes the next waypoint is refused), joystick policies by the keyboard."""


def view_command(path: str | Path, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT,
                 record: str | Path | None = None, skeleton: bool = False) -> int:
    """Show a motion ``.npz``, an evaluation folder, a run's latest evaluation or a folder of motions.

    The character is a capsule body among the objects of the scene its motion file carries.
    ``record``: a .gif or .mp4 that gets every frame played, drawn when the server stops.
    ``skeleton``: draw the skeleton too from the start (a checkbox on the page switches it).
    """
    from latentrl.viewer.record import Recorder, check_record
    from latentrl.viewer.server import require_viser, serve_until_interrupted, start_server
    from latentrl.viewer.sources import open_source

    source = open_source(path)
    check_record(record)
    require_viser()
    server = start_server(host, port, label=f"latentrl view {Path(path).name}")
    from latentrl.viewer.playback import Player

    recorder = Recorder(record, "view") if record else None
    player = Player(server, source, recorder, skeleton=skeleton)
    player.start()
    code = serve_until_interrupted(server, "view", host, player.stop)
    player.thread.join(2)
    if recorder is not None:
        recorder.write()
    return code


def play_command(policy: str | Path, host: str = DEFAULT_HOST, port: int = DEFAULT_PORT, motion: str | None = None,
                 device: str | None = None, text: str | None = None, deterministic: bool = False, seed: int = 0,
                 allow_motion_mismatch: bool = False, record: str | Path | None = None, scene: str | None = None,
                 skeleton: bool = False, route: float | None = None) -> int:
    """Steer a trained policy live in the browser, and pick its text from a list.

    Clicks set a reach/path policy's goal and waypoints and a ReachJoint policy's timed joint goals
    (:mod:`latentrl.viewer.joint_play`); keys set a joystick policy's heading and speed; a ctrl-click (cmd-click)
    drops a box into the scene.

    ``policy`` is a file or a shipped policy's name (``reach_walk_default``). The text list is ``text``
    (if given), the policy's training texts, then every prompt the motion model's text table knows; the
    first is where the page starts. ``motion`` None: the model named in the policy's stored config.
    ``record``: a .gif or .mp4 that gets every frame shown, drawn when the server stops.
    ``scene``: a ``latentrl.scene/1`` file or a name in ``tasks/scenes`` to play in (default: the policy's
    training scene when it has a fixed one, else the bare floor). ``skeleton``: draw the skeleton too.
    ``route``: a reach, path or joystick policy heads along routes keeping this many metres from the objects (None:
    the policy's ``env.route``; 0: off).
    """
    import torch

    from latentrl.evaluation.trained import stored_task
    from latentrl.resources import policy_file
    from latentrl.viewer.server import check_port, require_viser, serve_until_interrupted, start_server

    policy = Path(policy_file(policy))
    if not policy.is_file():
        raise CheckpointError(f"{policy}: no such policy checkpoint (give a .pt written by latentrl train, "
                              "or a shipped policy's name)")
    task = stored_task(policy)
    if task not in PLAY_TASKS:
        raise CheckpointError(f"{policy}: play steers reach and path policies toward clicked goals, ReachJoint "
                              f"policies to clicked joint goals and joystick policies by the keyboard; this "
                              f"policy's task is '{task}' "
                              "(evaluate it with latentrl eval)")
    from latentrl.motion.text import prompt_problem
    from latentrl.viewer.record import Recorder, check_record

    if text is not None and prompt_problem(text):  # an empty --text would fall back to the default silently
        raise ConfigError(f"--text: {prompt_problem(text)}")
    check_record(record)
    if route is not None and not 0 <= route <= 2:
        raise ConfigError(f"--route: expected the route's clearance in metres, in [0, 2] (0: off), got {route}")
    if route and task not in ("reach", "path", "joystick"):
        raise ConfigError(f"--route: only reach, path and joystick policies walk to a place on the floor; this "
                          f"policy's task is '{task}'")
    world = play_scene(scene)
    require_viser()
    check_port(host, port)  # before the models load
    from latentrl.evaluation.trained import trained_motion
    from latentrl.motion.checkpoint import load_motion_model
    from latentrl.ppo import load_policy
    from latentrl.ppo.checkpoint import check_shapes
    from latentrl.preflight import check_device
    from latentrl.viewer.live import LiveController, play_env
    from latentrl.viewer.markup import plain

    device = device or ("cuda" if torch.cuda.is_available() else "cpu")
    check_device(device, "--device")
    motion = trained_motion(policy, motion)
    model = load_motion_model(motion, device=device)
    loaded = load_policy(policy, device, motion={"path": model.info.get("source"), "sha256": model.info.get("sha256")},
                         allow_motion_mismatch=allow_motion_mismatch)
    env = play_env(loaded.checkpoint, model, text, device, task, world, route)
    if task != "joystick" and loaded.policy.action_dim == env.single_action_space.shape[0] and \
            loaded.policy.obs_dim == env.single_observation_space.shape[0] + 4:
        raise CheckpointError(f"{policy}: this {task} policy also observes the next waypoint; play steers one "
                              "clicked goal (reach policies, path policies trained without observe_next)")
    check_shapes(loaded.checkpoint, policy, env.single_observation_space.shape[0], env.single_action_space.shape[0])
    server = start_server(host, port, label=f"latentrl play {policy.name}", command="play")
    how = {"joystick": "Arrows or WASD steer: up/W faster, down/S slower, left/A and right/D turn, space stops",
           "reach_joint": "Click on the floor to give the joint picked below a goal in the picked seconds, "
                          "shift-click to add one more"}.get(task, "Click on the floor to set the goal, shift-click "
                                                                   "to add waypoints")
    how += "; ctrl-click (cmd-click) drops a box"
    title = f"**latentrl play** {plain(policy)} on motion {plain(motion)}  \n{how}; pick the text below."
    recorder = Recorder(record, "play") if record else None
    common = dict(deterministic=deterministic, seed=seed, recorder=recorder, skeleton=skeleton)
    if task == "reach_joint":  # refined as the policy's card was (its stored eval.refine), switchable on the page
        from latentrl.evaluation.trained import stored_eval_choices
        from latentrl.optim.refine import RefineSettings
        from latentrl.viewer.joint_play import JointGoalController

        stored = stored_eval_choices(policy)
        refine = RefineSettings.of(int(stored.get("refine") or 0), stored.get("refine_horizon"),
                                   stored.get("refine_start"), stored.get("refine_skate"), stored.get("refine_pace"),
                                   stored.get("refine_land"))
        controller = JointGoalController(server, env, loaded.policy, title, env.texts[0], refinement=refine,
                                         **common)
    else:  # the scene filter as the policy's card used it (its stored eval.avoid), switchable on the page
        from latentrl.evaluation.trained import stored_eval_choices
        from latentrl.optim.avoid import AvoidSettings
        from latentrl.viewer.live import PLAY_SAMPLES

        stored = stored_eval_choices(policy)
        samples = stored.get("avoid_samples")
        avoid = AvoidSettings.of(int(stored.get("avoid") or 0), stored.get("avoid_horizon"), stored.get("avoid_margin"),
                                 PLAY_SAMPLES if samples is None else int(samples))
        controller = LiveController(server, env, loaded.policy, title, env.texts[0], avoid=avoid, **common)
    controller.start()
    code = serve_until_interrupted(server, "play", host, controller.stop)
    controller.thread.join(2)
    if recorder is not None:
        recorder.write()
    return code


def play_scene(value: str | None):
    """The :class:`~latentrl.scenes.Scene` of ``play --scene`` (None without one); one-line error for a bad one.

    A file path or a name in ``tasks/scenes``, read by the scene file reader (every field checked).
    """
    if value is None:
        return None
    from latentrl.envs.scene import resolve_scene
    from latentrl.errors import LatentRLError
    from latentrl.scenes.scene import Scene

    if value == "random_obstacles":
        raise ConfigError("--scene: play takes a scene file (random obstacles are drawn per episode by eval and "
                          "train)")
    try:
        scene = resolve_scene(value)
    except LatentRLError as exc:
        raise ConfigError(f"--scene: {str(exc).removeprefix('scene: ')}") from None
    if not isinstance(scene, Scene):
        raise ConfigError(f"--scene: expected a latentrl.scene/1 file, got {value!r:.80}")
    return scene
