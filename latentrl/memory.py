"""Memory estimated before a big allocation, so that asking for too much is one line, not an out-of-memory crash.

Each estimate is a count times a per-unit figure measured on a CPU (docs/robustness.md, "Memory"), compared
with the memory the OS says is available now (``MemAvailable`` of ``/proc/meminfo``, else the physical RAM).
The figures are rough: they refuse what cannot fit, and a run they let through may still need more.
"""

from __future__ import annotations

import os

from latentrl.errors import ConfigError

TRANSITION_BYTES = 45 << 10
"""CPU training, per env step of one iteration (``env.num_envs * ppo.num_steps``): rollout storage, the envs'
state and the update. Measured: peak RSS 0.50 GiB at 64 envs and 3.25 GiB at 2,048 on configs/quick.yaml
(32 steps, one minibatch), 45 KiB per env step."""
SAMPLE_BYTES = 256 << 10
"""One sample of a sampler batch of DART's size (``bench rollout --batches``): 265 KB measured from batch 16
to 1,024."""
ENV_BYTES = 464 << 10
"""One env of a batched env of DART's size (``bench env --num-envs``, ``eval --episodes``): 476 KB measured
with ``bench env`` (the batched env and the per-env loop) from 16 to 512 envs."""
EXPORT_BYTES = 416 << 10
"""One character of ``export onnx --batch`` (trace, check and one onnxruntime run): 426 KB measured from batch
1 to 1,024."""
PARAMETER_BYTES = 16
"""One policy parameter while training: the weight, its gradient and Adam's two moments, float32."""
PROCESS_BYTES = 400 << 20
"""One training process before its envs: Python, torch and the motion model (0.42 GB in the same measurement)."""


def available_bytes() -> int | None:
    """Bytes of memory available now (``MemAvailable``), else this machine's RAM, else None (unknown)."""
    try:
        with open("/proc/meminfo", encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return physical_memory()


def physical_memory() -> int | None:
    """Bytes of RAM of this machine, or None where the OS does not say."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        return None


def gib(n: float) -> str:
    """``n`` bytes as GiB with one decimal (``0.5 GiB``)."""
    return f"{n / 2**30:,.1f} GiB"


def require_memory(need: float, flag: str, what: str, hint: str) -> None:
    """Raise one :class:`ConfigError` line naming ``flag`` when ``need`` bytes exceed the available memory."""
    have = available_bytes()
    if have is not None and need > have:
        raise ConfigError(f"{flag}: {what} needs about {gib(need)} of memory; this machine has {gib(have)} "
                          f"available; {hint}")


def policy_parameters(architecture: str, latent_dim: int, n_blocks: int, mlp_hidden: list[int]) -> int:
    """Rough parameter count of an actor-critic (the hidden layers; the input and output layers are left out)."""
    if architecture == "mlp":
        widths = list(mlp_hidden)
        return 2 * sum(a * b for a, b in zip(widths[:-1], widths[1:]))
    return latent_dim * latent_dim * (4 * n_blocks + 4)  # two Linear layers a block, actor and critic, + embeddings


def training_bytes(num_envs: int, num_steps: int, parameters: int) -> int:
    """Memory of one CPU training process, in bytes.

    :data:`PROCESS_BYTES`, :data:`TRANSITION_BYTES` per env step of an iteration and :data:`PARAMETER_BYTES` per
    policy parameter.
    """
    return PROCESS_BYTES + num_envs * num_steps * TRANSITION_BYTES + parameters * PARAMETER_BYTES
