"""Fixed opponents for the single-agent views: a seeded mixed strategy over discrete actions."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np


class FixedMix:
    """Plays action ``i`` with probability ``probs[i]``, independently every step.

    Has stable-baselines3's ``predict`` signature, so it can be the opponent of
    :class:`~fdia_env.envs.single_agent.SingleAgentEnv`; the view reseeds it on ``reset(seed)``
    so that seeded episodes are reproducible. ``deterministic`` is ignored: a mixed strategy is
    played by sampling.

    Args:
        probs: Probabilities over ``Discrete(len(probs))``; non-negative, summing to 1.
        seed: Seed of its own generator.
    """

    def __init__(self, probs: Sequence[float] | np.ndarray, seed: int | None = None) -> None:
        p = np.asarray(probs, dtype=np.float64)
        if p.ndim != 1 or p.size == 0 or not np.all(np.isfinite(p)) or np.any(p < 0):
            raise ValueError(
                f"probs must be a non-empty vector of non-negative numbers, got {probs!r}"
            )
        if abs(p.sum() - 1.0) > 1e-9:
            raise ValueError(f"probs must sum to 1, got {p.sum():.12g}")
        self.probs = p / p.sum()
        self._cdf = np.cumsum(self.probs)
        self.rng = np.random.default_rng(seed)

    @classmethod
    def uniform(cls, n: int, seed: int | None = None) -> FixedMix:
        """Every action with probability 1/n."""
        return cls(np.full(n, 1.0 / n), seed)

    def reset(self, seed: int | None = None) -> None:
        """Reseed (when ``seed`` is given)."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = False,
    ) -> tuple[int, Any]:
        """A sampled action and ``state`` unchanged."""
        return int(
            min(np.searchsorted(self._cdf, self.rng.random(), side="right"), self.probs.size - 1)
        ), state
