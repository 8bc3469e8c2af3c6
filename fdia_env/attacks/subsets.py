"""Non-empty sensor subsets in the literature's order: by size, then lexicographically.

For M = 3 the order is z1, z2, z3, z1z2, z1z3, z2z3, z1z2z3 (docs/math.md §5). Index ``j`` of a
``Discrete(2**M − 1)`` action is the j-th subset in this order.

>>> subsets(3)
[(0,), (1,), (2,), (0, 1), (0, 2), (1, 2), (0, 1, 2)]
>>> subset_bits(3)
[1, 2, 4, 3, 5, 6, 7]

Strategy sets that stay usable for large M (the power-grid presets have 34 to 304 meters):
``max_subset_size=k`` limits the sensor game to the subsets of sizes :func:`game_sizes` gives,
in the same size-then-lexicographic order: the attacker picks at most k sensors, the defender
leaves out at most k (sizes M − k .. M, so a defender strategy keeps almost every meter and the
network observable; a defender restricted to k meters could not estimate the grid at all).

>>> subsets(4, min_size=3)  # the defender's strategies with k = 1: drop one sensor or none
[(0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3), (0, 1, 2, 3)]
>>> game_sizes(4, 1, "attacker"), game_sizes(4, 1, "defender"), game_sizes(4, None, "defender")
((1, 1), (3, 4), (1, 4))
"""

from __future__ import annotations

import functools
import itertools
import math
from typing import Any

import numpy as np
from gymnasium import spaces

from fdia_env._validation import check_choice, check_int
from fdia_env.attacks.base import as_index, bit_array

PLAYERS = ("attacker", "defender")
MAX_STRATEGIES = 2**16 - 1
"""Most subsets one player's ``Discrete`` action may index (the full game of 16 sensors)."""


@functools.lru_cache(maxsize=32)
def _subsets(M: int, lo: int = 1, hi: int | None = None) -> tuple[tuple[int, ...], ...]:
    top = M if hi is None else hi
    return tuple(s for r in range(lo, top + 1) for s in itertools.combinations(range(M), r))


def _sizes(M: int, max_size: int | None, min_size: int) -> tuple[int, int, int]:
    M = check_int("M", M, minimum=1)
    lo = check_int("min_size", min_size, minimum=1)
    hi = M if max_size is None else min(check_int("max_size", max_size, minimum=1), M)
    if lo > hi:
        raise ValueError(f"min_size must be <= max_size (and <= M = {M}), got {lo} > {hi}")
    return M, lo, hi


def subset_count(M: int, max_size: int | None = None, min_size: int = 1) -> int:
    """Number of subsets of ``range(M)`` with ``min_size <= size <= max_size`` (default M)."""
    M, lo, hi = _sizes(M, max_size, min_size)
    return sum(math.comb(M, r) for r in range(lo, hi + 1))


def subsets(M: int, max_size: int | None = None, min_size: int = 1) -> list[tuple[int, ...]]:
    """Subsets of ``range(M)`` (0-based) of sizes ``min_size..max_size``, by size then lex.

    The defaults give the ``2**M − 1`` non-empty subsets.
    """
    M, lo, hi = _sizes(M, max_size, min_size)
    return list(_subsets(M, lo, hi))


def subset_bits(M: int, max_size: int | None = None, min_size: int = 1) -> list[int]:
    """Bitmask of each subset of :func:`subsets` (bit i set = sensor i)."""
    M, lo, hi = _sizes(M, max_size, min_size)
    return [sum(1 << i for i in s) for s in _subsets(M, lo, hi)]


def game_sizes(M: int, max_subset_size: int | None, player: str) -> tuple[int, int]:
    """``(min_size, max_size)`` of a sensor-game player's subsets.

    ``max_subset_size=None``: every non-empty subset, ``(1, M)``. Otherwise ``k`` in
    ``[1, M]``: the attacker's subsets have at most k sensors, ``(1, k)``; the defender's leave
    out at most k, ``(max(1, M − k), M)``. A k above M is an error, not k = M.
    """
    check_choice("player", player, PLAYERS)
    M = check_int("M", M, minimum=1)
    if max_subset_size is None:
        return 1, M
    k = check_int("max_subset_size", max_subset_size, minimum=1)
    if k > M:
        raise ValueError(
            f"max_subset_size must be in [1, M = {M}] (the number of sensors), got {k}"
        )
    return (1, k) if player == "attacker" else (max(1, M - k), M)


def game_subsets(M: int, max_subset_size: int | None, player: str) -> list[tuple[int, ...]]:
    """The subsets of :func:`game_sizes`, in size-then-lexicographic order."""
    lo, hi = game_sizes(M, max_subset_size, player)
    return subsets(M, max_size=hi, min_size=lo)


def subset_name(subset: tuple[int, ...]) -> str:
    """``(0, 2) -> "z1z3"`` (1-based sensor names, as the literature writes them)."""
    return "".join(f"z{i + 1}" for i in subset)


class SubsetChoice:
    """Bookkeeping of a player that picks a subset each round and sees the other's last one.

    Shared by the sensor game's attack model (:class:`~fdia_env.attacks.subset.SubsetAttack`) and
    defense model (:class:`~fdia_env.defenses.selection.SensorSelection`): the action space,
    the last choice (``b_last``), the opponent's last subset as 0/1 indicator features
    (``b_opponent``), over batches of the backend ``xp`` (the single env's is the batch of
    one, :mod:`fdia_env.backend.one`).
    """

    def bind_subsets(self, M: int, max_subset_size: int | None = None, player: str = "") -> None:
        """Build the ``Discrete`` action space over the player's subsets and the feature bounds.

        Args:
            M: Number of sensors.
            max_subset_size: None for every non-empty subset (``Discrete(2**M − 1)``), else k
                (see :func:`game_sizes`).
            player: ``"attacker"`` or ``"defender"`` (whose family ``k`` selects).

        Raises:
            ValueError: When the family has more than :data:`MAX_STRATEGIES` subsets.
        """
        lo, hi = game_sizes(M, max_subset_size, player or "attacker")
        count = subset_count(M, hi, lo)
        if count > MAX_STRATEGIES:
            raise ValueError(
                f"the subset action supports at most 16 sensors ({MAX_STRATEGIES:,} subsets); "
                f"the {player or 'player'}'s strategy set has {count:,} subsets for M = {M} "
                f"with max_subset_size={max_subset_size}: pass a smaller max_subset_size"
            )
        self.M = M
        self.max_subset_size = max_subset_size
        self.subsets = subsets(M, max_size=hi, min_size=lo)
        self.bits = subset_bits(M, max_size=hi, min_size=lo)
        self.action_space = spaces.Discrete(len(self.subsets))
        self.feature_low = np.zeros(M, dtype=np.float32)
        self.feature_high = np.ones(M, dtype=np.float32)
        masks = np.zeros((len(self.subsets), M), dtype=bool)
        for j, s in enumerate(self.subsets):
            masks[j, list(s)] = True
        self._masks_np = masks
        self._b_xp = None  # the backend of the tables below (see batch_reset)

    def subset_index(self, action: Any, who: str) -> int:
        """``action`` as a subset index, or ``ValueError`` naming ``who``."""
        j = as_index(action)
        if j is None or not 0 <= j < len(self.subsets):
            raise ValueError(
                f"{who} action must be an integer in [0, {len(self.subsets)}) (a subset index), "
                f"got {action!r}"
            )
        return j

    @property
    def last(self) -> int:
        """The single env's subset index of the last step (0 before the first)."""
        return int(self.xp.member(self.b_last, 0)) if hasattr(self, "b_last") else 0

    @property
    def last_subset(self) -> tuple[int, ...]:
        """The subset chosen in the last step (0-based sensors)."""
        return self.subsets[self.last]

    batch_backends = ("numpy", "torch")

    def _batch_tables(self, xp: Any) -> None:
        """The subsets' masks and bitmasks on the backend ``xp`` (once per backend change).

        Raises:
            ValueError: Naming ``backend`` on torch with more than 62 sensors (the bitmasks are
                int64 there; numpy keeps larger ones as Python ints).
        """
        if getattr(xp, "name", None) == "torch" and self.M > 62:
            raise ValueError(
                "backend='torch' holds sensor subsets as int64 bitmasks, so at most 62 sensors, "
                f"got M = {self.M}; use backend='numpy'"
            )
        self._masks = xp.asarray(self._masks_np)
        self._bits_arr = xp.asarray(bit_array(self.bits, self.M))  # <= 16 sensors: int64

    def batch_reset(self, batch: int, where: Any = None) -> None:
        """Forget the last round of the members ``where`` (all when None).

        The batch arrays belong to the backend ``self.xp`` (numpy, torch or the batch of one).
        """
        xp = self.xp
        if where is None:
            self._batch = batch
            self.b_last = xp.zeros(batch, dtype=xp.int64)
            self.b_opponent = xp.zeros((batch, self.M))
            if self._b_xp is not xp:
                self._batch_tables(xp)
                self._b_xp = xp
        else:
            self.b_opponent[where] = 0.0

    def batch_observe_opponent(self, other: Any) -> None:
        """Every member's opponent subset (from the opponent's own subset list).

        An opponent that picks no subset (e.g. a sparse or covariance attack against sensor
        selection) leaves the indicators at zero.
        """
        xp = self.xp
        if not isinstance(other, SubsetChoice):
            self.b_opponent = xp.zeros((self._batch, self.M))
            return
        self.b_opponent = xp.astype(other._masks[other.b_last], xp.float64)

    def batch_features(self) -> Any:
        """(B, M) the other player's last subsets as indicators."""
        return self.b_opponent
