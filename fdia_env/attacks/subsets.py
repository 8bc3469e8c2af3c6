"""Non-empty sensor subsets in the literature's order: by size, then lexicographically.

For M = 3 the order is z1, z2, z3, z1z2, z1z3, z2z3, z1z2z3 (MATH.md §5). Index ``j`` of a
``Discrete(2**M − 1)`` action is the j-th subset in this order.

>>> subsets(3)
[(0,), (1,), (2,), (0, 1), (0, 2), (1, 2), (0, 1, 2)]
>>> subset_bits(3)
[1, 2, 4, 3, 5, 6, 7]
"""

from __future__ import annotations

import functools
import itertools
from typing import Any

import numpy as np
from gymnasium import spaces

from fdia_env._validation import check_int
from fdia_env.attacks.base import as_index


@functools.lru_cache(maxsize=32)
def _subsets(M: int) -> tuple[tuple[int, ...], ...]:
    return tuple(s for r in range(1, M + 1) for s in itertools.combinations(range(M), r))


def subsets(M: int) -> list[tuple[int, ...]]:
    """The ``2**M − 1`` non-empty subsets of ``range(M)`` (0-based), by size then lexicographic."""
    return list(_subsets(check_int("M", M, minimum=1)))


def subset_bits(M: int) -> list[int]:
    """Bitmask of each subset of :func:`subsets` (bit i set = sensor i)."""
    return [sum(1 << i for i in s) for s in _subsets(check_int("M", M, minimum=1))]


def subset_name(subset: tuple[int, ...]) -> str:
    """``(0, 2) -> "z1z3"`` (1-based sensor names, as the literature writes them)."""
    return "".join(f"z{i + 1}" for i in subset)


class SubsetChoice:
    """Bookkeeping of a player that picks a subset each round and sees the other's last one.

    Shared by the sensor game's attack model (:class:`~fdia_env.attacks.subset.SubsetAttack`) and
    defense model (:class:`~fdia_env.defenses.selection.SensorSelection`): the action space,
    the last choice, the opponent's last subset as 0/1 indicator features, and their batched
    counterparts (``b_last``, ``b_opponent``).
    """

    def bind_subsets(self, M: int) -> None:
        """Build the ``Discrete(2**M − 1)`` action space and the feature bounds."""
        self.M = M
        self.subsets = subsets(M)
        self.bits = subset_bits(M)
        self.action_space = spaces.Discrete(len(self.subsets))
        self.feature_low = np.zeros(M, dtype=np.float32)
        self.feature_high = np.ones(M, dtype=np.float32)
        self.last = 0
        self.opponent_last: tuple[int, ...] = ()

    def subset_index(self, action: Any, who: str) -> int:
        """``action`` as a subset index, or ``ValueError`` naming ``who``."""
        j = as_index(action)
        if j is None or not 0 <= j < len(self.subsets):
            raise ValueError(
                f"{who} action must be an integer in [0, {len(self.subsets)}) (a subset index), "
                f"got {action!r}"
            )
        return j

    def reset(self) -> None:
        """Forget the last round."""
        self.opponent_last = ()

    @property
    def last_subset(self) -> tuple[int, ...]:
        """The subset chosen in the last step (0-based sensors)."""
        return self.subsets[self.last]

    def observe_opponent(self, other: Any) -> None:
        """Remember the other player's last subset for the next observation."""
        self.opponent_last = getattr(other, "last_subset", ())

    def features(self) -> list[float]:
        """The other player's last subset as indicators."""
        return [1.0 if i in self.opponent_last else 0.0 for i in range(self.M)]

    def batch_reset(self, batch: int, where: np.ndarray | None = None) -> None:
        """Forget the last round of the members ``where`` (all when None)."""
        if where is None:
            self._batch = batch
            self.b_last = np.zeros(batch, dtype=np.int64)
            self.b_opponent = np.zeros((batch, self.M))
            self._bits_arr = np.array(self.bits, dtype=np.int64)
            self._masks = np.array([[i in s for i in range(self.M)] for s in self.subsets])
        else:
            self.b_opponent[where] = 0.0

    def batch_observe_opponent(self, other: Any) -> None:
        """Every member's opponent subset (both sides use the same subset order)."""
        self.b_opponent = self._masks[other.b_last].astype(float)

    def batch_features(self) -> np.ndarray:
        """(B, M) the other player's last subsets as indicators."""
        return self.b_opponent
