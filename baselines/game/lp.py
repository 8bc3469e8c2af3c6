"""Mixed equilibria of the zero-sum sensor-selection game by linear programming (docs/math.md §5).

The defender (row player) *minimises* the payoff ``L[D, A]``; the attacker (column player)
maximises it. Every function here takes a plain payoff matrix, so it serves the ch5 game, the
incomplete-information game and the double oracle's restricted games alike.

>>> import numpy as np
>>> x, y, value = solve_zero_sum(np.array([[0.0, 1.0], [1.0, 0.0]]))  # matching pennies
>>> x.round(12).tolist(), y.round(12).tolist(), round(value, 12)
([0.5, 0.5], [0.5, 0.5], 0.5)
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.optimize
import scipy.sparse

from fdia_env._validation import as_float_array

# HiGHS' default feasibility tolerances (1e-7) would let a basis whose reduced costs are ~1e-8
# off pass as optimal; the payoffs are rescaled to [0, 1] before solving, so these tolerances are
# relative to the payoff range and the returned strategies are exploitable by ~1e-10 of it at most.
_HIGHS_OPTIONS = {
    "primal_feasibility_tolerance": 1e-10,
    "dual_feasibility_tolerance": 1e-10,
}


def as_payoff(L: Any, name: str = "L") -> np.ndarray:
    """``L`` as a finite float64 2-D array with at least one row and column.

    Raises:
        ValueError: Naming ``name``: a ragged nested list, a non-numeric entry, an array that is
            not 2-D, an empty dimension, NaN or infinity.
    """
    arr = as_float_array(name, L, "a 2-D numeric payoff matrix (rows of equal length)")
    if arr.ndim != 2:
        raise ValueError(f"{name} must be a 2-D payoff matrix, got an array of shape {arr.shape}")
    if 0 in arr.shape:
        raise ValueError(f"{name} must have at least one row and one column, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite (no NaN or inf)")
    return arr


def as_payoffs(matrices: Any, name: str = "matrices") -> np.ndarray:
    """S payoff matrices of one shape (a sequence or an (S, m, n) array) as an (S, m, n) array.

    Raises:
        ValueError: Naming ``name``: no matrices, a matrix :func:`as_payoff` refuses (named
            ``name[s]``), or matrices of different shapes.

    Example:
        >>> as_payoffs([[[1, 2]], [[3, 4]]]).shape
        (2, 1, 2)
    """
    if isinstance(matrices, np.ndarray) and matrices.ndim == 3:
        matrices = list(matrices)
    if isinstance(matrices, str) or not isinstance(matrices, Sequence) or len(matrices) == 0:
        raise ValueError(f"{name} must be a non-empty sequence of payoff matrices")
    Ls = [as_payoff(L, f"{name}[{s}]") for s, L in enumerate(matrices)]
    for s, L in enumerate(Ls):
        if L.shape != Ls[0].shape:
            raise ValueError(
                f"{name} must share one shape: {name}[0] is {Ls[0].shape}, {name}[{s}] is {L.shape}"
            )
    return np.stack(Ls)


def as_strategy(p: Any, size: int, name: str) -> np.ndarray:
    """``p`` as a probability vector of length ``size`` (entries ≥ 0 summing to 1 within 1e-9).

    Entries down to −1e-12 (other solvers' rounding) are accepted and clipped to 0.

    Raises:
        ValueError: Naming ``name`` when the shape, sign or sum is wrong.
    """
    arr = as_float_array(name, p, "a 1-D probability vector")
    if arr.shape != (size,):
        raise ValueError(f"{name} must have shape ({size},), got {arr.shape}")
    if not np.all(np.isfinite(arr)) or (arr < -1e-12).any():
        bad = arr[~np.isfinite(arr) | (arr < -1e-12)]
        raise ValueError(f"{name} must have finite entries >= 0, got {bad.tolist()[:5]}")
    if abs(arr.sum() - 1.0) > 1e-9:
        raise ValueError(f"{name} must sum to 1, got sum {arr.sum()!r}")
    return np.clip(arr, 0.0, None)


def _to_simplex(v: np.ndarray) -> np.ndarray:
    """Clip the solver's ±1e-17 rounding below zero and renormalise."""
    v = np.clip(v, 0.0, None)
    return v / v.sum()


def _defender_lp(
    blocks: Sequence[np.ndarray], weights: np.ndarray
) -> tuple[np.ndarray, list[np.ndarray], float]:
    """Solve ``min Σ_s w_s b_s  s.t.  L_s' x ≤ b_s 1 (every s),  1'x = 1,  x ≥ 0``.

    Returns ``x``, the duals ``μ_s ≥ 0`` of each block's constraints (``1'μ_s = w_s``) and the
    optimal objective. With one block and w = 1 this is the game LP of :func:`solve_zero_sum`.
    """
    m = blocks[0].shape[0]
    S = len(blocks)
    # variables z = (x_1..x_m, b_1..b_S); rows: block s, column j: (L_s' x)_j − b_s ≤ 0
    a_rows = []
    for s, Ls in enumerate(blocks):
        e = np.zeros((Ls.shape[1], S))
        e[:, s] = -1.0
        a_rows.append(np.hstack([Ls.T, e]))
    A_ub = scipy.sparse.csr_array(np.vstack(a_rows))
    c = np.concatenate([np.zeros(m), weights])
    A_eq = np.concatenate([np.ones(m), np.zeros(S)])[None, :]
    bounds = [(0.0, None)] * m + [(None, None)] * S
    res = scipy.optimize.linprog(
        c,
        A_ub=A_ub,
        b_ub=np.zeros(A_ub.shape[0]),
        A_eq=A_eq,
        b_eq=[1.0],
        bounds=bounds,
        method="highs",
        options=_HIGHS_OPTIONS,
    )
    if res.status != 0:
        raise RuntimeError(f"HiGHS did not solve the game LP: {res.message}")
    duals = -np.asarray(res.ineqlin.marginals)  # ≤ constraints of a minimisation: marginals ≤ 0
    splits = np.cumsum([Ls.shape[1] for Ls in blocks])[:-1]
    return res.x[:m], np.split(duals, splits), float(res.fun)


def solve_zero_sum(L: Any) -> tuple[np.ndarray, np.ndarray, float]:
    """Mixed equilibrium and value of the zero-sum game ``L`` (row player minimises).

    Args:
        L: (m, n) payoff to the column player (the attacker); the row player (the defender)
            pays it.

    Returns:
        ``(x, y, value)``: the defender's (m,) and the attacker's (n,) equilibrium mixed
        strategies and the game value ``x' L y``. When the equilibrium is not unique, HiGHS
        returns one vertex of the equilibrium polytope.

    Raises:
        ValueError: If ``L`` is not a finite, non-empty 2-D matrix.
        RuntimeError: If HiGHS reports a failure (it cannot on a finite matrix game).
    """
    L = as_payoff(L)
    # Von Neumann's minimax LP and its dual (e.g. Shoham & Leyton-Brown, *Multiagent Systems*,
    # 2009, §4.1; docs/math.md §5):
    #
    #     defender (primal):  min_{x, b}  b   s.t.  L' x ≤ b 1,  1' x = 1,  x ≥ 0
    #     attacker (dual):    max_{y, v}  v   s.t.  L y  ≥ v 1,  1' y = 1,  y ≥ 0
    #
    # The attacker's LP is the dual of the defender's: its y are the multipliers of the n
    # constraints (L' x)_j ≤ b, which HiGHS returns with the primal solution, so one solve gives
    # both strategies and b* = v* = the value. The payoff is first mapped affinely onto [0, 1]
    # (equilibria are invariant to it) so that HiGHS' tolerances are relative to its range.
    lo, hi = float(L.min()), float(L.max())
    if hi == lo:  # every strategy is optimal; uniform play is one equilibrium
        m, n = L.shape
        return np.full(m, 1.0 / m), np.full(n, 1.0 / n), lo
    scale = hi - lo
    x, (y,), _ = _defender_lp([(L - lo) / scale], np.ones(1))
    x, y = _polish(L, _to_simplex(x), _to_simplex(y))
    return x, y, float(x @ L @ y)


def _nash_conv(L: np.ndarray, x: np.ndarray, y: np.ndarray) -> float:
    return float((x @ L).max() - (L @ y).min())


def _polish(L: np.ndarray, x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Re-solve the equilibrium's indifference equations on the LP's supports.

    On supports Sx, Sy an equilibrium satisfies ``L[Sx, Sy]' x = v 1``, ``1'x = 1`` and
    ``L[Sx, Sy] y = v 1``, ``1'y = 1``. Solving these (least squares, for degenerate supports)
    removes the ~1e-10 · range that HiGHS' tolerances leave; the result is kept only if it is a
    pair of probability vectors with a smaller NashConv.
    """
    sx, sy = np.flatnonzero(x > 0), np.flatnonzero(y > 0)
    sub = L[np.ix_(sx, sy)]
    # unknowns (x_Sx, v): [sub' −1; 1' 0] (x_Sx, v) = (0, 1); likewise (y_Sy, v) with sub
    ax = np.block([[sub.T, -np.ones((sy.size, 1))], [np.ones((1, sx.size)), np.zeros((1, 1))]])
    ay = np.block([[sub, -np.ones((sx.size, 1))], [np.ones((1, sy.size)), np.zeros((1, 1))]])
    try:
        zx = np.linalg.lstsq(ax, np.r_[np.zeros(sy.size), 1.0], rcond=None)[0][:-1]
        zy = np.linalg.lstsq(ay, np.r_[np.zeros(sx.size), 1.0], rcond=None)[0][:-1]
    except np.linalg.LinAlgError:
        return x, y
    if (zx < 0).any() or (zy < 0).any():
        return x, y
    px, py = np.zeros_like(x), np.zeros_like(y)
    px[sx], py[sy] = zx / zx.sum(), zy / zy.sum()
    if _nash_conv(L, px, py) < _nash_conv(L, x, y):
        return px, py
    return x, y


def strategy_bounds(
    L: Any,
    player: str = "defender",
    groups: Sequence[Sequence[int]] | None = None,
    rtol: float = 1e-9,
) -> tuple[np.ndarray, np.ndarray]:
    """Least and greatest probability of each strategy (or group) over all equilibria.

    A player's equilibrium strategies form a polytope, e.g. the defender's
    ``{x : L' x ≤ v 1, 1'x = 1, x ≥ 0}``; this minimises and maximises each coordinate (or each
    group's total) over it with 2 LPs per entry. Equal bounds mean the entry is the same in
    every equilibrium; equal bounds everywhere mean the strategy is unique.

    Args:
        L: (m, n) payoff matrix (defender minimises).
        player: ``"defender"`` (rows) or ``"attacker"`` (columns).
        groups: Lists of strategy indices whose totals to bound (default: each strategy alone).
        rtol: The value v is relaxed by ``rtol`` times the payoff range, so that the polytope is
            not empty through rounding; the bounds are therefore loose by about that much.

    Returns:
        ``(low, high)``, one entry per group.

    Example:
        >>> low, high = strategy_bounds([[1.0, 1.0], [0.0, 2.0]], "attacker")
        >>> low.round(6).tolist(), high.round(6).tolist()  # y_2 ≥ 1/2 is all that binds
        ([0.0, 0.5], [0.5, 1.0])
    """
    L = as_payoff(L)
    if not isinstance(player, str) or player not in ("defender", "attacker"):  # arrays too
        raise ValueError(f"player must be 'defender' or 'attacker', got {player!r}")
    value = solve_zero_sum(L)[2]
    lo, hi = float(L.min()), float(L.max())
    scale = hi - lo if hi > lo else 1.0
    # The LPs run on the payoffs rescaled to [0, 1], as the solver's do: HiGHS' tolerances are
    # absolute, and it takes entries beyond 1e15 for infinite (a 1e300 payoff: "Model error").
    S, v = (L - lo) / scale, (value - lo) / scale
    slack = rtol * max(hi - lo, 1.0) / scale
    # defender: S' x ≤ (v + slack) 1; attacker: −S y ≤ −(v − slack) 1
    A_ub, b_ub = (S.T, v + slack) if player == "defender" else (-S, -(v - slack))
    k = A_ub.shape[1]
    groups = [[j] for j in range(k)] if groups is None else [list(g) for g in groups]
    low, high = np.zeros(len(groups)), np.zeros(len(groups))
    for g, members in enumerate(groups):
        c = np.zeros(k)
        c[members] = 1.0
        for sign, out in ((1.0, low), (-1.0, high)):
            res = scipy.optimize.linprog(
                sign * c,
                A_ub=A_ub,
                b_ub=np.full(A_ub.shape[0], b_ub),
                A_eq=np.ones((1, k)),
                b_eq=[1.0],
                method="highs",
                options=_HIGHS_OPTIONS,
            )
            if res.status != 0:
                raise RuntimeError(f"HiGHS failed on a strategy-bound LP: {res.message}")
            out[g] = sign * res.fun
    return low, high


@dataclass(frozen=True)
class Exploitability:
    """How far a strategy pair is from equilibrium (docs/math.md §5).

    Attributes:
        defender: ``max_j (L' x)_j − v``: what a best-responding attacker gains against ``x``
            beyond the value (≥ 0; 0 iff ``x`` is an equilibrium strategy).
        attacker: ``v − min_i (L y)_i``: what a best-responding defender saves against ``y``.
        nash_conv: Their sum ``max_j (L' x)_j − min_i (L y)_i``, which does not depend on v.
        value: The game value v used.
    """

    defender: float
    attacker: float
    nash_conv: float
    value: float


def exploitability(L: Any, x: Any, y: Any, value: float | None = None) -> Exploitability:
    """Exploitability of each player's mixed strategy and their NashConv.

    Args:
        L: (m, n) payoff matrix (defender minimises).
        x: (m,) defender mixed strategy.
        y: (n,) attacker mixed strategy.
        value: Game value v; solved with :func:`solve_zero_sum` when not given.

    Returns:
        An :class:`Exploitability`.

    Raises:
        ValueError: For a bad matrix or a strategy that is not a probability vector of the
            matching length.

    Example:
        >>> rps = np.array([[0.0, 1.0, -1.0], [-1.0, 0.0, 1.0], [1.0, -1.0, 0.0]])
        >>> e = exploitability(rps, [1.0, 0.0, 0.0], np.full(3, 1 / 3), value=0.0)
        >>> e.defender, round(e.attacker, 12), e.nash_conv
        (1.0, 0.0, 1.0)
    """
    L = as_payoff(L)
    x = as_strategy(x, L.shape[0], "x")
    y = as_strategy(y, L.shape[1], "y")
    if value is None:
        value = solve_zero_sum(L)[2]
    best_attack = float((x @ L).max())  # max_j (L' x)_j
    best_defence = float((L @ y).min())  # min_i (L y)_i
    return Exploitability(
        defender=best_attack - value,
        attacker=value - best_defence,
        nash_conv=best_attack - best_defence,
        value=float(value),
    )


ATTACKER_MODELS = ("uninformed", "informed")


@dataclass(frozen=True)
class BayesianSolution:
    """Equilibrium of the incomplete-information game (docs/math.md §5).

    Attributes:
        x: (m,) defender mixed strategy.
        y: (S, n) attacker mixed strategy per type (identical rows in the ``"uninformed"``
            model, where the attacker's choice cannot depend on its type).
        value: Expected payoff ``Σ_s p_s x' L_s y_s`` at the equilibrium.
        type_values: (S,) expected payoff ``x' L_s y_s`` against each type.
        priors: (S,) the priors p_s.
        attacker: The attacker model solved, ``"uninformed"`` or ``"informed"``.
    """

    x: np.ndarray
    y: np.ndarray
    value: float
    type_values: np.ndarray
    priors: np.ndarray
    attacker: str


def solve_bayesian(
    matrices: Sequence[Any], priors: Any, attacker: str = "uninformed"
) -> BayesianSolution:
    """Equilibrium when the defender does not know which of S attack types it faces.

    Two models of the attacker's side:

    - ``"uninformed"`` (docs/math.md §5, the literature's formulation): the attacker's pure strategy
      is a column index (e.g. the attacked subset) chosen without regard to its type, which
      nature then draws with ``priors``. The game is the zero-sum game on ``L̄ = Σ_s p_s L_s``;
      the defender's LP is :func:`solve_zero_sum`'s on L̄ and the attacker's strategy is its dual,
      returned as S identical rows.
    - ``"informed"`` (Harsanyi): each type knows itself and best-responds on its own matrix. The
      defender solves ``min Σ_s p_s b_s  s.t.  L_s' x ≤ b_s 1 (every s),  1'x = 1,  x ≥ 0``;
      type s plays the duals ``μ_s / p_s`` of its block (a type with prior 0 gets a pure best
      response to x). The value is ≥ the uninformed one: the attacker knows more.

    Args:
        matrices: S payoff matrices of the same shape (m, n).
        priors: (S,) probabilities ≥ 0 summing to 1.
        attacker: ``"uninformed"`` or ``"informed"``.

    Returns:
        A :class:`BayesianSolution`.

    Raises:
        ValueError: Naming the parameter: no matrices, matrices of different shapes, priors of
            the wrong length, negative or not summing to 1, an unknown attacker model.

    Example:
        >>> L1, L2 = np.array([[3.0, 0.0], [0.0, 1.0]]), np.array([[1.0, 0.0], [0.0, 3.0]])
        >>> sol = solve_bayesian([L1, L2], [0.5, 0.5])
        >>> sol.x.round(6).tolist(), round(sol.value, 6)
        ([0.5, 0.5], 1.0)
        >>> round(solve_bayesian([L1, L2], [0.5, 0.5], attacker="informed").value, 6)
        1.5
    """
    if not isinstance(attacker, str) or attacker not in ATTACKER_MODELS:  # arrays too
        raise ValueError(f"attacker must be one of {list(ATTACKER_MODELS)}, got {attacker!r}")
    stack = as_payoffs(matrices)
    S, n = stack.shape[0], stack.shape[2]
    p = as_strategy(priors, S, "priors")
    if attacker == "uninformed":
        x, y, _ = solve_zero_sum(np.tensordot(p, stack, axes=1))  # L̄ = Σ_s p_s L_s
        ys = np.tile(y, (S, 1))
    else:
        lo, hi = float(stack.min()), float(stack.max())
        scale = hi - lo if hi > lo else 1.0
        x, duals, _ = _defender_lp([(L - lo) / scale for L in stack], p)
        x = _to_simplex(x)
        ys = np.zeros((S, n))
        for s in range(S):
            if p[s] > 0 and duals[s].sum() > 0:
                ys[s] = _to_simplex(duals[s])
            else:
                ys[s, int(np.argmax(x @ stack[s]))] = 1.0
    type_values = np.einsum("i,sij,sj->s", x, stack, ys)
    return BayesianSolution(
        x=x,
        y=ys,
        value=float(p @ type_values),
        type_values=type_values,
        priors=p,
        attacker=attacker,
    )
