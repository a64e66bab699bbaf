"""The env's prompt table: every text an episode may use, encoded once, with what the step reads per text.

Rows are the unique prompts (the env's ``texts`` and those a task adds, such as a path file's); the
step indexes the embedding, floor scale and skill code tables by each env's text row. Episodes draw
their text from the env's own ``texts`` with ``text_weights``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from latentrl.config import require
from latentrl.motion.text import prompt_problem


class TextTable:
    """Prompts (K) -> (K, E) embeddings, (K,) floor-reward scales and skill codes, and the weighted draw.

    Args:
        motion: the env's motion prior (``encode_text``).
        rewards: the env's reward composer (``floor_scales``, ``skill_codes``).
        texts: prompts episodes draw from, in order.
        text_weights: their sampling weights (None: uniform).
        every_text: every prompt the env may use (``texts`` first); a task with its own texts adds them.
        device: where the tables live.
    """

    def __init__(self, motion, rewards, texts: Sequence[str], text_weights: Sequence[float] | None,
                 every_text: Sequence[str], device: torch.device):
        self.texts: tuple[str, ...] = tuple(dict.fromkeys(every_text))
        require(len(self.texts) > 0, "texts", "give at least one prompt")
        for text in self.texts:
            require(prompt_problem(text) is None, "texts", str(prompt_problem(text)))
        self.embeddings = motion.encode_text(list(self.texts)).to(device, torch.float32)
        """(K, E) text embeddings, one row per prompt."""
        self.floor_scale = rewards.floor_scales(self.texts).to(device)
        self.skill_code = rewards.skill_codes(self.texts).to(device)
        self._draw_from = torch.tensor([self.texts.index(t) for t in texts], device=device)
        if text_weights is None:
            self._weights = torch.ones(len(texts), device=device)
        else:
            w = torch.as_tensor(np.asarray(text_weights, dtype=np.float32), device=device)
            require(w.shape == (len(texts),), "text_weights",
                    f"needs one weight per text ({len(texts)}), got {w.shape}")
            require(bool(torch.isfinite(w).all() and (w >= 0).all() and w.sum() > 0), "text_weights",
                    f"must be finite, >= 0 and not all 0, got {w.tolist()}")
            self._weights = w

    @property
    def dim(self) -> int:
        """E, the size of one embedding (the observation's ``text`` group)."""
        return int(self.embeddings.shape[1])

    def sample(self, count: int, generator: torch.Generator) -> torch.Tensor:
        """(count,) rows of :attr:`texts`, drawn from the episode texts with their weights."""
        pick = torch.multinomial(self._weights, count, replacement=True, generator=generator)
        return self._draw_from[pick]
