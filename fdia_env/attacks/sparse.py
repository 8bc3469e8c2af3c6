"""Sparse attack: the attacker picks sensor-time pairs within a budget c (MATH.md §4)."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from fdia_env._validation import check_int
from fdia_env.attacks.base import AttackEffect, AttackModel
from fdia_env.episode import EpisodeSpec
from fdia_env.systems import LinearSystem

MAX_SENSORS = 16


def subset_to_mask(action: int, M: int) -> np.ndarray:
    """Bit ``i`` of ``action`` set means sensor ``i`` is attacked: (M,) bool."""
    return (int(action) >> np.arange(M)) & 1 == 1


def mask_to_subset(mask: np.ndarray) -> int:
    """Inverse of :func:`subset_to_mask`."""
    return int(np.dot(np.asarray(mask, dtype=np.int64), 1 << np.arange(len(mask))))


class SparseAttack(AttackModel):
    """Attack up to ``budget`` sensor-time pairs over the window.

    Action: ``Discrete(2**M)``; action ``a`` attacks the sensors whose bits are set in ``a``
    (bit 0 = sensor 1), so 0 is "no attack". The observation's ``action_mask`` marks the
    subsets no larger than the remaining budget.

    Over-budget rule: an action that selects more sensors than the budget left is trimmed to
    the lowest-numbered selected sensors that fit; no episode ever spends more than ``budget``.

    Features: the remaining budget as a fraction of ``budget`` (0 when ``budget`` is 0).
    """

    name = "sparse"

    def __init__(self, budget: int) -> None:
        self.budget = check_int("budget", budget, minimum=0)
        self.remaining = self.budget
        self.last_attacked: np.ndarray | None = None

    def bind(self, system: LinearSystem, spec: EpisodeSpec) -> None:
        """Build the action space for ``system`` and check the budget fits the window."""
        if system.M > MAX_SENSORS:
            raise ValueError(
                f"the sparse attack's subset action supports at most {MAX_SENSORS} sensors, "
                f"the system has {system.M}"
            )
        if self.budget > system.M * spec.horizon:
            raise ValueError(
                f"budget must be <= M * horizon = {system.M * spec.horizon} "
                f"(every sensor-time pair of the window), got {self.budget}"
            )
        self.M = system.M
        self.action_space = spaces.Discrete(2**system.M)
        self._sizes = np.array([bin(a).count("1") for a in range(2**system.M)])
        self.feature_low = np.zeros(1, dtype=np.float32)
        self.feature_high = np.ones(1, dtype=np.float32)

    def reset(self) -> None:
        """Restore the full budget."""
        self.remaining = self.budget
        self.last_attacked = np.zeros(self.M, dtype=bool)

    def features(self) -> np.ndarray:
        """Remaining budget fraction."""
        return np.array([self.remaining / self.budget if self.budget else 0.0])

    def action_mask(self) -> np.ndarray:
        """Subsets whose size fits the remaining budget."""
        return (self._sizes <= self.remaining).astype(np.int8)

    def apply(self, action: Any) -> AttackEffect:
        """Attack the chosen subset, trimmed to the remaining budget."""
        if not self.action_space.contains(_as_int(action)):
            raise ValueError(
                f"attacker action must be an integer in [0, {self.action_space.n}), got {action!r}"
            )
        attacked = subset_to_mask(int(action), self.M)
        chosen = np.flatnonzero(attacked)
        if chosen.size > self.remaining:  # over-budget rule: keep the lowest-numbered sensors
            attacked[chosen[self.remaining :]] = False
        self.remaining -= int(attacked.sum())
        self.last_attacked = attacked
        return AttackEffect(attacked=attacked)

    def info(self) -> dict[str, Any]:
        """The sensors attacked this step (0-based) and the budget left."""
        return {"attacked": np.flatnonzero(self.last_attacked).tolist(), "budget_left": self.remaining}


def _as_int(action: Any) -> Any:
    """Accept numpy integer scalars and 0-d/1-element arrays as Discrete actions."""
    if isinstance(action, np.ndarray) and action.size == 1 and np.issubdtype(action.dtype, np.integer):
        return np.int64(action.reshape(()))
    return action
