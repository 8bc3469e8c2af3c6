"""Fixed opponents for the single-agent views: a seeded mixed strategy over discrete actions."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from fdia_env.envs.policy import SampledPolicyBase, batch_size


class FixedMix(SampledPolicyBase):
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
        super().__init__(seed)

    @classmethod
    def uniform(cls, n: int, seed: int | None = None) -> FixedMix:
        """Every action with probability 1/n."""
        return cls(np.full(n, 1.0 / n), seed)

    def mode(self) -> int:
        """The most likely action (first on ties)."""
        return int(np.argmax(self.probs))

    def act(self, observation: Any, deterministic: bool = False) -> Any:
        """A sampled action index; only the observation's batch size matters.

        Args:
            observation: Unbatched (d,) or batched (B, d) observation, a dict observation or
                None.
            deterministic: Ignored; see the class docstring.

        Returns:
            An ``np.int64`` action for one observation, a (B,) int64 array for a batch.
        """
        batch = batch_size(observation)
        u = self.rng.random(1 if batch is None else batch)
        actions = np.minimum(np.searchsorted(self._cdf, u, side="right"), self.n_actions - 1)
        actions = actions.astype(np.int64)
        return np.int64(actions[0]) if batch is None else actions
