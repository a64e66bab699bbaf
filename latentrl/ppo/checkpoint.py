"""PPO checkpoints: one atomic torch file per save, readable with ``weights_only=True``.

A checkpoint is a dict of tensors and plain containers::

    format, version          "latentrl.ppo/1", latentrl.__version__
    trainer                  "native" | "sb3"
    iteration, env_steps     iterations done, env steps done (transitions summed over envs)
    elapsed_s                training wall time so far
    policy_spec, policy      ActorCritic.spec() and state_dict() (normalizer statistics included)
    optimizer                Adam state_dict
    rng                      python, numpy, torch (+cuda) and, when the env has get_rng_state, env
    policy_sha256            sha256 of the policy weights (:func:`weights_sha256`), verified on load
    config, config_hash      the resolved run config (plain dict) and sha256 of its canonical JSON
    motion                   {"path", "sha256"} of the motion model the env used, or None
    extra                    trainer-specific plain data (SB3 counters)

Run layout: ``<run_dir>/checkpoints/iter_<N>.pt`` every ``checkpoint_every`` iterations (the newest
``keep_checkpoints`` kept) and ``<run_dir>/final.pt`` at the end. Every file is written to a
temporary sibling and renamed, so a kill leaves the previous checkpoint intact (and at most a
``.<name>.*.tmp`` file, which nothing reads and a resume deletes); a truncated or corrupt newest
file is skipped with a warning by :func:`load_latest`.
"""

from __future__ import annotations

import enum
import hashlib
import json
import random
import re
import warnings
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch

from latentrl.errors import CheckpointError
from latentrl.ppo.policy import ActorCritic
from latentrl.safe_io import load_torch, save_torch_atomic

FORMAT = "latentrl.ppo/1"
CHECKPOINT_DIR = "checkpoints"
FINAL = "final.pt"
TOTAL_STEPS = "ppo.total_steps"
"""The training budget: ``--resume RUN --total-steps N`` may raise it (see :func:`check_resumable`)."""
RESUME_MAY_DIFFER = ("ppo.device", "ppo.log_every", "ppo.checkpoint_every", "ppo.keep_checkpoints", "ppo.eval_every")
"""Dotted config keys that may change between a run and its ``--resume`` (they do not change the result)."""

_ITER_RE = re.compile(r"^iter_(\d+)\.pt$")


class LoadedCheckpoint(NamedTuple):
    """A checkpoint file and its loaded state, as found when resuming a run."""
    path: Path
    state: dict


class LoadedPolicy(NamedTuple):
    """A checkpoint's policy rebuilt for evaluation, with the metadata it was saved with."""
    policy: ActorCritic
    """In eval mode, on the requested device; its normalizer (if any) is frozen."""
    checkpoint: dict
    """The checkpoint's metadata (everything except the weights and optimizer)."""


# --------------------------------------------------------------------------- config identity
def plain_config(config: Any) -> dict:
    """A config dataclass or mapping as JSON-compatible nested dicts (tuples become lists)."""
    import dataclasses

    if dataclasses.is_dataclass(config):
        from latentrl.config import to_dict

        config = to_dict(config)
    return json.loads(json.dumps(config, default=_jsonable))


def _jsonable(value: Any) -> Any:
    import dataclasses

    if dataclasses.is_dataclass(value):
        from latentrl.config import to_dict

        return to_dict(value)
    if isinstance(value, Path):
        return str(value)
    if isinstance(value, enum.Enum):
        return value.value
    if isinstance(value, Mapping):
        return dict(value)
    if hasattr(value, "_asdict"):
        return value._asdict()
    raise TypeError(f"config value {value!r} of type {type(value).__name__} is not plain data")


def config_hash(config: Any) -> str:
    """sha256 of the canonical JSON of ``config``."""
    text = json.dumps(plain_config(config), sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def flatten(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """Nested dicts as {dotted key: leaf}."""
    out: dict[str, Any] = {}
    for key, value in tree.items():
        if isinstance(value, Mapping):
            out.update(flatten(value, f"{prefix}{key}."))
        else:
            out[f"{prefix}{key}"] = value
    return out


def config_differences(saved: Mapping, current: Mapping, ignore: Iterable[str] = RESUME_MAY_DIFFER) -> list[str]:
    """``key: saved -> current`` for every dotted key whose value differs, except ``ignore``."""
    a, b, skip = flatten(plain_config(saved)), flatten(plain_config(current)), set(ignore)
    keys = sorted((set(a) | set(b)) - skip)
    return [f"{k}: {a.get(k, '<absent>')!r} -> {b.get(k, '<absent>')!r}" for k in keys if a.get(k) != b.get(k)]


# --------------------------------------------------------------------------- RNG
def capture_rng(env: Any = None) -> dict:
    """States of python's, numpy's and torch's global generators (and the env's, if it exposes one)."""
    np_state = np.random.get_state(legacy=False)
    state = {
        "python": random.getstate(),
        "numpy": {**np_state, "state": {"key": torch.from_numpy(np_state["state"]["key"].astype(np.int64)),
                                        "pos": int(np_state["state"]["pos"])}},
        "torch": torch.get_rng_state(),
        "cuda": torch.cuda.get_rng_state_all() if torch.cuda.is_available() and torch.cuda.is_initialized() else [],
    }
    if env is not None and callable(getattr(env, "get_rng_state", None)):
        state["env"] = env.get_rng_state()
    return state


def restore_rng(state: Mapping[str, Any], env: Any = None) -> None:
    """Inverse of :func:`capture_rng`; CUDA states are restored only onto the same number of GPUs."""
    version, internal, gauss = state["python"]
    random.setstate((version, tuple(internal), gauss))
    np_state = dict(state["numpy"])
    np_state["state"] = {"key": state["numpy"]["state"]["key"].numpy().astype(np.uint32),
                         "pos": state["numpy"]["state"]["pos"]}
    np.random.set_state(np_state)
    torch.set_rng_state(state["torch"])
    cuda = state.get("cuda") or []
    if cuda and torch.cuda.is_available() and len(cuda) == torch.cuda.device_count():
        torch.cuda.set_rng_state_all(cuda)
    if "env" in state and env is not None and callable(getattr(env, "set_rng_state", None)):
        env.set_rng_state(state["env"])


# --------------------------------------------------------------------------- save
def make_checkpoint(*, trainer: str, iteration: int, env_steps: int, elapsed_s: float, policy: ActorCritic,
                    optimizer: torch.optim.Optimizer, config: Any, motion: Mapping[str, Any] | None,
                    env: Any = None, extra: Mapping[str, Any] | None = None) -> dict:
    """Assemble the checkpoint dict described in the module docstring."""
    from latentrl import __version__

    return {
        "format": FORMAT, "version": __version__, "trainer": trainer,
        "iteration": int(iteration), "env_steps": int(env_steps), "elapsed_s": float(elapsed_s),
        "policy_spec": policy.spec(), "policy": policy.state_dict(), "optimizer": optimizer.state_dict(),
        "policy_sha256": weights_sha256(policy.state_dict()),
        "rng": capture_rng(env), "config": plain_config(config), "config_hash": config_hash(config),
        "motion": dict(motion) if motion else None, "extra": dict(extra or {}),
    }


def weights_sha256(weights: Mapping[str, Any]) -> str:
    """sha256 over a state_dict's names, dtypes, shapes and bytes (in name order); device independent."""
    h = hashlib.sha256()
    for name in sorted(weights):
        t = weights[name]
        if not isinstance(t, torch.Tensor):
            h.update(f"{name}={t!r};".encode())
            continue
        t = t.detach().to("cpu").contiguous()
        h.update(f"{name}:{t.dtype}:{tuple(t.shape)};".encode())
        h.update(t.reshape(-1).view(torch.uint8).numpy().tobytes() if t.numel() else b"")
    return h.hexdigest()


def check_state(state: dict, path: Path) -> None:
    """The structure every reader relies on, checked once: one ``CheckpointError`` line naming the field."""
    from latentrl.config import from_dict
    from latentrl.errors import LatentRLError
    from latentrl.ppo.config import PolicyConfig

    def bad(field: str, expected: str, got: Any) -> CheckpointError:
        shown = repr(got) if not isinstance(got, (dict, list)) else type(got).__name__
        return CheckpointError(f"{path}: field '{field}': expected {expected}, got {shown[:80]}")

    spec = state.get("policy_spec")
    if not isinstance(spec, dict):
        raise bad("policy_spec", "a dict (ActorCritic.spec())", spec)
    for key in ("obs_dim", "action_dim"):
        value = spec.get(key)
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_SPEC_DIM:
            raise bad(f"policy_spec.{key}", f"an integer in [1, {MAX_SPEC_DIM}]", value)
    if not isinstance(spec.get("config"), dict):
        raise bad("policy_spec.config", "a dict of policy settings", spec.get("config"))
    if spec.get("layout") is not None and not isinstance(spec.get("layout"), dict):
        raise bad("policy_spec.layout", "a dict or None", spec.get("layout"))
    try:  # sizes are checked here, before any layer is allocated
        from_dict(PolicyConfig, spec["config"], f"{path}: policy_spec.config")
    except LatentRLError as exc:
        raise CheckpointError(str(exc)) from None
    weights = state.get("policy")
    if not isinstance(weights, dict) or not all(isinstance(v, torch.Tensor) for v in weights.values()):
        raise bad("policy", "a dict of tensors (a state_dict)", weights)
    if state.get("motion") is not None and not isinstance(state.get("motion"), dict):
        raise bad("motion", "a dict {path, sha256} or None", state.get("motion"))
    for key in ("iteration", "env_steps"):
        value = state.get(key, 0)
        if isinstance(value, bool) or not isinstance(value, int) or value < 0:
            raise bad(key, "an integer >= 0", value)
    if not isinstance(state.get("config", {}), dict):
        raise bad("config", "a dict", state.get("config"))
    recorded = state.get("policy_sha256")
    if recorded is not None and recorded != weights_sha256(weights):  # older checkpoints carry no hash
        raise CheckpointError(f"{path}: policy weights do not match their recorded sha256 {str(recorded)[:12]} "
                              f"(the file was changed or damaged after it was written)")


MAX_SPEC_DIM = 1_000_000
"""Observation and action sizes a policy_spec may name, at most."""


def iteration_path(run_dir: str | Path, iteration: int) -> Path:
    """Where a run keeps iteration ``iteration``'s checkpoint (``<run>/checkpoints/iter_N.pt``)."""
    return Path(run_dir) / CHECKPOINT_DIR / f"iter_{iteration}.pt"


def save_checkpoint(state: Mapping[str, Any], path: str | Path) -> Path:
    """Write atomically (temporary sibling, fsync, rename)."""
    return save_torch_atomic(dict(state), path)


def prune_checkpoints(run_dir: str | Path, keep: int, suffixes: tuple[str, ...] = ()) -> None:
    """Delete all but the newest ``keep`` ``iter_N.pt`` (0 keeps all), with same-stem ``suffixes`` siblings."""
    if keep <= 0:
        return
    for path in iteration_checkpoints(run_dir)[keep:]:
        for p in (path, *(path.with_suffix(s) for s in suffixes)):
            p.unlink(missing_ok=True)


def remove_temporaries(run_dir: str | Path) -> list[Path]:
    """Delete the ``.<name>.*.tmp`` files that writes killed mid-way left in a run (never read; safe on resume)."""
    removed = []
    for folder in (Path(run_dir), Path(run_dir) / CHECKPOINT_DIR):
        for path in folder.glob(".*.tmp") if folder.is_dir() else ():
            path.unlink(missing_ok=True)
            removed.append(path)
    return removed


# --------------------------------------------------------------------------- load
def iteration_checkpoints(run_dir: str | Path) -> list[Path]:
    """``checkpoints/iter_N.pt`` files, newest (largest N) first."""
    folder = Path(run_dir) / CHECKPOINT_DIR
    found = [(int(m.group(1)), p) for p in folder.glob("iter_*.pt") if (m := _ITER_RE.match(p.name))]
    return [p for _, p in sorted(found, reverse=True)]


def read_checkpoint(path: str | Path, map_location: str | torch.device = "cpu") -> dict:
    """Load and check the format; ``CheckpointError`` for unreadable, truncated or foreign files."""
    state = load_torch(path, map_location=map_location, what="PPO checkpoint")
    if not isinstance(state, dict) or state.get("format") != FORMAT:
        found = state.get("format") if isinstance(state, dict) else type(state).__name__
        raise CheckpointError(f"{path}: not a latentrl PPO checkpoint (format {found!r}, expected {FORMAT!r})")
    check_state(state, Path(path))
    return state


def load_latest(run_dir: str | Path, map_location: str | torch.device = "cpu") -> LoadedCheckpoint | None:
    """The newest readable checkpoint of a run (``final.pt``, then ``iter_N.pt`` by N), or None if there is none.

    An unreadable newer file (killed mid-copy by a foreign tool, disk error) is skipped with a warning.
    """
    candidates = [p for p in [Path(run_dir) / FINAL] if p.is_file()] + iteration_checkpoints(run_dir)
    for path in candidates:
        try:
            return LoadedCheckpoint(path, read_checkpoint(path, map_location))
        except CheckpointError as exc:
            warnings.warn(f"skipping unusable checkpoint: {exc}", stacklevel=2)
    return None


def check_motion(state: Mapping[str, Any], path: Path, motion: Mapping[str, Any] | None,
                 allow_motion_mismatch: bool) -> None:
    """Refuse a checkpoint trained on another motion model (by content hash) unless explicitly allowed."""
    saved = state.get("motion") or {}
    if not saved.get("sha256") or not motion or not motion.get("sha256") or allow_motion_mismatch:
        return
    if saved["sha256"] != motion["sha256"]:
        raise CheckpointError(
            f"{path}: policy was trained on motion model {saved.get('path')} (sha256 {saved['sha256'][:12]}) but the "
            f"env uses {motion.get('path')} (sha256 {motion['sha256'][:12]}); the latent action spaces differ. "
            "Pass allow_motion_mismatch=True (--allow-motion-mismatch) only if you know they are compatible")


def normalized_config(saved: Mapping[str, Any], current: Any) -> Any:
    """A run's saved config in today's layout, when ``current`` is a config dataclass.

    Renamed keys move as its class's ``ALIASES`` say (as for old YAML files) and keys added since
    take their defaults, so runs written by earlier versions still resume. A saved config that no
    longer loads is returned unchanged (its differences are then reported key by key).
    """
    import dataclasses

    from latentrl.errors import ConfigError

    if not dataclasses.is_dataclass(current) or not isinstance(saved, Mapping):
        return saved
    from latentrl.config import apply_aliases, from_dict

    cls = type(current)
    try:
        return from_dict(cls, apply_aliases(dict(saved), getattr(cls, "ALIASES", {})), "saved run config")
    except ConfigError:
        return saved


def check_resumable(state: Mapping[str, Any], path: Path, *, trainer: str, config: Any,
                    motion: Mapping[str, Any] | None, allow_motion_mismatch: bool = False,
                    may_differ: Iterable[str] = RESUME_MAY_DIFFER) -> int | None:
    """Refuse to resume with another trainer, another config or another motion model.

    ``ppo.total_steps`` may grow (``--total-steps N`` extends a run); returns the run's former
    budget when it does, else None. A smaller budget than the run's is refused.
    """
    if state.get("trainer") != trainer:
        raise CheckpointError(f"{path}: written by the '{state.get('trainer')}' trainer; resume it with "
                              f"--trainer {state.get('trainer')} (not '{trainer}')")
    saved = normalized_config(state["config"], config)
    diffs = config_differences(saved, config, (*may_differ, TOTAL_STEPS))
    if diffs:
        shown = "; ".join(diffs[:5]) + (f"; ... ({len(diffs)} in all)" if len(diffs) > 5 else "")
        raise CheckpointError(f"{path}: config differs from the run's: {shown}. Resume with the run's own "
                              "config.yaml, or start a new run")
    check_motion(state, path, motion, allow_motion_mismatch)
    before, after = flatten(plain_config(saved)).get(TOTAL_STEPS), flatten(plain_config(config)).get(TOTAL_STEPS)
    if before == after or before is None or after is None:
        return None
    if after < before:
        raise CheckpointError(f"{path}: {TOTAL_STEPS} {after} is below the run's budget {before}; "
                              "--total-steps can only extend a run")
    return int(before)


def check_shapes(state: Mapping[str, Any], path: Path, obs_dim: int, action_dim: int) -> None:
    """Refuse a checkpoint whose policy sizes differ from the env's, naming the file and both shapes."""
    spec = state["policy_spec"]
    if (spec["obs_dim"], spec["action_dim"]) != (obs_dim, action_dim):
        raise CheckpointError(f"{path}: policy expects observations of {spec['obs_dim']} and actions of "
                              f"{spec['action_dim']} dims; the env has {obs_dim} and {action_dim}")


def load_policy(path: str | Path, device: str | torch.device = "cpu", motion: Mapping[str, Any] | None = None,
                allow_motion_mismatch: bool = False) -> LoadedPolicy:
    """Rebuild the trained ``ActorCritic`` of a checkpoint for evaluation (eval mode, frozen normalizer)."""
    path = Path(path)
    state = read_checkpoint(path, map_location=device)
    check_motion(state, path, motion, allow_motion_mismatch)
    policy = ActorCritic.from_spec(state["policy_spec"]).to(device)
    try:
        policy.load_state_dict(state["policy"])
    except RuntimeError as exc:
        raise CheckpointError(f"{path}: policy weights do not match its policy_spec: {str(exc)[:300]}") from None
    meta = {k: v for k, v in state.items() if k not in ("policy", "optimizer", "rng")}
    return LoadedPolicy(policy.eval(), meta)


def export_policy(src: str | Path, dst: str | Path, half: bool = False) -> Path:
    """A release copy of a checkpoint, about a third of its size (a sixth with ``half``).

    Keeps policy, spec, config, counters and motion-model hash; drops the optimizer and RNG states.
    ``half`` stores the weight matrices in float16 (biases, the action std and the normalizer statistics stay
    float32; ``load_policy`` loads them into the float32 policy): the file halves, and the actions it gives
    are those of the rounded weights, so a half copy must be evaluated as itself. ``load_policy`` reads it;
    ``--resume`` cannot continue from it.
    """
    state = read_checkpoint(src)
    slim = {k: v for k, v in state.items() if k not in ("optimizer", "rng")}
    slim["extra"] = {**(state.get("extra") or {}), "exported_from": Path(src).name}
    if half:
        slim["policy"] = {k: v.half() if v.is_floating_point() and v.dim() == 2 else v
                          for k, v in state["policy"].items()}
        slim["policy_sha256"] = weights_sha256(slim["policy"])
        slim["extra"]["half_weights"] = True
    return save_torch_atomic(slim, dst)
