"""Fixed opponents for the single-agent views: a seeded mixed strategy over discrete actions."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np


class FixedMix:
    """Plays action ``i`` with probability ``probs[i]``, independently every step.

    Has stable-baselines3's ``predict`` signature, so it can be the opponent of
    :class:`~fdia_env.envs.single_agent.SingleAgentEnv`; the view calls :meth:`reset` with a seed
    on a seeded ``reset``, so seeded episodes replay the same opponent draws.

    ``deterministic`` is ignored on purpose: a mixed strategy is an equilibrium only when it is
    sampled, and SB3's ``evaluate_policy`` passes ``deterministic=True`` by default, which would
    otherwise turn it into an exploitable pure strategy. :meth:`mode` gives the argmax action.

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
        self.probs.setflags(write=False)
        self.n_actions = self.probs.size
        self._cdf = np.cumsum(self.probs)
        self.rng = np.random.default_rng(seed)

    @classmethod
    def uniform(cls, n: int, seed: int | None = None) -> FixedMix:
        """Every action with probability 1/n."""
        return cls(np.full(n, 1.0 / n), seed)

    def reset(self, seed: int | None = None) -> None:
        """Restart the generator from ``seed`` (nothing happens without one)."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)

    def mode(self) -> int:
        """The most likely action (first on ties)."""
        return int(np.argmax(self.probs))

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = False,
    ) -> tuple[Any, Any]:
        """Return ``(action, state)``: a sampled action index and ``state`` unchanged.

        Args:
            observation: Unbatched (d,) or batched (B, d) observation, a dict observation (its
                ``"observation"`` entry is used) or None; only its batch size matters.
            state: Returned as given (the policy has no memory).
            episode_start: Ignored.
            deterministic: Ignored; see the class docstring.

        Returns:
            An ``np.int64`` action for one observation, a (B,) int64 array for a batch.
        """
        obs = observation["observation"] if isinstance(observation, Mapping) else observation
        obs = np.asarray(obs) if obs is not None else np.zeros(0)
        batch = obs.shape[0] if obs.ndim >= 2 else None
        u = self.rng.random(1 if batch is None else batch)
        actions = np.minimum(np.searchsorted(self._cdf, u, side="right"), self.n_actions - 1)
        actions = actions.astype(np.int64)
        if batch is None:
            return np.int64(actions[0]), state
        return actions, state
