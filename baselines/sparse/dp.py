"""DP: dynamic programming over (budget spent, time step) (docs/math.md §4).

For a count r of sensors attacked at one step, the sensors are taken without search: the r with
the largest information ``tr(H_i' R_i⁻¹ H_i)`` (ties to the lower index). For scalar
measurements sharing one H (the position sensors of the literature) that is the r
smallest-variance sensors, and it is the best choice of r sensors at that step whatever the
prediction: dropping the largest information leaves the largest covariance in the PSD order.
For vector measurements (position+velocity sensors, ``H_i = I₂`` with correlated ``R_i``) the
information matrices are not ordered, and the trace rule is a heuristic.

The table keeps, for every budget spent ``s`` and step ``k``, the single state that maximises
``Φ(P[k|k])`` among the candidates ``KF(state(s − r, k − 1), r)``, ``0 <= r <= min(s, M)``:

    Φ_DP(s, k) = max_r Φ(KF(P_DP(s − r, k − 1), r)),   C(s, k) = argmax_r

and traces back from ``(c, N)``: at each step the budget left for the earlier steps is c minus
*all* later attacks (docs/references.md §4). Memory O(N·c), time O(N·c·M) one-step updates.

Exact for a scalar state (n = 1): P is then a number, the Riccati map is increasing in it, so the
largest state per (s, k) dominates every other continuation. For n > 1 the covariances are only
partially ordered, keeping one state per (s, k) can discard the optimum, and DP is a heuristic.
"""

from __future__ import annotations

import numpy as np

from baselines.sparse.problem import Pair, make_problem
from baselines.sparse.result import SparseResult, result_of
from fdia_env.kalman import information_update, predict_cov
from fdia_env.kalman import objective as phi_of
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem


def attack_ranking(J: np.ndarray) -> np.ndarray:
    """(M,) sensor indices, largest information trace first (stable, so ties keep index order)."""
    return np.argsort(-np.trace(J, axis1=-2, axis2=-1), kind="stable")


def dp(
    system_or_scenario: str | Scenario | LinearSystem,
    budget: int | None = None,
    horizon: int | None = None,
    objective: str = "trace",
) -> SparseResult:
    """DP over (budget spent, step) with the largest-information sensors attacked at each step.

    Args: as :func:`~baselines.sparse.make_problem` (the instance, c, N and Φ).

    Returns:
        The :class:`SparseResult`; ``evaluations`` counts the one-step candidates ``(s, r)``.

    Example:
        >>> round(dp("ch4-position", budget=5, horizon=20).value, 4)
        0.0328
    """
    problem = make_problem(system_or_scenario, budget, horizon, objective)
    system, c, M, N = problem.system, problem.budget, problem.M, problem.horizon
    ranking = attack_ranking(system.J)
    used = np.ones((M + 1, M), dtype=bool)  # used[r]: sensors left after attacking r of them
    for r in range(1, M + 1):
        used[r:, ranking[r - 1]] = False

    states = problem.P_start[None]  # P_DP(s, 0): only s = 0 is reachable
    choice = np.zeros((N, c + 1), dtype=int)  # C(s, k): sensors attacked at step k
    evaluations = 0
    s_full, r_full = np.meshgrid(np.arange(c + 1), np.arange(M + 1), indexing="ij")
    for k in range(N):
        reach = min(c, M * (k + 1))  # most attacks possible after step k
        s_grid, r_grid = s_full[: reach + 1], r_full[: reach + 1]
        valid = (r_grid <= s_grid) & (s_grid - r_grid < len(states))
        s_idx, r_idx = s_grid[valid], r_grid[valid]
        # KF(P_DP(s − r, k − 1), r) for every candidate (s, r) at once
        P = information_update(
            predict_cov(states[s_idx - r_idx], system.F, system.Q), system.J, used[r_idx]
        )
        phi = np.full(s_grid.shape, -np.inf)
        phi[valid] = phi_of(P, objective)
        evaluations += len(s_idx)
        choice[k, : reach + 1] = np.argmax(phi, axis=1)  # first maximum: the smallest r
        P_grid = np.empty((*s_grid.shape, system.n, system.n))
        P_grid[valid] = P
        states = P_grid[np.arange(reach + 1), choice[k, : reach + 1]]

    pairs: list[Pair] = []
    left = c
    for k in range(N - 1, -1, -1):  # the budget for steps < k is c minus every later attack
        r = int(choice[k, left])
        pairs += [(k, int(i)) for i in ranking[:r]]
        left -= r
    return result_of(problem, pairs, "dp", evaluations=evaluations)
