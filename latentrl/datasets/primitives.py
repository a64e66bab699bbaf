"""Motion-text sequences cut into DART primitives (H history + F future frames) with text labels.

Each sequence's 276-D features are computed once in world coordinates; a training batch takes
``num_primitives`` consecutive primitives from one window (for scheduled/rollout training), and
canonicalizes each primitive in the frame of its own first frame, as DART's dataset does.

Labels: a primitive's text is drawn uniformly from the segments that overlap its frames.
Class balance: windows are drawn with weights that give each text (roughly) the same share,
DART's importance sampling over action labels.

All datasets are re-expressed with one ``pelvis_delta`` (``transl = pelvis - pelvis_delta``): the
offset is a convention linking ``transl`` to the pelvis, and a model needs a single one.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import NamedTuple

import numpy as np
import torch

from latentrl.errors import DataError
from latentrl.motion.canonical import canonicalize
from latentrl.motion.representation import FEATURE_DIM, Normalizer, compute_features
from latentrl.motion.rotations import axis_angle_to_matrix
from latentrl.motion.text import normalize_prompt


class PrimitiveBatch(NamedTuple):
    """``num_primitives`` consecutive primitives per row."""

    motion: torch.Tensor  # (B, N, H + F, 276) unnormalized, each primitive in its own canonical frame
    text_index: torch.Tensor  # (B, N) int64 indices into ``PrimitiveDataset.texts``


class PrimitiveDataset:
    """Primitives from a list of sequences in the motion-text format (see ``docs/datasets.md``).

    Args:
        sequences: dicts with ``poses`` (T, 22, 3) axis-angle, ``joints`` (T, 22, 3) world metres,
            ``pelvis_delta`` (3,), and ``seg_start``/``seg_end``/``seg_text`` segments.
        history, future: primitive lengths (DART: 2 and 8).
        pelvis_delta: the common rest pelvis offset; defaults to the first sequence's.
        names: file names for error messages.
    """

    def __init__(
        self,
        sequences: Sequence[dict],
        history: int = 2,
        future: int = 8,
        pelvis_delta: np.ndarray | None = None,
        names: Sequence[str] | None = None,
    ):
        if not sequences:
            raise DataError("the dataset holds no sequences")
        self.history, self.future = history, future
        names = list(names) if names is not None else [f"sequence {i}" for i in range(len(sequences))]
        self.pelvis_delta = torch.as_tensor(
            pelvis_delta if pelvis_delta is not None else sequences[0]["pelvis_delta"], dtype=torch.float32
        )
        texts: dict[str, int] = {}
        self.features: list[torch.Tensor] = []  # per sequence (T - 1, 276), world frame
        self.frame_labels: list[list[list[int]]] = []  # per sequence, per frame: text indices
        for seq, name in zip(sequences, names):
            poses = torch.as_tensor(np.asarray(seq["poses"]), dtype=torch.float32)
            joints = torch.as_tensor(np.asarray(seq["joints"]), dtype=torch.float32)
            if len(poses) < history + future + 1:
                raise DataError(f"{name}: {len(poses)} frames, a primitive needs at least {history + future + 1}")
            transl = joints[:, 0] - self.pelvis_delta
            self.features.append(compute_features(transl, axis_angle_to_matrix(poses), joints))
            labels: list[list[int]] = [[] for _ in range(len(poses) - 1)]
            for start, end, text in zip(seq["seg_start"], seq["seg_end"], seq["seg_text"]):
                idx = texts.setdefault(normalize_prompt(str(text)), len(texts))
                for f in range(int(start), min(int(end), len(labels))):
                    labels[f].append(idx)
            self.frame_labels.append(labels)
        self.texts: list[str] = list(texts)
        self._index_windows(1)

    @classmethod
    def from_folder(cls, folder: str | Path, **kwargs) -> PrimitiveDataset:
        """Load every ``.npz`` sequence of a dataset folder."""
        from latentrl.datasets.motion_text import list_dataset, read_sequence

        files = list_dataset(folder)
        return cls([read_sequence(f, check_fk=False) for f in files], names=[f.name for f in files], **kwargs)

    # ------------------------------------------------------------------ windows and weights
    def _index_windows(self, num_primitives: int) -> None:
        """All (sequence, start) windows of ``num_primitives`` primitives, with balanced weights."""
        length = self.history + num_primitives * self.future
        seq_ids, starts, label_sets = [], [], []
        for i, feats in enumerate(self.features):
            for s in range(0, len(feats) - length + 1):
                seq_ids.append(i)
                starts.append(s)
                first = self.frame_labels[i][s : s + self.history + self.future]
                label_sets.append(sorted({t for frame in first for t in frame}))
        if not seq_ids:
            raise DataError(f"no sequence is long enough for {num_primitives} primitives ({length + 1} frames)")
        counts = np.zeros(len(self.texts))
        for labels in label_sets:
            counts[labels] += 1
        weights = np.array([np.mean(1.0 / counts[lab]) if lab else 0.0 for lab in label_sets])
        self._num_primitives = num_primitives
        self._seq_ids = torch.tensor(seq_ids)
        self._starts = torch.tensor(starts)
        self._weights = torch.as_tensor(weights / weights.sum(), dtype=torch.float64)

    @property
    def num_frames(self) -> int:
        """Frames over all sequences (each sequence's features span its frames minus one)."""
        return sum(len(f) + 1 for f in self.features)

    def text_frame_counts(self) -> dict[str, int]:
        """Frames carrying each text (a frame with two overlapping segments counts for both)."""
        counts = dict.fromkeys(self.texts, 0)
        for labels in self.frame_labels:
            for frame in labels:
                for t in frame:
                    counts[self.texts[t]] += 1
        return counts

    # ------------------------------------------------------------------ sampling
    def sample(
        self, batch_size: int, num_primitives: int = 1, generator: torch.Generator | None = None, balanced: bool = True
    ) -> PrimitiveBatch:
        """Draw ``batch_size`` windows of ``num_primitives`` consecutive primitives."""
        if num_primitives != self._num_primitives:
            self._index_windows(num_primitives)
        if balanced:
            pick = torch.multinomial(self._weights, batch_size, replacement=True, generator=generator)
        else:
            pick = torch.randint(len(self._starts), (batch_size,), generator=generator)
        return self._gather(self._seq_ids[pick], self._starts[pick], num_primitives, generator)

    def _gather(
        self, seq_ids: torch.Tensor, starts: torch.Tensor, num_primitives: int, generator: torch.Generator | None
    ) -> PrimitiveBatch:
        h, f = self.history, self.future
        windows = torch.stack(
            [self.features[i][s : s + h + num_primitives * f] for i, s in zip(seq_ids.tolist(), starts.tolist())]
        )  # (B, H + N F, 276)
        prims = torch.stack([windows[:, k * f : k * f + h + f] for k in range(num_primitives)], dim=1)
        b = prims.shape[0]
        flat, _, _ = canonicalize(prims.reshape(b * num_primitives, h + f, FEATURE_DIM), self.pelvis_delta)
        text_index = torch.empty(b, num_primitives, dtype=torch.int64)
        rand = torch.rand(b, num_primitives, generator=generator)
        for row, (i, s) in enumerate(zip(seq_ids.tolist(), starts.tolist())):
            for k in range(num_primitives):
                frames = self.frame_labels[i][s + k * f : s + k * f + h + f]
                labels = sorted({t for frame in frames for t in frame})
                text_index[row, k] = labels[int(rand[row, k] * len(labels))] if labels else -1
        return PrimitiveBatch(flat.reshape(b, num_primitives, h + f, FEATURE_DIM), text_index)

    def normalizer(self, num_samples: int = 20000, seed: int = 0) -> Normalizer:
        """Mean/std of canonical primitive frames (uniform over windows, not balanced)."""
        g = torch.Generator().manual_seed(seed)
        chunks = []
        remaining = num_samples
        while remaining > 0:
            n = min(remaining, 2048)
            chunks.append(self.sample(n, 1, generator=g, balanced=False).motion.reshape(-1, FEATURE_DIM))
            remaining -= n
        return Normalizer.from_data(torch.cat(chunks))

    def standing_seeds(self, text: str = "stand", max_seeds: int = 16, seed: int = 0) -> torch.Tensor:
        """(K, H, 276) canonical histories from frames labelled ``text`` (reset seeds for rollouts)."""
        key = normalize_prompt(text)
        candidates = [t for t in self.texts if t == key] or [t for t in self.texts if key in t]
        if not candidates:
            raise DataError(f"no segment labelled like '{text}' to take seed histories from; texts: {self.texts}")
        wanted = {self.texts.index(t) for t in candidates}
        pure, mixed = [], []
        for i, labels in enumerate(self.frame_labels):
            for s in range(0, len(labels) - self.history):
                window = [set(frame) for frame in labels[s : s + self.history]]
                if all(frame and frame <= wanted for frame in window):
                    pure.append((i, s))
                elif all(frame & wanted for frame in window):
                    mixed.append((i, s))
        picks = pure or mixed  # windows labelled only `text`, else windows that carry it among others
        if not picks:
            raise DataError(f"no {self.history}-frame window is labelled '{text}'")
        g = np.random.default_rng(seed)
        chosen = [picks[j] for j in sorted(g.choice(len(picks), size=min(max_seeds, len(picks)), replace=False))]
        hist = torch.stack([self.features[i][s : s + self.history] for i, s in chosen])
        canon, _, _ = canonicalize(hist, self.pelvis_delta)
        return canon
