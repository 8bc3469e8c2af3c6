"""EXS: exhaustive search over every c-subset of the M·N sensor-time pairs (docs/math.md §4).

The ``C(M·N, c)`` sets are not evaluated one recursion at a time. The search walks the window
step by step over a *frontier* of distinct partial attack patterns, sharing every prefix:

- before the first attacked step the filter stays at the steady state, so all patterns start
  from one state; a pattern's state after step k depends only on its attacks up to k;
- level k holds one filter state per pattern over steps 0..k−1 with ``s <= c`` attacks, pruned
  to those that can still reach exactly c attacks (``s >= c − M·(N − k)``);
- rows are kept sorted by attack count s, so the parents that may attack r more sensors at the
  next step form one contiguous slice: each (subset, slice) child block is a pure array
  operation, with no gather;
- the predicted information ``(F P F' + Q)⁻¹`` is computed once per parent and shared by its
  children, and the last step computes only Φ, never the covariance.

Memory stays bounded: when a level would exceed ``chunk_rows`` children, its parents are
processed in chunks, depth first (each level then holds at most ``chunk_rows`` states).

Attacking more never lowers Φ under perfect detection (dropping information makes P larger in
the PSD order, and the Riccati map is monotone), so the best set of size exactly c is also the
best of size at most c; the search still enumerates exactly-c sets, as docs/math.md §4 specifies.
"""

from __future__ import annotations

import bisect
import itertools
import math
from dataclasses import dataclass

import numpy as np

from baselines.sparse.algebra import CovarianceAlgebra, algebra_for
from baselines.sparse.problem import Pair, SparseProblem, make_problem
from baselines.sparse.result import SparseResult, result_of
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem

DEFAULT_CHUNK_ROWS = 1 << 18
DEFAULT_MAX_SETS = 10**9
"""EXS refuses instances with more sets than this unless ``max_sets`` is raised or None."""
FAST_SETS_PER_S = 1e7  # measured order of magnitude, 2×2 component path, one core
GENERIC_FLOPS_PER_S = 2e9  # generic path: about one n×n inverse (≈ 2n³ flops) per set


def estimated_seconds(count: int, n: int, fast: bool) -> float:
    """Rough EXS run time for ``count`` sets on a state of size ``n`` (order of magnitude)."""
    rate = FAST_SETS_PER_S if fast and n == 2 else GENERIC_FLOPS_PER_S / max(2.0 * n**3, 200.0)
    return count / rate


def _duration(seconds: float) -> str:
    for unit, size in (("years", 365.25 * 86400), ("days", 86400), ("hours", 3600), ("min", 60)):
        if seconds >= size:
            return f"{seconds / size:,.3g} {unit}"
    return f"{seconds:.3g} s"


@dataclass
class _Level:
    """Filter states after ``depth`` window steps, one per partial pattern, sorted by count.

    Attributes:
        depth: Number of window steps taken.
        states: Batch of states (see :class:`CovarianceAlgebra`).
        bounds: (c+2,) rows with attack count s are ``bounds[s]:bounds[s+1]``.
        block_start: First row of each child block (ascending).
        block_parent: Row of the parent level that each block's first row extends.
        block_code: Subset (bitmask) attacked at step ``depth − 1`` by each block.
        parent: The level this one was expanded from (None at the window start).
    """

    depth: int
    states: np.ndarray
    bounds: np.ndarray
    block_start: list[int]
    block_parent: list[int]
    block_code: list[int]
    parent: _Level | None


def subsets_by_size(M: int, max_size: int) -> list[list[int]]:
    """Bitmasks of the sensor subsets of each size ``0..min(M, max_size)``, lexicographic."""
    return [
        [sum(1 << i for i in combo) for combo in itertools.combinations(range(M), r)]
        for r in range(min(M, max_size) + 1)
    ]


def used_information(J: np.ndarray, codes: list[int]) -> dict[int, np.ndarray]:
    """``Σ_{i not in u} J_i`` for each attacked subset ``u`` (bitmask) in ``codes``."""
    M = J.shape[0]
    return {u: J[[i for i in range(M) if not (u >> i) & 1]].sum(axis=0) for u in codes}


def code_pairs(step: int, code: int, M: int) -> list[Pair]:
    """The pairs ``(step, i)`` for the sensors ``i`` set in ``code``."""
    return [(step, i) for i in range(M) if (code >> i) & 1]


class _FrontierSearch:
    """Depth-first walk over frontier chunks; keeps the best complete pattern found."""

    def __init__(self, problem: SparseProblem, algebra: CovarianceAlgebra, chunk_rows: int) -> None:
        self.problem = problem
        self.alg = algebra
        self.chunk_rows = chunk_rows
        self.M, self.N, self.c = problem.M, problem.horizon, problem.budget
        self.subsets = subsets_by_size(self.M, self.c)
        self.J_used = used_information(problem.system.J, [u for s in self.subsets for u in s])
        self.best_value = -np.inf
        self.best_pairs: list[Pair] = []
        self.nonfinite = False  # an objective overflowed (a NaN/inf value is never the best)

    def run(self) -> tuple[float, list[Pair]]:
        """Search every exactly-c pattern; return the best search value and its pairs."""
        bounds = np.ones(self.c + 2, dtype=np.int64)
        bounds[0] = 0  # the window start: one state, zero attacks
        start = _Level(0, self.alg.start(self.problem.P_start), bounds, [], [], [], None)
        self._search(start)
        return self.best_value, sorted(self.best_pairs)

    def _count_range(self, depth: int) -> tuple[int, int]:
        """Attack counts a pattern may have after ``depth`` steps and still end at exactly c."""
        return max(0, self.c - self.M * (self.N - depth)), min(self.c, self.M * depth)

    def _search(self, level: _Level) -> None:
        if level.depth == self.N - 1:
            for lo, hi in self._chunks(level):
                self._finish(level, lo, hi)
            return
        for lo, hi in self._chunks(level):
            self._search(self._expand(level, lo, hi))

    def _children_per_row(self, level: _Level) -> list[int]:
        """Number of feasible children of a parent row with attack count s, for each s."""
        t_min, t_max = self._count_range(level.depth + 1)
        sizes = [len(codes) for codes in self.subsets]  # subsets of r sensors, r = 0..min(M, c)
        return [
            sum(sizes[t - s] for t in range(t_min, t_max + 1) if 0 <= t - s < len(sizes))
            for s in range(self.c + 1)
        ]

    def _chunks(self, level: _Level) -> list[tuple[int, int]]:
        """Split the parent rows so that each chunk has at most ``chunk_rows`` children."""
        per_row = self._children_per_row(level)
        cuts, used = [0], 0
        for s in range(self.c + 1):
            lo, hi, width = int(level.bounds[s]), int(level.bounds[s + 1]), per_row[s]
            while lo < hi and width > 0:
                room = (self.chunk_rows - used) // width
                if room == 0 and used > 0:
                    cuts.append(lo)
                    used = 0
                    continue
                take = min(max(room, 1), hi - lo)
                lo += take
                used += take * width
        cuts.append(int(level.bounds[-1]))
        return [(a, b) for a, b in itertools.pairwise(cuts) if b > a]

    def _blocks(self, level: _Level, lo: int, hi: int, t: int):
        """``(r, parent_lo, parent_hi)`` for the children with count t from parent rows lo:hi."""
        for r in range(len(self.subsets)):
            s = t - r  # attacks before this step
            if s < 0:
                break
            a = max(int(level.bounds[s]), lo)
            b = min(int(level.bounds[s + 1]), hi)
            if a < b:
                yield r, a, b

    def _expand(self, level: _Level, lo: int, hi: int) -> _Level:
        """The next level from parent rows ``lo:hi``: one child per (pattern, attacked subset)."""
        alg = self.alg
        info = alg.predicted_information(alg.take(level.states, lo, hi))  # Y = (F P F' + Q)⁻¹
        t_min, t_max = self._count_range(level.depth + 1)
        parts, starts, parents, codes = [], [], [], []
        bounds = np.zeros(self.c + 2, dtype=np.int64)
        rows = 0
        for t in range(self.c + 1):
            bounds[t] = rows
            if not t_min <= t <= t_max:
                continue
            for r, a, b in self._blocks(level, lo, hi, t):
                sub = alg.take(info, a - lo, b - lo)
                for code in self.subsets[r]:
                    parts.append(alg.posterior(sub, self.J_used[code]))  # P = (Y + J_used)⁻¹
                    starts.append(rows)
                    parents.append(a)
                    codes.append(code)
                    rows += b - a
        bounds[self.c + 1] = rows
        return _Level(level.depth + 1, alg.concat(parts), bounds, starts, parents, codes, level)

    def _finish(self, level: _Level, lo: int, hi: int) -> None:
        """Last step: Φ of every exactly-c completion of parent rows ``lo:hi``."""
        alg = self.alg
        info = alg.predicted_information(alg.take(level.states, lo, hi))
        for r, a, b in self._blocks(level, lo, hi, self.c):
            sub = alg.take(info, a - lo, b - lo)
            for code in self.subsets[r]:
                values = alg.posterior_objective(sub, self.J_used[code])
                self.nonfinite |= not bool(np.all(np.isfinite(values)))
                j = int(np.argmax(values))
                if values[j] > self.best_value:
                    self.best_value = float(values[j])
                    last = code_pairs(level.depth, code, self.M)
                    self.best_pairs = last + self._trace(level, a + j)

    def _trace(self, level: _Level, row: int) -> list[Pair]:
        """The attacked pairs of the pattern at ``row`` of ``level``, back to the window start."""
        pairs: list[Pair] = []
        while level.parent is not None:
            j = bisect.bisect_right(level.block_start, row) - 1
            pairs += code_pairs(level.depth - 1, level.block_code[j], self.M)
            row = level.block_parent[j] + row - level.block_start[j]
            level = level.parent
        return pairs


def exhaustive(
    system_or_scenario: str | Scenario | LinearSystem,
    budget: int | None = None,
    horizon: int | None = None,
    objective: str = "trace",
    *,
    fast: bool = True,
    chunk_rows: int = DEFAULT_CHUNK_ROWS,
    max_sets: int | None = DEFAULT_MAX_SETS,
) -> SparseResult:
    """EXS: the best attack set of exactly ``budget`` pairs, by exhaustive search.

    Args:
        system_or_scenario: Preset name, :class:`Scenario` or :class:`LinearSystem`.
        budget: Sparsity budget c (default: the preset's).
        horizon: Window length N (default: the preset's).
        objective: ``"trace"`` or ``"logdet"``.
        fast: Use the 2×2 component algebra when the state has two components; ``False`` forces
            the generic ``np.linalg`` path (for cross-checks). A search whose closed forms
            overflow (covariances beyond about 1e±155) is run again on the generic path.
        chunk_rows: Most states held per level (bounds memory; larger is slightly faster).
        max_sets: Refuse instances with more than this many sets ``C(M·N, c)`` (default 10⁹,
            minutes on the 2×2 path); ``None`` runs any size.

    Returns:
        The optimal :class:`SparseResult` (``evaluations = C(M·N, c)``). Among sets with equal
        Φ the first one the walk meets is kept. Cost grows like ``C(M·N, c)``: about 10⁷ sets/s
        on one core with the 2×2 path (M·N = 60, c = 5 in about half a second).

    Raises:
        ValueError: For a bad budget, horizon, objective or scenario (naming the parameter), or
            an instance above ``max_sets`` (the message gives the number of sets and an
            estimated run time), or a system whose covariances overflow float64 in the search.

    Example:
        >>> result = exhaustive("ch4-position", budget=5, horizon=6)
        >>> round(result.value, 4), result.attacks
        (0.0328, ((2, 0), (3, 0), (4, 0), (5, 0), (5, 1)))
    """
    problem = make_problem(system_or_scenario, budget, horizon, objective)
    if chunk_rows < 1:
        raise ValueError(f"chunk_rows must be >= 1, got {chunk_rows}")
    sys = problem.system
    count = math.comb(problem.size, problem.budget)
    if max_sets is not None:
        if isinstance(max_sets, bool) or not isinstance(max_sets, int) or max_sets < 1:
            raise ValueError(f"max_sets must be an integer >= 1 or None, got {max_sets!r}")
        if count > max_sets:
            eta = _duration(estimated_seconds(count, sys.n, fast))
            raise ValueError(
                f"EXS would evaluate C(M·N = {problem.size}, c = {problem.budget}) = {count:,} "
                f"sets (estimated {eta} on one core), above max_sets = {max_sets:,}; pass "
                "max_sets=None to run it anyway, or use sfs / sfs_ss / dp"
            )
    search = _FrontierSearch(problem, algebra_for(sys.F, sys.Q, objective, fast), chunk_rows)
    _, pairs = search.run()
    if search.nonfinite and fast:  # the 2×2 closed forms square entries: |P| ~ 1e155 overflows
        search = _FrontierSearch(problem, algebra_for(sys.F, sys.Q, objective, False), chunk_rows)
        _, pairs = search.run()
    if search.nonfinite:
        raise ValueError(
            f"system_or_scenario: the covariances of {sys.name or 'the system'} overflow or "
            "underflow float64 in the search (a Φ came out NaN or inf), so no optimum is "
            "certified; rescale its Q, R and P0 toward 1"
        )
    return result_of(problem, pairs, "exs", evaluations=math.comb(problem.size, problem.budget))
