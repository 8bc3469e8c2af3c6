"""Greedy solvers of docs/math.md §4: SFS, SBS and the simplex-improved SFS-SS.

Every greedy step scores all its candidate sets in one batched covariance recursion
(:meth:`SparseProblem.evaluate_masks`). Candidates are scanned in the canonical pair order (by
step, then sensor); ties go to the first.
"""

from __future__ import annotations

import numpy as np

from baselines.sparse import lowrank
from baselines.sparse.problem import Pair, SparseProblem, make_problem
from baselines.sparse.result import SparseResult, result_of
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem

# An SFS-SS swap must raise Φ by more than this (relative) to count as an improvement, so
# rounding noise between equal sets cannot make the search cycle.
IMPROVEMENT_RTOL = 1e-12

Scenarioish = str | Scenario | LinearSystem


def _pair(problem: SparseProblem, flat: int) -> Pair:
    step, sensor = divmod(int(flat), problem.M)
    return step, sensor


def _toggle_each(problem: SparseProblem, attacked: np.ndarray, flats: np.ndarray) -> np.ndarray:
    """Φ of ``attacked`` with each pair of ``flats`` flipped, one candidate per entry (batched).

    Large states with scalar sensors (the power-grid presets) take the rank-one path of
    :mod:`baselines.sparse.lowrank`: O(N n²) per candidate instead of O(N n³).
    """
    if lowrank.applies(problem):
        return lowrank.toggle_values(problem, attacked, flats)
    masks = np.repeat(attacked.reshape(1, -1), len(flats), axis=0)
    rows = np.arange(len(flats))
    masks[rows, flats] = ~masks[rows, flats]
    return problem.evaluate_masks(masks.reshape(-1, problem.horizon, problem.M))


def _sfs_order(problem: SparseProblem) -> tuple[list[Pair], int]:
    """SFS pick order and the number of candidate sets scored."""
    attacked = np.zeros(problem.size, dtype=bool)
    order: list[Pair] = []
    evaluations = 0
    for _ in range(problem.budget):
        candidates = np.flatnonzero(~attacked)
        values = _toggle_each(problem, attacked, candidates)  # Φ(A ∪ {p}) for every p ∉ A
        evaluations += len(candidates)
        best = candidates[int(np.argmax(values))]
        attacked[best] = True
        order.append(_pair(problem, best))
    return order, evaluations


def sfs(
    system_or_scenario: Scenarioish,
    budget: int | None = None,
    horizon: int | None = None,
    objective: str = "trace",
) -> SparseResult:
    """Sequential forward selection: add, one at a time, the pair whose attack raises Φ most.

    ``c·M·N`` candidate evaluations at most. The pick order (``result.order``) is itself a
    strategy: its first ``b`` pairs are SFS's answer for every budget ``b <= c``.

    Args: as :func:`~baselines.sparse.make_problem` (the instance, c, N and Φ).

    Returns:
        The :class:`SparseResult`, with ``order`` the pairs in pick order.

    Example:
        >>> sfs("ch4-position", budget=5, horizon=6).order
        ((5, 0), (4, 0), (3, 0), (5, 1), (2, 0))
    """
    problem = make_problem(system_or_scenario, budget, horizon, objective)
    order, evaluations = _sfs_order(problem)
    return result_of(problem, order, "sfs", order=order, evaluations=evaluations)


def sbs(
    system_or_scenario: Scenarioish,
    budget: int | None = None,
    horizon: int | None = None,
    objective: str = "trace",
) -> SparseResult:
    """Sequential backward selection: attack every pair, then un-attack one pair at a time.

    Each round restores the pair whose restoration lowers Φ least, until ``c`` pairs are left.
    About ``(M·N)²/2`` candidate evaluations.

    Args: as :func:`~baselines.sparse.make_problem` (the instance, c, N and Φ).

    Returns:
        The :class:`SparseResult` (``order`` is None).
    """
    problem = make_problem(system_or_scenario, budget, horizon, objective)
    attacked = np.ones(problem.size, dtype=bool)
    evaluations = 0
    for _ in range(problem.size - problem.budget):
        candidates = np.flatnonzero(attacked)
        values = _toggle_each(problem, attacked, candidates)  # Φ(A \ {p}) for every p ∈ A
        evaluations += len(candidates)
        attacked[candidates[int(np.argmax(values))]] = False
    pairs = [_pair(problem, f) for f in np.flatnonzero(attacked)]
    return result_of(problem, pairs, "sbs", evaluations=evaluations)


def sfs_ss(
    system_or_scenario: Scenarioish,
    budget: int | None = None,
    horizon: int | None = None,
    objective: str = "trace",
) -> SparseResult:
    """SFS improved by single swaps (the "simplex" step of docs/math.md §4).

    Start from the SFS set in pick order, at the last pick (position ``c−1``, 0-based). At a
    position, try replacing its pair by each pair outside the set (one batch) and keep the best
    replacement if it raises Φ (by more than a relative ``1e-12``); after a swap restart from
    the last position, otherwise move one position earlier. Stop once the first pick's position
    shows no improvement. Φ only increases, so the result is at least SFS's.

    Args: as :func:`~baselines.sparse.make_problem` (the instance, c, N and Φ).

    Returns:
        The :class:`SparseResult` (``order`` is None).
    """
    problem = make_problem(system_or_scenario, budget, horizon, objective)
    order, evaluations = _sfs_order(problem)
    chosen = [pair[0] * problem.M + pair[1] for pair in order]  # flat indices, in pick order
    attacked = np.zeros(problem.size, dtype=bool)
    attacked[chosen] = True
    current = problem.evaluate(order)
    position = len(chosen) - 1
    while position >= 0:
        outside = np.flatnonzero(~attacked)
        if outside.size == 0:
            break
        attacked[chosen[position]] = False
        values = _toggle_each(problem, attacked, outside)  # Φ((A \ {a_j}) ∪ {p}), p ∉ A
        evaluations += len(outside)
        best = int(np.argmax(values))
        if values[best] > current + IMPROVEMENT_RTOL * abs(current):
            chosen[position] = int(outside[best])
            current = float(values[best])
            position = len(chosen) - 1
        else:
            position -= 1
        attacked[:] = False
        attacked[chosen] = True
    pairs = [_pair(problem, f) for f in chosen]
    return result_of(problem, pairs, "sfs_ss", evaluations=evaluations)
