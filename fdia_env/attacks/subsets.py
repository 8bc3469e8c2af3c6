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

from fdia_env._validation import check_int


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
