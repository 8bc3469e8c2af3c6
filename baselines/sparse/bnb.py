"""Exact branch and bound with a certificate: the optimum, an upper bound, the gap.

The search walks the set-enumeration tree of attack sets in the canonical pair order (by step,
then sensor): a node is a set S of attacked pairs; its children add one pair after the last
pair of S, and every pair between is *not* attacked. Pairs are therefore decided in time order,
so a child's filter recursion reuses its parent's posteriors up to the child's step (prefix
sharing), and all children of a batch of nodes are bounded in one batched pass.

- Incumbent: the better of SFS-SS and DP, and the allocation bound's argmax when it is attained.
- Root: the allocation bound (:func:`baselines.sparse.bound.allocation_bound`); when it equals
  the incumbent (relative :data:`ROOT_RTOL`) the optimum is proved at the root (scalar
  position sensors sharing H).
- Nodes: the smaller of the smoother (downdate) bound of :mod:`baselines.sparse.bound`,
  computed for every child of a node from the node's RTS smoother, and the mixed bound of
  :mod:`baselines.sparse.tail` (exact enumeration of the last two steps, Loewner relaxation of
  the steps before, validity argument in that module's docstring; used when its enumeration
  stays below :data:`TAIL_LIMIT` small problems, e.g. 14 sensors at c = 5 but not 50 sensors);
  children are kept sorted by bound and explored
  depth first, best bound first; a child is pruned when its bound does not exceed the incumbent
  (relative tolerance :data:`PRUNE_RTOL`, absorbing rounding between two exact evaluations).

With a time limit the search stops between batches and returns the incumbent together with the
best upper bound over every still-open node, every pruned node and the root bounds.
"""

from __future__ import annotations

import math
import numbers
import time
from dataclasses import dataclass

import numpy as np

from baselines.sparse.bound import (
    GRAM_ENTRIES,
    allocation_bound,
    brute_force_optimum,
    child_bounds,
    final_value,
    forward,
    information_groups,
    measurement_factors,
    pair_terms,
)
from baselines.sparse.dp import dp
from baselines.sparse.greedy import sfs_ss
from baselines.sparse.problem import Pair, SparseProblem, make_problem
from baselines.sparse.result import SparseResult, result_of
from baselines.sparse.split import split_bound
from baselines.sparse.tail import TailTable, enumeration_size, tail_child_bounds
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem

PRUNE_RTOL = 1e-12
# The root proof compares two different float paths (the allocation recursion and the reference
# evaluation), which differ by up to ~1e-11 relative on ill-conditioned instances.
ROOT_RTOL = 1e-9
DEFAULT_CHUNK = 512
# Largest exact tail enumeration (small problems) per child, and per table point.
TAIL_LIMIT = 200_000


@dataclass
class _Open:
    """Children not yet explored, sorted by bound (descending).

    Attributes:
        attacked: (R, N, M) the children's attacked masks.
        last: (R,) flat index of each child's last (largest) pair.
        parent_posts: (R, N, n, n) the parents' posteriors (valid before the child's step).
        bounds: (R,) the children's bounds.
        depth: Number of attacked pairs of every child.
        pos: Rows before ``pos`` are done.
    """

    attacked: np.ndarray
    last: np.ndarray
    parent_posts: np.ndarray
    bounds: np.ndarray
    depth: int
    pos: int = 0


def _check_time_limit(time_limit: object) -> float | None:
    if time_limit is None:
        return None
    if isinstance(time_limit, bool) or not isinstance(time_limit, numbers.Real):
        raise ValueError(f"time_limit must be None or a number of seconds >= 0, got {time_limit!r}")
    value = float(time_limit)
    if not math.isfinite(value) or value < 0:
        raise ValueError(f"time_limit must be None or a finite number >= 0, got {time_limit!r}")
    return value


class _Timeout(Exception):
    """The deadline passed while bounding a batch of children."""


class _Search:
    def __init__(
        self,
        problem: SparseProblem,
        chunk: int,
        deadline: float | None,
        debug: bool,
        tail: bool = True,
    ):
        self.p = problem
        self.chunk = chunk
        self.deadline = deadline
        self.debug = debug
        self.factors = measurement_factors(problem)
        self.nz = self.factors.shape[2]
        self.best_value = -np.inf
        self.best_pairs: list[Pair] = []
        self.pruned_max = -np.inf
        self.nodes = 0
        self.checked = 0
        self.timed_out = False
        self.groups = information_groups(problem.system.J)
        self.table = None
        N, n = problem.horizon, problem.system.n
        # the mixed bound only where its enumerations stay small (e.g. 14 sensors, c = 5)
        self.tail = tail and enumeration_size(problem.M, problem.budget - 1) <= TAIL_LIMIT
        if self.tail and N >= 3:
            posts = np.empty((1, N, n, n))
            forward(problem, posts, np.zeros((1, N, problem.M), dtype=bool), 0)
            self.table = TailTable(problem, self.factors, posts[0, N - 3])

    # -- incumbent --------------------------------------------------------------------------

    def offer(self, value: float, pairs: list[Pair]) -> None:
        if value > self.best_value:
            self.best_value, self.best_pairs = value, list(pairs)

    def threshold(self) -> float:
        v = self.best_value
        return v + PRUNE_RTOL * max(abs(v), 1.0 if self.p.objective == "logdet" else 0.0)

    # -- expansion --------------------------------------------------------------------------

    def _with_cross(self, rows: int, tail: int) -> bool:
        return rows * (tail * self.p.M) ** 2 * self.nz**2 <= GRAM_ENTRIES * 4 or rows == 1

    def children(
        self, attacked: np.ndarray, last: np.ndarray, posts: np.ndarray, bound: np.ndarray
    ) -> _Open | None:
        """Bound every child of the nodes (one batch, common depth) and return the survivors."""
        p = self.p
        depth = int(attacked[0].sum())
        remaining = p.budget - depth - 1
        start = int((last.min() + 1) // p.M)
        pieces = []
        for lo in range(0, len(last), max(1, self._rows_per_call(start))):
            if self.deadline is not None and time.perf_counter() > self.deadline:
                raise _Timeout  # the caller keeps these nodes' own bounds
            sl = slice(lo, lo + max(1, self._rows_per_call(start)))
            cross = self._with_cross(len(last[sl]), p.horizon - start)
            terms = pair_terms(p, self.factors, posts[sl], start, cross, attacked[sl])
            b = child_bounds(p, terms, last[sl] + 1, remaining, self.nz)
            if self.tail:
                tail = tail_child_bounds(
                    p,
                    self.factors,
                    self.table,
                    self.groups,
                    attacked[sl],
                    last[sl],
                    posts[sl],
                    start,
                    remaining,
                    TAIL_LIMIT,
                )
                b = np.minimum(b, tail)
            b = np.minimum(b, bound[sl, None])  # a child's bound never exceeds its parent's
            pieces.append(b)
        b = np.concatenate(pieces)
        if self.debug:
            self._check(attacked, last, b, start, remaining)
        row, col = np.nonzero(np.isfinite(b) | (b == np.inf))
        vals = b[row, col]
        keep = vals > self.threshold()
        if (~keep).any():
            self.pruned_max = max(self.pruned_max, float(vals[~keep].max()))
        row, col, vals = row[keep], col[keep], vals[keep]
        if len(vals) == 0:
            return None
        order = np.argsort(-vals, kind="stable")
        row, col, vals = row[order], col[order], vals[order]
        flat = start * p.M + col
        child = attacked[row].copy()
        child.reshape(len(row), -1)[np.arange(len(row)), flat] = True
        return _Open(child, flat, posts[row], vals, depth + 1)

    def _rows_per_call(self, start: int) -> int:
        T = self.p.horizon - start
        per_row = (T * self.p.M) ** 2 * max(self.nz, 1) ** 2 + T * T * self.p.system.n**2
        return max(1, GRAM_ENTRIES // per_row)

    def _check(self, attacked, last, bounds, start, remaining) -> None:
        """Debug: every child bound must be at least the child's exact subtree optimum."""
        p = self.p
        pairs = p.pairs()

        def scale(v: float) -> float:  # relative for trace (values may be ~1e-4), log det: ≥ 1
            return abs(v) if p.objective == "trace" else max(abs(v), 1.0)

        for r_ in range(len(last)):
            base = [pairs[f] for f in np.flatnonzero(attacked[r_].ravel())]
            for col in range(bounds.shape[1]):
                f = start * p.M + col
                if not np.isfinite(bounds[r_, col]) or f <= last[r_]:
                    continue
                exact = brute_force_optimum(p, [*base, pairs[f]], pairs[f + 1 :], remaining)
                self.checked += 1
                if bounds[r_, col] < exact - 1e-9 * scale(exact):
                    raise RuntimeError(
                        f"invalid bound at node {[*base, pairs[f]]}: bound {bounds[r_, col]!r} "
                        f"< subtree optimum {exact!r}"
                    )

    def expand(self, node: _Open, lo: int, hi: int) -> _Open | None:
        """Explore rows lo:hi of ``node``: evaluate leaves, or bound the grandchildren."""
        p = self.p
        attacked, last = node.attacked[lo:hi], node.last[lo:hi]
        steps = last // p.M
        self.nodes += hi - lo
        if node.depth == p.budget:
            for k in np.unique(steps):
                sel = np.flatnonzero(steps == k)
                prior = (
                    node.parent_posts[lo:hi][sel, k - 1]
                    if k > 0
                    else np.broadcast_to(p.P_start, (len(sel), p.system.n, p.system.n))
                )
                values = final_value(p, prior, attacked[sel], int(k))
                j = int(np.argmax(values))
                if values[j] > self.best_value:
                    flat = np.flatnonzero(attacked[sel[j]].ravel())
                    self.offer(float(values[j]), [divmod(int(f), p.M) for f in flat])
            return None
        posts = node.parent_posts[lo:hi].copy()
        for k in np.unique(steps):
            sel = np.flatnonzero(steps == k)
            sub = posts[sel]
            forward(p, sub, attacked[sel], int(k))
            posts[sel] = sub
        out = []
        for k in np.unique(steps):  # group by the first free step (shared tail length)
            sel = np.flatnonzero(steps == k)
            kids = self.children(attacked[sel], last[sel], posts[sel], node.bounds[lo:hi][sel])
            if kids is not None:
                out.append(kids)
        if not out:
            return None
        if len(out) == 1:
            return out[0]
        vals = np.concatenate([o.bounds for o in out])
        order = np.argsort(-vals, kind="stable")
        return _Open(
            np.concatenate([o.attacked for o in out])[order],
            np.concatenate([o.last for o in out])[order],
            np.concatenate([o.parent_posts for o in out])[order],
            vals[order],
            out[0].depth,
        )

    def run(self, root_bound: float) -> float:
        """Search; return the certified upper bound (the incumbent when the search completes)."""
        p = self.p
        n, N, M = p.system.n, p.horizon, p.M
        posts = np.empty((1, N, n, n))
        attacked = np.zeros((1, N, M), dtype=bool)
        forward(p, posts, attacked, 0)
        self.nodes += 1
        stack: list[_Open] = []
        try:
            root = self.children(attacked, np.array([-1]), posts, np.array([root_bound]))
        except _Timeout:
            self.timed_out = True
            return max(self.best_value, root_bound)
        if root is not None:
            stack.append(root)
        while stack:
            if self.deadline is not None and time.perf_counter() > self.deadline:
                self.timed_out = True
                break
            node = stack[-1]
            if node.pos >= len(node.bounds):
                stack.pop()
                continue
            if node.bounds[node.pos] <= self.threshold():  # sorted: the rest are pruned too
                self.pruned_max = max(self.pruned_max, float(node.bounds[node.pos]))
                stack.pop()
                continue
            lo = node.pos
            hi = min(len(node.bounds), lo + self.chunk)
            cut = np.searchsorted(-node.bounds[lo:hi], -self.threshold(), side="left")
            hi = lo + max(int(cut), 1)
            node.pos = hi
            try:
                kids = self.expand(node, lo, hi)
            except _Timeout:  # rows lo:hi were not bounded further: their own bounds stand
                self.pruned_max = max(self.pruned_max, float(node.bounds[lo:hi].max()))
                self.timed_out = True
                break
            if kids is not None:
                stack.append(kids)
        open_max = max(
            (float(o.bounds[o.pos]) for o in stack if o.pos < len(o.bounds)), default=-np.inf
        )
        if not self.timed_out:
            return self.best_value
        return max(self.best_value, self.pruned_max, open_max)


def branch_and_bound(
    system_or_scenario: str | Scenario | LinearSystem,
    budget: int | None = None,
    horizon: int | None = None,
    objective: str = "trace",
    time_limit: float | None = None,
    *,
    chunk: int = DEFAULT_CHUNK,
    debug: bool = False,
    mixed_bound: bool = True,
    split: bool = True,
) -> SparseResult:
    """The optimal attack set of exactly ``budget`` pairs, with a proof (or a certified gap).

    Args:
        system_or_scenario: Preset name, :class:`Scenario` or :class:`LinearSystem`.
        budget: Sparsity budget c (default: the preset's).
        horizon: Window length N (default: the preset's).
        objective: ``"trace"`` or ``"logdet"``.
        time_limit: Wall-clock seconds for the whole call, the heuristic incumbent included
            (``None``: until proved). The search stops between batches once it is spent and
            returns the incumbent with the certified upper bound and gap.
        chunk: Nodes expanded per batch.
        debug: Check every child bound against the brute-force optimum of its subtree (tiny
            instances only); a violation raises ``RuntimeError``.
        mixed_bound: Also use the mixed (tail-enumeration) bound of
            :mod:`baselines.sparse.tail` (the minimum of the valid bounds is used); ``False``
            gives the smoother and allocation bounds only, as before it existed.
        split: Also use the split bound of :mod:`baselines.sparse.split` at the root (the last
            step enumerated exactly, earlier drops by a concave tangent; its best last-step
            set is offered as an incumbent). It often proves the optimum of meter-level grid
            instances at the root, where the tree search would not finish.

    Returns:
        A :class:`SparseResult` (``solver="bnb"``) with ``upper_bound``, ``gap`` (0 when
        proved), ``nodes`` (tree nodes bounded or evaluated), ``seconds`` and
        ``proved_optimal``.

    Raises:
        ValueError: For a bad budget, horizon, objective, scenario, time_limit or chunk.

    Example:
        >>> result = branch_and_bound("ch4-position", budget=5, horizon=20)
        >>> round(result.value, 4), result.proved_optimal, result.gap
        (0.0328, True, 0.0)
    """
    t0 = time.perf_counter()
    problem = make_problem(system_or_scenario, budget, horizon, objective)
    limit = _check_time_limit(time_limit)
    if isinstance(chunk, bool) or not isinstance(chunk, numbers.Integral) or chunk < 1:
        raise ValueError(f"chunk must be an integer >= 1, got {chunk!r}")
    if not isinstance(mixed_bound, bool):
        raise ValueError(f"mixed_bound must be True or False, got {mixed_bound!r}")
    if not isinstance(split, bool):
        raise ValueError(f"split must be True or False, got {split!r}")
    deadline = None if limit is None else t0 + limit
    search = _Search(problem, int(chunk), deadline, debug, mixed_bound)
    for heuristic in (sfs_ss, dp):
        result = heuristic(problem.system, problem.budget, problem.horizon, objective)
        search.offer(result.value, list(result.attacks))
    alloc, alloc_pairs = allocation_bound(problem, deadline)
    if alloc_pairs is not None:
        search.offer(problem.evaluate(alloc_pairs), alloc_pairs)
    root = alloc
    if split and problem.budget > 0 and alloc_pairs is None:
        cut = split_bound(problem, search.factors, deadline)
        if cut.pairs is not None:
            search.offer(cut.value, cut.pairs)
        root = min(root, cut.bound)
    if problem.budget == 0 or search.best_value >= root - ROOT_RTOL * max(abs(root), 1.0):
        bound, proved = search.best_value, True
        search.nodes = 1  # proved at the root
    else:
        bound = min(root, search.run(root))
        proved = not search.timed_out
    pairs = sorted(search.best_pairs)
    value = problem.evaluate(pairs)
    if proved:
        bound = value
    result = result_of(
        problem,
        pairs,
        "bnb",
        value,
        evaluations=search.nodes,
        upper_bound=bound,
        nodes=search.nodes,
        seconds=time.perf_counter() - t0,
        proved_optimal=proved,
    )
    return result
