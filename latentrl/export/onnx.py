"""One controller step as one ONNX graph: policy mean, guided DDIM sampler, VAE decode and world update.

``latentrl export onnx POLICY --out controller.onnx`` writes what an env step plus a deterministic
policy call compute, for a fixed batch B, so that a game engine (onnxruntime, Unreal NNE, Unity
Sentis) can drive a character with it. The contract (float32; names are the graph's):

========================  ==============  ===================================================
input                     shape           meaning
========================  ==============  ===================================================
history                   (B, 2, 276)     canonical, unnormalized history (the motion state)
world_rotation            (B, 3, 3)       canonical-to-world rotation: ``p_world = R p + t``
world_translation         (B, 3)          canonical-to-world translation, metres
airborne                  (B,)            1 where the last step left the body in the air (the floor snap's flag), else 0
goal                      (B, 3)          reach, path, timed: goal or current waypoint, world metres, z up (z unused)
time_left                 (B,)            timed: seconds until the current waypoint's arrival time (negative
                                          when late; the graph clips it to +-``time_left_clip``); reach_joint:
                                          seconds until the joint goal's time
joint_target              (B, 3)          reach_joint: the goal joint's target, world metres, z up (z unused when
                                          planar)
goal_joint                (B,)            reach_joint: the goal joint's index in ``latentrl.settings.joints``
                                          (pelvis, left_foot, right_foot, left_hand, right_hand, head)
goal_planar               (B,)            reach_joint: 1 where only the target's xy counts (feet), else 0
next_goal                 (B, 3)          only for path/timed policies trained with observe_next (at the last
                                          waypoint: as ``latentrl.settings.next_at_last`` says)
command_heading_deg       (B,)            joystick: commanded world heading, degrees counter-clockwise from +y
command_speed             (B,)            joystick: commanded speed, m/s
scene_rays                (B, 16)         only for policies that observe a scene (``env.scene``, not blind by
                                          ``env.observe_scene: false``): distances to
                                          the objects along the 16 rays of ``ray_origin``/``ray_directions``,
                                          metres, clipped at 4 (the engine casts them in its own world)
text_embedding            (B, E)          only when no prompt was baked in (``--text``)
========================  ==============  ===================================================

========================  ==============  ===================================================
output                    shape           meaning
========================  ==============  ===================================================
action                    (B, D)          the policy's mean, clamped to the env's action bound:
                                          the latent noise the sampler started from
joints_world              (B, 8, 22, 3)   the 8 new frames, SMPL-22 joints, world metres, z up, 30 fps
next_history              (B, 2, 276)     feed back as ``history``
next_world_rotation       (B, 3, 3)       feed back as ``world_rotation``
next_world_translation    (B, 3)          feed back as ``world_translation``
next_airborne             (B,)            feed back as ``airborne``
next_ray_origin           (B, 2)          scene policies: where the next call's rays start (the pelvis), world xy
next_ray_directions       (B, 16, 2)      scene policies: their unit world xy directions, right to left over the
                                          front half-plane
========================  ==============  ===================================================

Inside the graph: the env's observation (the task's goal fields, built by the env's own functions:
:func:`~latentrl.envs.goal.goal_features`, :func:`~latentrl.envs.timed.timed_observation`,
:func:`~latentrl.envs.joystick.command_observation`; then text, history, floor height) ->
the policy's mean -> :meth:`latentrl.motion.MotionModel.rollout_step` (10 DDIM steps with
classifier-free guidance unrolled, the scale and the step indices as constants, then the VAE
decode and the re-canonicalization). The rollout's floor snap is part of ``rollout_step`` and so of the graph;
:meth:`ControllerStep.post_step` is where any further world-space correction would go. Initial states (the model's seed
histories, identity rotation, the translation that puts the lowest joint on the floor), the
prompt embeddings of the policy's training texts and this contract are stored as JSON in the
file's metadata (``latentrl.*`` keys). The rest of an env step (goal reached? next waypoint?) is
the caller's job. docs/export.md shows a loop in Python.

The graph is traced with torch's TorchScript-based exporter (``dynamo=False``): on torch 2.13 it
exports the default model in seconds, while the torch.export-based exporter needs about three
minutes (and onnxscript), and its handling of the sampler's inference mode needs ``no_grad``.
"""

from __future__ import annotations

import io
import json
import sys
import time
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import torch
from torch import nn

from latentrl.constants import OBS_GOAL_ANGLE_CLIP_DEG, OBS_GOAL_DIST_CLIP_M
from latentrl.envs.config import observes_scene, stored_env_config
from latentrl.envs.goal import goal_features
from latentrl.envs.joystick import command_observation, world_angle
from latentrl.envs.observation import observe
from latentrl.envs.reach_joint import JOINTS, TIME_LEFT_CLIP_S, joint_goal_observation
from latentrl.envs.scene import NUM_RAYS, RAY_RANGE_M, ray_fan
from latentrl.envs.settings import StepSettings
from latentrl.envs.timed import timed_observation
from latentrl.errors import CheckpointError, ConfigError, TextError
from latentrl.motion.canonical import WorldTransform
from latentrl.motion.representation import FEATURE_DIM, FUTURE_LENGTH, HISTORY_LENGTH, joints_of
from latentrl.motion.rollout import MotionModel, RolloutState, StepResult
from latentrl.motion.skeleton import JOINT_NAMES, NUM_JOINTS

FORMAT = "latentrl.onnx-controller/2"  # 2: the airborne flag is part of the state
MIN_OPSET = 17
DEFAULT_OPSET = 17
MAX_DIFF = 1e-3
"""``export_command`` fails when onnxruntime and torch differ by more than this after one step."""
EXPORT_TASKS = ("reach", "path", "joystick", "timed", "reach_joint")
"""Tasks whose observation the graph builds, each from its own inputs (:data:`TASK_INPUTS`)."""
TASK_INPUTS = {"reach": ("goal",), "path": ("goal",), "timed": ("goal", "time_left"),
               "joystick": ("command_heading_deg", "command_speed"),
               "reach_joint": ("joint_target", "goal_joint", "goal_planar", "time_left")}
"""Task -> the graph inputs its observation is built from (``next_goal`` follows for observe_next policies)."""
GOAL_SIZES = {"reach": (4,), "path": (4, 8), "timed": (5, 9), "joystick": (3,), "reach_joint": (12,)}
"""Task -> the goal-observation sizes its policies may have (the larger: observe_next)."""
EXTRA = "pip install 'latentrl[onnx]' (packages onnx and onnxruntime)"
OUTPUT_NAMES = ("action", "joints_world", "next_history", "next_world_rotation", "next_world_translation",
                "next_airborne")
RAY_OUTPUT_NAMES = ("next_ray_origin", "next_ray_directions")
"""Extra outputs of a scene policy's graph: where the engine casts the next call's ``scene_rays``."""
_MEANINGS = {
    "history": "canonical, unnormalized history (2 frames x 276 features); start from a seed in latentrl.seeds",
    "world_rotation": "canonical-to-world rotation, p_world = R p + t",
    "world_translation": "canonical-to-world translation, metres",
    "airborne": "1 where the previous step ended in the air (the floor snap lands it this step), else 0; start at 0",
    "goal": "goal or current waypoint, world metres, z up (z is not used)",
    "time_left": "seconds until the current waypoint's arrival time (timed) or the joint goal's time (reach_joint), "
                 "negative when late (clipped in the graph to +-latentrl.settings.time_left_clip)",
    "joint_target": "the goal joint's target, world metres, z up (z is not used when goal_planar is 1)",
    "goal_joint": "the goal joint: its index in latentrl.settings.joints (0 pelvis, 1 left_foot, 2 right_foot, "
                  "3 left_hand, 4 right_hand, 5 head; hands are the wrists)",
    "goal_planar": "1 where only the target's xy counts (feet on the floor), else 0",
    "command_heading_deg": "commanded world heading, degrees counter-clockwise from +y (the body's start facing)",
    "command_speed": "commanded speed, m/s",
    "next_goal": "the waypoint after the current one, world metres (FollowPath observe_next policies); at the last "
                 "waypoint what latentrl.settings.next_at_last says: the last again (repeat) or last + (last - "
                 "previous) (extend; previous = the episode's start pelvis on a one-waypoint path)",
    "text_embedding": "prompt embedding; rows of latentrl.texts",
    "scene_rays": "distances to the scene's objects along the rays of ray_origin/ray_directions (the previous call's "
                  "next_ray_*; at the start latentrl.seeds), metres, clipped at latentrl.settings.scene_rays.range_m",
    "next_ray_origin": "where the next call's scene_rays start: the pelvis, world xy metres",
    "next_ray_directions": "the next call's scene_rays directions, unit world xy vectors, right (-90 deg) to left "
                           "(+90 deg) of the body's forward axis",
    "action": "policy mean clamped to +-action_bound: the latent noise the sampler started from",
    "joints_world": "8 new frames of SMPL-22 joints (latentrl.joint_names), world metres, z up, 30 fps",
    "next_history": "feed back as history",
    "next_world_rotation": "feed back as world_rotation",
    "next_world_translation": "feed back as world_translation",
    "next_airborne": "feed back as airborne",
}


def _require_extra() -> tuple[Any, Any]:
    """(onnx, onnxruntime), or a one-line ConfigError naming the extra."""
    try:
        import onnx
        import onnxruntime
    except ImportError as exc:
        raise ConfigError(f"ONNX export needs the optional 'onnx' extra ({exc.name} is missing): {EXTRA}") from None
    return onnx, onnxruntime


# --------------------------------------------------------------------------- the traced step
class ControllerStep(nn.Module):
    """One controller step for a fixed batch: observation -> policy mean -> motion step (see the module docstring).

    Args:
        policy: a PPO ``ActorCritic`` (eval mode; its frozen observation normalizer is part of it).
        model: the motion model the policy was trained on.
        batch: B, fixed in the exported graph.
        settings: how the training env stepped the motion (guidance, action bound, foot lock; traced as constants).
            The graph runs in float32 whatever its ``amp`` (which the metadata records). None: the defaults.
        observe_next: the policy observes a second goal (path/timed ``observe_next``): adds ``next_goal``.
        task: whose observation the graph builds (:data:`TASK_INPUTS` names its inputs).
        time_left_clip: the timed env's clip of ``time_left``, seconds.
        text_embedding: (E,) or (1, E) prompt embedding baked in as a constant; ``None`` adds the
            ``text_embedding`` input.
        goal_angle_clip_deg, goal_dist_clip, floor_height: the env's observation settings.
        scene_rays: the policy observes a scene's rays: adds the ``scene_rays`` input and the ``next_ray_*`` outputs.
            The graph's floor snap keeps the flat floor, so the scene's objects must not carry the body (walls,
            obstacles: yes; stairs, seats: no).
    """

    def __init__(self, policy: nn.Module, model: MotionModel, batch: int = 1, *, settings: StepSettings | None = None,
                 observe_next: bool = False, text_embedding: torch.Tensor | None = None,
                 goal_angle_clip_deg: float = OBS_GOAL_ANGLE_CLIP_DEG, goal_dist_clip: float = OBS_GOAL_DIST_CLIP_M,
                 floor_height: float = 0.0, task: str = "reach", time_left_clip: float = 10.0,
                 scene_rays: bool = False):
        super().__init__()
        if int(batch) < 1:
            raise ConfigError(f"--batch must be >= 1, got {batch}")
        self.policy, self.model = policy.eval(), model.eval()
        self.batch = int(batch)
        self.settings = settings.step_settings() if settings is not None else StepSettings()
        self.settings.validate()
        self.guidance_scale, self.action_bound = self.settings.guidance_scale, self.settings.action_bound
        if task not in TASK_INPUTS:
            raise ConfigError(f"task must be one of {tuple(TASK_INPUTS)}, got '{task}'")
        self.task, self.time_left_clip = task, float(time_left_clip)
        if observe_next and task == "joystick":
            raise ConfigError("a joystick policy observes no next goal (observe_next)")
        self.observe_next = bool(observe_next)
        self.scene_rays = bool(scene_rays)
        self.goal_angle_clip_deg, self.goal_dist_clip = float(goal_angle_clip_deg), float(goal_dist_clip)
        self.floor_height = float(floor_height)
        self.foot_lock, self.foot_lock_min_weight = self.settings.foot_lock, self.settings.foot_lock_min_weight
        self.baked_text = text_embedding is not None
        if self.baked_text:
            emb = torch.as_tensor(text_embedding, dtype=torch.float32).reshape(1, model.text_dim)
            self.register_buffer("text", emb.expand(self.batch, -1).clone().to(model.device))
        else:
            self.text = None
        self.input_names: tuple[str, ...] = ("history", "world_rotation", "world_translation", "airborne",
                                             *TASK_INPUTS[task],
                                             *(("next_goal",) if self.observe_next else ()),
                                             *(("scene_rays",) if self.scene_rays else ()),
                                             *(() if self.baked_text else ("text_embedding",)))
        self.output_names = OUTPUT_NAMES + (RAY_OUTPUT_NAMES if self.scene_rays else ())
        self.eval()

    def train(self, mode: bool = True) -> ControllerStep:
        """Always evaluation mode (no dropout): ``torch.onnx.export`` restores the mode it found, recursively."""
        return super().train(False)

    def input_shapes(self) -> dict[str, tuple[int, ...]]:
        """Input name -> shape, for this batch and this policy (next goal, baked text)."""
        b = self.batch
        shapes = {"history": (b, HISTORY_LENGTH, FEATURE_DIM), "world_rotation": (b, 3, 3), "world_translation": (b, 3),
                  "airborne": (b,), "goal": (b, 3), "next_goal": (b, 3), "text_embedding": (b, self.model.text_dim),
                  "time_left": (b,), "command_heading_deg": (b,), "command_speed": (b,), "scene_rays": (b, NUM_RAYS),
                  "joint_target": (b, 3), "goal_joint": (b,), "goal_planar": (b,)}
        return {name: shapes[name] for name in self.input_names}

    def output_shapes(self) -> dict[str, tuple[int, ...]]:
        """Output name -> shape, for this batch."""
        b = self.batch
        shapes = {"action": (b, self.model.latent_dim), "joints_world": (b, FUTURE_LENGTH, NUM_JOINTS, 3),
                "next_history": (b, HISTORY_LENGTH, FEATURE_DIM), "next_world_rotation": (b, 3, 3),
                "next_world_translation": (b, 3), "next_airborne": (b,), "next_ray_origin": (b, 2),
                "next_ray_directions": (b, NUM_RAYS, 2)}
        return {name: shapes[name] for name in self.output_names}

    def observe(self, state: RolloutState, named: Mapping[str, torch.Tensor], text: torch.Tensor) -> torch.Tensor:
        """(B, obs_dim) the env's observation ``[task fields | text | history | scene]`` from the named inputs.

        Built by the envs' own functions (:func:`observe`, :func:`goal_features`, :func:`timed_observation`,
        :func:`command_observation`), so the graph sees what the env's policy saw.
        """
        history_world = state.world.apply(joints_of(state.history))

        def features(goal: torch.Tensor) -> torch.Tensor:
            return goal_features(history_world[:, -1], state.world.rotation, goal, self.goal_angle_clip_deg,
                                 self.goal_dist_clip)

        following = features(named["next_goal"]) if self.observe_next else None
        if self.task == "joystick":
            goal_obs = command_observation(history_world, world_angle(named["command_heading_deg"]),
                                           named["command_speed"])
        elif self.task == "reach_joint":
            slot = named["goal_joint"].round()[:, None]
            one_hot = (slot == torch.arange(len(JOINTS), device=slot.device, dtype=slot.dtype)).to(torch.float32)
            ids = torch.tensor(list(JOINTS.values()), device=slot.device)
            position = (one_hot[..., None] * history_world[:, -1, ids]).sum(dim=1)  # the goal joint, as a gather
            goal_obs = joint_goal_observation(position, state.world.rotation, named["joint_target"], one_hot,
                                              named["goal_planar"] > 0.5, named["time_left"], self.goal_dist_clip,
                                              self.time_left_clip)
        elif self.task == "timed":
            goal_obs = timed_observation(features(named["goal"]), named["time_left"], self.time_left_clip, following)
        else:
            goal_obs = features(named["goal"]) if following is None else torch.cat(
                (features(named["goal"]), following), dim=1)
        rays = named["scene_rays"].clamp(0.0, RAY_RANGE_M) if self.scene_rays else None
        return observe(state.history, history_world, goal_obs, text, self.floor_height, rays)

    def post_step(self, step: StepResult) -> StepResult:
        """World-space correction after the motion step; the identity, so the graph is exactly ``rollout_step``.

        A post-step returns ``step._replace(joints_world=..., state=RolloutState(history,
        WorldTransform(rotation, translation)))`` computed with tensor operations only (``torch.where``,
        no Python branches on values), so that it traces into the graph (the floor snap already runs
        inside ``rollout_step``).
        """
        return step

    def forward(self, *inputs: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """Tensors in the order of :attr:`input_names` -> tensors in the order of :attr:`output_names`."""
        named = dict(zip(self.input_names, inputs))
        state = RolloutState(named["history"], WorldTransform(named["world_rotation"], named["world_translation"]),
                             named["airborne"] > 0.5)
        text = self.text if self.baked_text else named["text_embedding"]
        action = self.policy(self.observe(state, named, text)).mean.clamp(-self.action_bound, self.action_bound)
        noise = action.reshape(self.batch, *self.model.latent_shape)
        step = self.model.rollout_step(state, text, noise, self.guidance_scale, foot_lock=self.foot_lock,
                                       lock_min_weight=self.foot_lock_min_weight)
        step = self.post_step(step)
        nxt = step.state
        airborne = nxt.airborne_flags().to(torch.float32)
        out = (action, step.joints_world, nxt.history, nxt.world.rotation, nxt.world.translation, airborne)
        if self.scene_rays:
            out = (*out, *ray_fan(nxt.world.apply(joints_of(nxt.history))))
        return out

    def initial_state(self, seed_index: torch.Tensor | None = None) -> RolloutState:
        """Start states from the model's seed histories (row i gets seed ``i % K`` unless ``seed_index`` is given)."""
        if seed_index is None:
            seed_index = torch.arange(self.batch) % self.model.seed_history.shape[0]
        return self.model.initial_state(self.batch, seed_index=seed_index)

    def example_inputs(self, text_embedding: torch.Tensor | None = None) -> tuple[torch.Tensor, ...]:
        """Inputs for tracing and checks: seed states, goals 1.5-3 m ahead (+y), the given text (zeros if none)."""
        state = self.initial_state()
        rows = torch.arange(self.batch, dtype=torch.float32)
        goal = torch.stack((0.5 * torch.sin(rows), 1.5 + (rows % 3) * 0.75, torch.zeros_like(rows)), dim=-1)
        values = {"history": state.history, "world_rotation": state.world.rotation,
                  "world_translation": state.world.translation, "airborne": torch.zeros(self.batch), "goal": goal,
                  "next_goal": goal + torch.tensor([1.0, 1.0, 0.0]), "time_left": 2.0 + rows,
                  "command_heading_deg": 30.0 * rows - 15.0, "command_speed": torch.full_like(rows, 1.2),
                  "joint_target": goal + torch.tensor([0.0, 0.0, 0.9]), "goal_joint": rows % len(JOINTS),
                  "goal_planar": ((rows % len(JOINTS) == 1) | (rows % len(JOINTS) == 2)).float(),
                  "scene_rays": torch.linspace(0.5, RAY_RANGE_M, NUM_RAYS).expand(self.batch, -1).contiguous()}
        if not self.baked_text:
            emb = torch.zeros(1, self.model.text_dim) if text_embedding is None else text_embedding
            values["text_embedding"] = emb.reshape(-1, self.model.text_dim).expand(self.batch, -1).contiguous()
        return tuple(values[n].to(self.model.device) for n in self.input_names)


# --------------------------------------------------------------------------- building from a checkpoint
def load_controller(policy_path: str | Path, motion: str = "default", batch: int = 1, text: str | None = None,
                    allow_motion_mismatch: bool = False) -> tuple[ControllerStep, dict]:
    """A :class:`ControllerStep` for a PPO checkpoint (on CPU) and a dict describing where it came from.

    The env settings (guidance scale, action bound, task layout) come from the checkpoint's config,
    as ``latentrl eval`` builds its env. Returns ``(step, info)`` with ``info`` holding ``policy``
    and ``motion`` identities, ``trained_texts`` (the training env's prompts) and ``texts``: prompt ->
    embedding for those and ``text``.
    """
    from latentrl.motion.checkpoint import file_sha256, load_motion_model
    from latentrl.ppo import load_policy

    model = load_motion_model(motion)
    ident = {"source": model.info.get("source"), "sha256": model.info.get("sha256")}
    loaded = load_policy(policy_path, "cpu", motion={"path": ident["source"], "sha256": ident["sha256"]},
                         allow_motion_mismatch=allow_motion_mismatch)
    policy = loaded.policy
    check_finite_weights(policy, policy_path)
    if model.seed_history is None or model.pelvis_delta is None:
        raise CheckpointError(f"motion model {motion} has no seed history/pelvis_delta; a controller cannot start")
    env_cfg = (loaded.checkpoint.get("config") or {}).get("env") or {}
    task = str(env_cfg.get("task") or "path")
    if task not in EXPORT_TASKS:
        raise CheckpointError(f"{policy_path}: export onnx builds controllers of {', '.join(EXPORT_TASKS)} policies; "
                              f"this policy's task is '{task}', which it cannot export")
    scene_rays = observes_scene(env_cfg)
    if scene_rays and int(env_cfg.get("height_grid") or 0):
        raise CheckpointError(f"{policy_path}: export onnx takes scene policies that observe rays; this one also "
                              f"observes a height grid (env.height_grid {env_cfg.get('height_grid')}), which the "
                              "graph's inputs do not carry")
    goal_size = policy.obs_dim - model.text_dim - HISTORY_LENGTH * FEATURE_DIM - 1 - (NUM_RAYS if scene_rays else 0)
    if policy.action_dim != model.latent_dim or goal_size not in GOAL_SIZES[task]:
        raise CheckpointError(
            f"{policy_path}: the policy ({policy.obs_dim}-D observations, {policy.action_dim}-D actions) does not fit "
            f"motion model {motion} ({model.text_dim}-D text, {model.latent_dim}-D latent); export it with the "
            "motion model it was trained on (--motion)")
    try:
        stored = stored_env_config(loaded.checkpoint.get("config"))
    except ConfigError as exc:  # a stored value out of range (NaN guidance, ...): name the checkpoint
        raise CheckpointError(f"{policy_path}: stored {str(exc).removeprefix('policy checkpoint: ')}") from None
    trained = [str(t) for t in env_cfg.get("texts") or []]
    texts = {}
    for prompt in dict.fromkeys([*trained, *([text] if text else [])]):
        try:
            texts[prompt] = model.encode_text([prompt])[0]
        except TextError:  # a prompt the model cannot encode is left out of the table (``--text`` re-raises below)
            continue
    baked = model.encode_text([text]) if text else None
    settings = StepSettings.of(stored)
    try:
        settings.validate()
    except ConfigError as exc:  # name the checkpoint and the stored field
        raise CheckpointError(f"{policy_path}: stored env: {exc}") from None
    observe_next = goal_size == GOAL_SIZES[task][-1] and len(GOAL_SIZES[task]) == 2
    time_left_clip = float((env_cfg.get("timed") or {}).get("time_left_clip", 10.0)) if task == "timed" \
        else TIME_LEFT_CLIP_S
    step = ControllerStep(policy, model, batch, settings=settings, observe_next=observe_next, text_embedding=baked,
                          task=task, time_left_clip=time_left_clip, scene_rays=scene_rays)
    info = {"policy": {"file": Path(policy_path).name, "sha256": file_sha256(policy_path),
                       "iteration": loaded.checkpoint.get("iteration")},
            "motion": ident, "texts": texts, "text": text, "trained_texts": trained,
            "next_at_last": (stored.next_at_last if stored is not None else "repeat") if observe_next else None}
    return step, info


def check_finite_weights(policy: nn.Module, source: str | Path) -> None:
    """``CheckpointError`` naming the first parameter or buffer of ``policy`` that holds NaN or inf.

    Such a policy traces and exports, but every action it gives is NaN (or saturated by an inf): a
    diverged or damaged checkpoint, never a controller.
    """
    for name, tensor in policy.state_dict().items():
        if tensor.is_floating_point() and not bool(torch.isfinite(tensor).all()):
            bad = ~torch.isfinite(tensor)
            kinds = " and ".join(k for k, hit in (("NaN", tensor.isnan().any()), ("inf", tensor.isinf().any())) if hit)
            raise CheckpointError(f"{source}: policy weight '{name}' holds {int(bad.sum())} non-finite value(s) "
                                  f"({kinds}); a diverged or damaged policy cannot be exported (export an earlier "
                                  "checkpoint)")


# --------------------------------------------------------------------------- writing and running
def _json_array(values: torch.Tensor) -> dict:
    """{"shape", "data"}: a tensor as a flat list of float32-exact decimals (9 significant digits)."""
    flat = values.detach().cpu().float().reshape(-1).tolist()
    return {"shape": list(values.shape), "data": [float(f"{v:.9g}") for v in flat]}


def controller_metadata(step: ControllerStep, info: Mapping[str, Any] | None = None, opset: int = DEFAULT_OPSET
                        ) -> dict[str, str]:
    """The ``latentrl.*`` metadata entries of an exported controller (each value a JSON string)."""
    info = dict(info or {})
    k = step.model.seed_history.shape[0]
    seeds = step.model.initial_state(k, seed_index=torch.arange(k))
    in_shapes, out_shapes = step.input_shapes(), step.output_shapes()
    contract = {"inputs": [{"name": n, "shape": list(s), "meaning": _MEANINGS[n]} for n, s in in_shapes.items()],
                "outputs": [{"name": n, "shape": list(s), "meaning": _MEANINGS[n]} for n, s in out_shapes.items()]}
    settings = {"task": step.task, "inputs": list(TASK_INPUTS[step.task]), "batch": step.batch, "opset": opset,
                "fps": 30, "frames_per_step": FUTURE_LENGTH,
                "guidance_scale": step.guidance_scale, "sampler": "ddim",
                "diffusion_steps": step.model.diffusion.num_timesteps,
                "action_bound": step.action_bound, "goal_angle_clip_deg": step.goal_angle_clip_deg,
                "goal_dist_clip": step.goal_dist_clip, "floor_height": step.floor_height,
                "foot_lock": step.foot_lock, "foot_lock_min_weight": step.foot_lock_min_weight,
                "training_amp": step.settings.amp,
                "time_left_clip": step.time_left_clip if step.task in ("timed", "reach_joint") else None,
                "joints": list(JOINTS) if step.task == "reach_joint" else None,
                "observe_next": step.observe_next, "next_at_last": info.get("next_at_last"),
                "scene_rays": {"count": NUM_RAYS, "range_m": RAY_RANGE_M, "from_deg": -90.0, "to_deg": 90.0,
                               "height": "any (horizontal rays: every object at any height counts)"}
                if step.scene_rays else None,
                "text": info.get("text") if step.baked_text else None}
    meta = {
        "latentrl.format": FORMAT,
        "latentrl.contract": contract,
        "latentrl.settings": settings,
        "latentrl.joint_names": list(JOINT_NAMES),
        "latentrl.seeds": {"history": _json_array(seeds.history),
                           "world_rotation": "identity",
                           "world_translation": _json_array(seeds.world.translation),
                           **_seed_rays(step, seeds)},
        "latentrl.policy": info.get("policy"),
        "latentrl.motion": info.get("motion"),
    }
    if not step.baked_text:
        meta["latentrl.texts"] = {p: [float(f"{v:.9g}") for v in e.tolist()] for p, e in info.get("texts", {}).items()}
    return {key: json.dumps(value, separators=(",", ":")) for key, value in meta.items()}


def _seed_rays(step: ControllerStep, seeds: RolloutState) -> dict:
    """Scene policies: where each seed state's first ``scene_rays`` start and point (origins, directions)."""
    if not step.scene_rays:
        return {}
    origin, dirs = ray_fan(seeds.world.apply(joints_of(seeds.history)))
    return {"ray_origin": _json_array(origin), "ray_directions": _json_array(dirs)}


def export_onnx(step: ControllerStep, path: str | Path, example: Sequence[torch.Tensor] | None = None,
                opset: int = DEFAULT_OPSET, metadata: Mapping[str, str] | None = None) -> Path:
    """Trace ``step`` on ``example`` (default: :meth:`ControllerStep.example_inputs`), check it, write it atomically."""
    from latentrl.safe_io import atomic_write_bytes

    return atomic_write_bytes(path, controller_bytes(step, example, opset, metadata))


def controller_bytes(step: ControllerStep, example: Sequence[torch.Tensor] | None = None,
                     opset: int = DEFAULT_OPSET, metadata: Mapping[str, str] | None = None) -> bytes:
    """The checked ONNX model of ``step`` (traced on ``example``, with ``metadata``) as bytes, nothing written."""
    onnx, _ = _require_extra()
    example = tuple(example if example is not None else step.example_inputs())
    buffer = io.BytesIO()
    with torch.no_grad(), warnings.catch_warnings():
        # tracing notes about shape-derived constants: the batch is fixed by design
        warnings.simplefilter("ignore", torch.jit.TracerWarning)
        warnings.filterwarnings("ignore", message=".*legacy TorchScript-based ONNX export.*")
        warnings.filterwarnings("ignore", message="The feature will be removed", category=DeprecationWarning)
        torch.onnx.export(step, example, buffer, input_names=list(step.input_names),
                          output_names=list(step.output_names), opset_version=int(opset), dynamo=False,
                          do_constant_folding=True)
    proto = onnx.load_from_string(buffer.getvalue())
    proto.doc_string = ("latentrl controller step (policy mean + guided DDIM sampler + VAE decoder + "
                        "canonical-to-world update); contract in metadata 'latentrl.contract'")
    for key, value in (metadata or {}).items():
        entry = proto.metadata_props.add()
        entry.key, entry.value = key, value
    onnx.checker.check_model(proto)
    return proto.SerializeToString()


def onnx_session(path: str | Path | bytes, threads: int = 1):
    """An onnxruntime CPU session with ``threads`` intra-op threads, of a file or of a model's bytes."""
    _, ort = _require_extra()
    options = ort.SessionOptions()
    options.intra_op_num_threads = int(threads)
    options.inter_op_num_threads = 1
    model = path if isinstance(path, bytes) else str(path)
    return ort.InferenceSession(model, options, providers=["CPUExecutionProvider"])


def run_session(session, inputs: Sequence[torch.Tensor], names: Sequence[str]) -> list[torch.Tensor]:
    """One ``session.run`` on torch inputs named ``names``; torch outputs in the graph's order."""
    feeds = {n: t.detach().cpu().numpy() for n, t in zip(names, inputs)}
    return [torch.from_numpy(a) for a in session.run(None, feeds)]


def max_difference(step: ControllerStep, session, inputs: Sequence[torch.Tensor]) -> float:
    """Largest absolute difference between torch's and onnxruntime's outputs for one step."""
    with torch.no_grad():
        expected = step(*inputs)
    got = run_session(session, inputs, step.input_names)
    return max(float((e.cpu() - g).abs().max()) for e, g in zip(expected, got))


def export_command(policy: str | Path, out: str | Path, batch: int = 1, text: str | None = None,
                   opset: int = DEFAULT_OPSET, motion: str | None = None, allow_motion_mismatch: bool = False) -> int:
    """``latentrl export onnx``: build the controller, check it (``onnx.checker``, onnxruntime), write it, print a line.

    ``motion`` None: the motion model named in the policy's stored config. Every check runs on the
    model in memory, so a failed export leaves no file at ``out``: non-finite policy weights or
    stored settings, or outputs that are not finite, are refused (``CheckpointError``, exit 2); a
    difference between onnxruntime and torch above :data:`MAX_DIFF` returns 1.
    """
    from latentrl.safe_io import atomic_write_bytes

    _require_extra()
    from latentrl.preflight import check_output_file

    try:
        from torch.onnx._constants import ONNX_TORCHSCRIPT_EXPORTER_MAX_OPSET as max_opset
    except ImportError:  # pragma: no cover - older or newer torch
        max_opset = 20
    if not MIN_OPSET <= int(opset) <= max_opset:
        raise ConfigError(f"--opset must lie in [{MIN_OPSET}, {max_opset}], got {opset}")
    if int(batch) < 1:
        raise ConfigError(f"--batch must be >= 1, got {batch}")
    from latentrl.memory import EXPORT_BYTES, require_memory

    require_memory(int(batch) * EXPORT_BYTES, "--batch", f"exporting a controller for {int(batch):,} characters",
                   "lower --batch (an engine may call the graph several times per frame)")
    check_output_file(out)
    from latentrl.resources import policy_file

    policy = policy_file(policy)  # a file, or a shipped policy by name (reach_walk_default)
    if not Path(policy).is_file():
        raise CheckpointError(f"policy checkpoint not found: {policy}")
    from latentrl.evaluation.trained import stored_task, trained_motion

    task = stored_task(policy)
    if task not in EXPORT_TASKS:
        raise CheckpointError(f"{policy}: export onnx builds controllers of {', '.join(EXPORT_TASKS)} policies; "
                              f"this policy's task is '{task}', which it cannot export")

    step, info = load_controller(policy, trained_motion(policy, motion), batch, text, allow_motion_mismatch)
    example = step.example_inputs(next(iter(info["texts"].values()), None))
    with torch.no_grad():
        outputs = step(*example)
    broken = [name for name, value in zip(step.output_names, outputs) if not bool(torch.isfinite(value).all())]
    if broken:
        raise CheckpointError(f"{policy}: the controller's {', '.join(broken)} hold NaN or inf after one step from a "
                              "seed state; nothing exported")
    t0 = time.perf_counter()
    data = controller_bytes(step, example, opset, controller_metadata(step, info, opset))
    seconds = time.perf_counter() - t0
    diff = max_difference(step, onnx_session(data), example)
    if not diff <= MAX_DIFF:
        print(f"latentrl: error: onnxruntime differs from torch by {diff:.2e} (> {MAX_DIFF:g}) over one step; "
              f"nothing written to {out}", file=sys.stderr)
        return 1
    path = atomic_write_bytes(out, data)
    how = f"text '{text}' baked in" if text else "text_embedding input"
    trained = info["trained_texts"]
    note = ""
    if text and trained and text not in trained:
        note = f"; note: the policy was trained on {trained}, not '{text}'"
    print(f"wrote {path} ({len(data) / 2**20:.1f} MiB, batch {step.batch}, opset {opset}, {how}) "
          f"in {seconds:.1f} s; onnxruntime vs torch over one step: max |diff| {diff:.1e}{note}")
    return 0
