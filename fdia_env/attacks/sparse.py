"""Sparse attack: the attacker picks sensor-time pairs within a budget c (MATH.md §4)."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from fdia_env._validation import check_choice, check_int
from fdia_env.attacks.base import AttackEffect, AttackModel, as_index, as_index_array
from fdia_env.episode import EpisodeSpec
from fdia_env.systems import LinearSystem

MAX_SENSORS = 16
ILLEGAL_ACTIONS = ("trim", "error", "noop")


def trim_to_budget(bits: int, remaining: int) -> int:
    """Over-budget rule: keep the lowest-numbered selected sensors that fit ``remaining``."""
    kept = 0
    while bits and remaining > 0:
        low = bits & -bits  # lowest set bit
        kept |= low
        bits ^= low
        remaining -= 1
    return kept


class SparseAttack(AttackModel):
    """Attack up to ``budget`` sensor-time pairs over the window.

    Action: ``Discrete(2**M)``; action ``a`` attacks the sensors whose bits are set in ``a``
    (bit 0 = sensor 1), so 0 is "no attack". The observation's ``action_mask`` marks the
    subsets no larger than the remaining budget.

    Over-budget rule (``illegal_action``): an action that selects more sensors than the budget
    left is an illegal action (its ``action_mask`` entry is 0). ``"trim"`` (default) keeps the
    lowest-numbered selected sensors that fit, ``"noop"`` attacks nothing, ``"error"`` raises a
    ``ValueError`` naming the action and the budget left. No episode ever spends more than
    ``budget``.

    Features: the remaining budget as a fraction of ``budget`` (0 when ``budget`` is 0).

    Args:
        budget: c, the sensor-time pairs the attacker may corrupt over the window (>= 0).
        illegal_action: ``"trim"``, ``"noop"`` or ``"error"`` (see above).
    """

    name = "sparse"

    def __init__(self, budget: int, illegal_action: str = "trim") -> None:
        self.budget = check_int("budget", budget, minimum=0)
        self.illegal_action = check_choice("illegal_action", illegal_action, ILLEGAL_ACTIONS)
        self.remaining = self.budget
        self.last_attacked = 0

    def bind(self, system: LinearSystem, spec: EpisodeSpec) -> None:
        """Build the action space for ``system`` and check the budget fits the window."""
        if system.M > MAX_SENSORS:
            raise ValueError(
                f"the sparse attack's subset action supports at most {MAX_SENSORS} sensors, "
                f"the system has {system.M}"
            )
        if self.budget > system.M * spec.horizon:
            raise ValueError(
                f"budget must be <= M * horizon = {system.M * spec.horizon} (every sensor-time "
                f"pair of the window: M = {system.M} sensors, horizon = {spec.horizon} steps, "
                f"which is max_cycles when only that is given), got {self.budget}"
            )
        self.M = system.M
        self.n_actions = 2**system.M
        self.action_space = spaces.Discrete(self.n_actions)
        sizes = np.array([a.bit_count() for a in range(self.n_actions)])
        self._sizes = sizes
        self._trim_table: np.ndarray | None = None  # built on first batched use
        self._masks = [
            (sizes <= r).astype(np.int8) for r in range(self.budget + 1)
        ]  # per budget left
        self.feature_low = np.zeros(1, dtype=np.float32)
        self.feature_high = np.ones(1, dtype=np.float32)

    def reset(self) -> None:
        """Restore the full budget."""
        self.remaining = self.budget
        self.last_attacked = 0

    def features(self) -> list[float]:
        """Remaining budget fraction."""
        return [self.remaining / self.budget if self.budget else 0.0]

    def action_mask(self) -> np.ndarray:
        """Subsets whose size fits the remaining budget (int8, 1 = legal); a new array per call."""
        return self._masks[self.remaining].copy()

    def apply(self, action: Any) -> AttackEffect:
        """Attack the chosen subset, trimmed to the remaining budget."""
        a = as_index(action)
        if a is None or not 0 <= a < self.n_actions:
            raise ValueError(
                f"attacker action must be an integer in [0, {self.n_actions}) (a sensor bitmask), "
                f"got {action!r}"
            )
        if a.bit_count() > self.remaining:
            a = self._illegal(a, self.remaining)
        self.remaining -= a.bit_count()
        self.last_attacked = a
        return AttackEffect(attacked=a)

    def _illegal(self, action: int, remaining: int) -> int:
        """What an over-budget ``action`` does, by the ``illegal_action`` rule."""
        if self.illegal_action == "error":
            raise ValueError(
                f"attacker action {action} (sensors {_sensors(action)}) is illegal: it attacks "
                f"{action.bit_count()} sensors with {remaining} of the budget left; legal actions "
                f"are those with action_mask[a] = 1 (at most {remaining} bits set)"
            )
        return 0 if self.illegal_action == "noop" else trim_to_budget(action, remaining)

    def info(self) -> dict[str, Any]:
        """``attacked``: (M,) int8, 1 for each sensor attacked this step; ``budget_left``."""
        attacked = (self.last_attacked >> np.arange(self.M)) & 1
        return {"attacked": attacked.astype(np.int8), "budget_left": int(self.remaining)}

    # --- batched (see AttackModel) ---------------------------------------------------------
    def batch_reset(self, batch: int, where: np.ndarray | None = None) -> None:
        """Restore the full budget of the members ``where``."""
        if where is None:
            self.b_remaining = np.full(batch, self.budget, dtype=np.int64)
            self.b_attacked = np.zeros(batch, dtype=np.int64)
        else:
            self.b_remaining[where] = self.budget
            self.b_attacked[where] = 0

    def batch_features(self) -> np.ndarray:
        """(B, 1) remaining budget fraction."""
        scale = 1.0 / self.budget if self.budget else 0.0
        return (self.b_remaining * scale)[:, None]

    def _batch_tables(self) -> None:
        """Tables indexed by [action, min(budget left, M)]: the trimmed action, and masks."""
        actions = np.arange(self.n_actions)[:, None]
        left = np.arange(self.M + 1)[None, :]
        kept = np.zeros((self.n_actions, self.M + 1), dtype=np.int64)
        count = np.zeros_like(kept)
        for i in range(self.M):  # keep the lowest-numbered selected sensors that fit
            take = ((actions >> i) & 1) & (count < left)
            kept |= take << i
            count += take
        self._trim_table = kept.reshape(-1)  # flat: index action * (M + 1) + left
        self._mask_table = (self._sizes[None, :] <= left.T).astype(np.int8)

    def batch_action_mask(self) -> np.ndarray:
        """(B, 2**M) subsets within each member's budget left."""
        if self._trim_table is None:
            self._batch_tables()
        return np.take(self._mask_table, np.minimum(self.b_remaining, self.M), axis=0)

    def batch_apply(self, actions: np.ndarray) -> tuple[np.ndarray, None]:
        """Attack each member's subset, trimmed to its budget (same rule as :meth:`apply`)."""
        a = as_index_array(actions, self.n_actions, "attacker", "sensor bitmasks")
        if self._trim_table is None:
            self._batch_tables()
        if self.illegal_action != "trim":
            over = np.take(self._sizes, a) > self.b_remaining
            if over.any():
                i = int(np.flatnonzero(over)[0])
                self._illegal(int(a[i]), int(self.b_remaining[i]))  # raises for "error"
                a = np.where(over, 0, a)
        a = np.take(self._trim_table, a * (self.M + 1) + np.minimum(self.b_remaining, self.M))
        self.b_remaining = self.b_remaining - np.take(self._sizes, a)
        self.b_attacked = a
        return a, None

    def batch_info(self) -> dict[str, np.ndarray]:
        """Batched :meth:`info`."""
        attacked = (self.b_attacked[:, None] >> np.arange(self.M)) & 1
        return {"attacked": attacked.astype(np.int8), "budget_left": self.b_remaining.copy()}


def _sensors(bits: int) -> list[int]:
    """The 1-based sensor numbers whose bits are set."""
    return [i + 1 for i in range(bits.bit_length()) if bits >> i & 1]
