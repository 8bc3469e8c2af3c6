"""Minimum-meter and budgeted stealthy attacks, and what protecting meters rules out.

- :func:`minimum_meter_attack`: the undetectable attack with the fewest meters on a target state
  (its security index) or on any state (Liu, Ning & Reiter 2009's k-meter attack at its
  smallest k).
- :func:`budgeted_attack`: with at most ``budget`` meters, each injected by at most ``a_max``,
  the undetectable attack (``a = H c``) that moves a target state's estimate the most, by the
  exact MILP ``max c_t`` s.t. ``|(H c)_i| ≤ a_max_i y_i``, ``Σ y ≤ budget``, ``y ∈ {0, 1}^m``
  (the bound on a is a natural big-M, so the MILP is exact); over every state when no target
  is given (the largest angle error any such attack achieves, ``max_t``).
- :func:`basic_measurement_set`: n meters with linearly independent rows of H; protecting them
  rules out every undetectable attack (Bobba et al. 2010: ``H_B c = 0`` forces ``c = 0``), and
  no set of fewer than n meters can (their rows leave a non-zero c with ``H_P c = 0``).
- :func:`undetectable_attack`: an undetectable attack that spares the protected meters, or
  ``None`` when they rule every one out.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import linalg, optimize, sparse

from baselines.stealth.common import (
    as_estimation,
    meter_indices,
    milp,
    null_space,
    on_support,
    state_index,
    support,
)
from baselines.stealth.security_index import security_index
from fdia_env._validation import check_int

if TYPE_CHECKING:
    from baselines.stealth.policy import StealthPolicy


@dataclass(frozen=True, eq=False)
class StealthyAttack:
    """An undetectable injection ``a = H c`` and what it achieves.

    Attributes:
        a: (m,) the injection, per unit.
        c: (n,) the estimate's shift it causes (radians on the grids).
        meters: Positions of the meters it corrupts.
        target: The state it was optimised for (``None``: the attack of
            :func:`undetectable_attack`).
        value: The objective: the number of meters (:func:`minimum_meter_attack`) or the
            target's shift ``c_t`` (:func:`budgeted_attack`).
        objective: ``"meters"``, ``"shift"`` or ``"exists"``.
        budget: The meter budget (budgeted attacks), else ``None``.
        seconds: Wall time of the solve.
        bound: The certified bound on the best achievable objective: an upper bound on the
            shift for :func:`budgeted_attack` (equal to ``value`` unless a solve stopped at
            ``time_limit``), a lower bound on the meters for :func:`minimum_meter_attack`;
            ``None`` for :func:`undetectable_attack`, which optimises nothing.
    """

    a: np.ndarray
    c: np.ndarray
    meters: tuple[int, ...]
    target: int | None
    value: float
    objective: str
    budget: int | None = None
    seconds: float = 0.0
    bound: float | None = None

    @property
    def proved(self) -> bool:
        """Whether ``value`` is certified optimal (its bound is reached, to 1e-9 relative)."""
        if self.bound is None:
            return False
        return abs(self.bound - self.value) <= 1e-9 * max(1.0, abs(self.value))

    def policy(self, a_max: float = 1.0) -> StealthPolicy:
        """This attack for ``stealth_attack_v0`` with ``action="free"`` and that ``a_max``.

        Raises:
            ValueError: If some ``|a_i|`` exceeds ``a_max``.
        """
        from baselines.stealth.policy import StealthPolicy

        return StealthPolicy(self.a / a_max, kind="free")


def _attack(a: np.ndarray, c: np.ndarray, **kwargs: Any) -> StealthyAttack:
    a = on_support(np.asarray(a, dtype=np.float64))
    c = np.array(c, dtype=np.float64)
    a.setflags(write=False)
    c.setflags(write=False)
    return StealthyAttack(a=a, c=c, meters=tuple(int(i) for i in support(a)), **kwargs)


def minimum_meter_attack(
    estimation: Any = "ieee14",
    *,
    target: int | None = None,
    protected: Any = None,
    method: str = "milp",
) -> StealthyAttack | None:
    """The undetectable attack with the fewest meters (on ``target``, or on any state).

    Args:
        estimation: A :class:`~fdia_env.stealth.StaticEstimation` or what
            :func:`~fdia_env.stealth.static_estimation` accepts.
        target: State position; ``None`` for the weakest state.
        protected: Meters the attacker cannot touch.
        method: A :func:`~baselines.stealth.security_index` method.

    Returns:
        The attack (``value`` = its number of meters, ``c`` scaled to ``c_target = 1``), or
        ``None`` if the protected meters leave no undetectable attack.

    Example:
        >>> from baselines.stealth import minimum_meter_attack
        >>> minimum_meter_attack("ieee14", method="mincut").value
        3.0
    """
    est = as_estimation(estimation)
    start = time.perf_counter()
    states = None if target is None else [state_index(est, target, "target")]
    result = security_index(est, method=method, states=states, protected=protected)
    k = result.weakest if target is None else states[0]
    if not np.isfinite(result.indices[k]):
        return None
    return _attack(
        result.attacks[k],
        result.shifts[k],
        target=k,
        value=float(result.indices[k]),
        objective="meters",
        seconds=time.perf_counter() - start,
        bound=float(result.lower_bounds[k]),
    )


def _a_max(est: Any, a_max: Any) -> np.ndarray:
    try:
        arr = np.array(a_max, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"a_max must be a positive number or {est.m} of them") from exc
    if arr.size == 1:
        arr = np.full(est.m, arr[0])
    if arr.size != est.m or not np.all(np.isfinite(arr)) or np.any(arr <= 0.0):
        raise ValueError(
            f"a_max must be one positive finite number or {est.m} of them, got "
            f"{np.asarray(a_max).tolist()}"
        )
    return arr


def check_budget(est: Any, budget: Any) -> int:
    """``budget`` as an int in 1..m (``ValueError`` naming it)."""
    return check_int("budget", budget, minimum=1, maximum=est.m)


def budgeted_attack(
    estimation: Any = "ieee14",
    budget: int = 5,
    *,
    a_max: Any = 1.0,
    target: int | None = None,
    protected: Any = None,
    time_limit: float | None = None,
    indices: Any = None,
) -> StealthyAttack | None:
    """The undetectable attack on at most ``budget`` meters that moves ``target`` the most.

    Args:
        estimation: A :class:`~fdia_env.stealth.StaticEstimation` or what
            :func:`~fdia_env.stealth.static_estimation` accepts.
        budget: Meters the attacker may corrupt, 1..m.
        a_max: Largest injection per meter (per unit), one number or m of them.
        target: State whose estimate to move; ``None``: every state, the best one kept.
        protected: Meters the attacker cannot touch.
        time_limit: HiGHS seconds per state. A solve that stops there keeps its best attack
            and certifies an upper bound (``bound``; ``proved`` is then False).
        indices: A :class:`~baselines.stealth.SecurityIndex` of this model with the same
            protected meters (every state computed), to skip states: a state whose certified
            lower bound exceeds ``budget`` has no undetectable attack on ``budget`` meters
            that moves it (its best shift is 0), so its MILP is not solved. This is what makes
            the search over every state of IEEE 118 finish: the MILP of such a state must prove
            a zero optimum, which its relaxation bounds poorly.

    Returns:
        The attack (``value`` = ``c_target``, the shift of the target's estimate; 0 when the
        budget allows no undetectable attack, then ``a = 0``), with ``bound`` the certified
        upper bound on the best shift.

    Raises:
        ValueError: Naming the parameter: a budget outside 1..m, a_max ≤ 0 or non-finite,
            unknown meters or target, ``indices`` of another model, protection or with
            states not computed.

    Example:
        >>> from baselines.stealth import budgeted_attack
        >>> attack = budgeted_attack("ieee14", budget=3, a_max=0.5, target=6)
        >>> attack.meters, round(attack.value, 4)
        ((6, 7, 32), 0.0881)
    """
    est = as_estimation(estimation)
    budget = check_budget(est, budget)
    bound = _a_max(est, a_max)
    prot = meter_indices(est, protected)
    targets = range(est.n) if target is None else [state_index(est, target, "target")]
    if indices is not None:
        lower = _index_bounds(est, indices, prot)
        targets = [t for t in targets if lower[t] <= budget]
    start = time.perf_counter()
    best: tuple[float, int, np.ndarray] | None = None
    upper = 0.0
    for t in targets:
        value, c, limit = _budget_milp(est, t, budget, bound, prot, time_limit)
        upper = max(upper, limit)
        if best is None or value > best[0] + 1e-12:
            best = (value, t, c)
    if best is None:  # every target skipped: no undetectable attack fits the budget
        best = (0.0, 0 if target is None else state_index(est, target, "target"), np.zeros(est.n))
    value, t, c = best
    a = est.H @ c
    if value <= 0.0:
        a, c, value = np.zeros(est.m), np.zeros(est.n), 0.0
    return _attack(
        a,
        c,
        target=t,
        value=float(value),
        objective="shift",
        budget=budget,
        seconds=time.perf_counter() - start,
        bound=max(float(upper), float(value)),
    )


def _index_bounds(est: Any, indices: Any, prot: np.ndarray) -> np.ndarray:
    """(n,) the certified lower bounds of ``indices``, checked to belong to this problem."""
    from baselines.stealth.security_index import SecurityIndex

    if not isinstance(indices, SecurityIndex):
        raise ValueError(f"indices must be a SecurityIndex, got {type(indices).__name__}")
    lower = np.asarray(indices.lower_bounds, dtype=np.float64)
    if lower.shape != (est.n,) or tuple(indices.meters) != tuple(est.meters):
        raise ValueError("indices must be the security index of this model (other meters)")
    if tuple(indices.protected) != tuple(int(i) for i in prot):
        raise ValueError(
            f"indices were computed with protected meters {list(indices.protected)}, not "
            f"{prot.tolist()}"
        )
    if np.isnan(lower).any():
        raise ValueError("indices must cover every state (some were not computed)")
    return lower


def _budget_milp(
    est: Any,
    t: int,
    budget: int,
    bound: np.ndarray,
    prot: np.ndarray,
    time_limit: float | None,
) -> tuple[float, np.ndarray, float]:
    """The best shift of state t found, its c, and the certified upper bound on the best shift.

    The bound is the shift itself when proved, HiGHS' dual bound when the solve stopped at
    ``time_limit``.
    """
    # the problem is linear in the bound: solve it with the largest bound in units of its
    # meter's row (the MILP's |a_i| / max |H_i|) scaled to 1 (HiGHS reads coefficients above
    # 1e20 as infinite, and ones far below 1 as within its tolerances) and scale the shift back
    rows = np.max(np.abs(est.H), axis=1)
    with np.errstate(over="ignore"):
        unit = float(np.max(bound / np.where(rows == 0.0, 1.0, rows)))
    if not 0.0 < unit < np.inf:
        unit = float(np.max(bound))
    value, c, limit = _budget_milp_unit(est, t, budget, bound / unit, prot, time_limit)
    value, c, limit = value * unit, c * unit, limit * unit
    over = float(np.max(np.abs(est.H @ c) / bound))
    if over > 1.0:  # rounding of the scaling: back inside the box
        c, value = c / over, value / over
    if not (np.isfinite(value) and np.all(np.isfinite(c))):
        raise ValueError(
            f"a_max = {unit:g} is too large for this model: the shift of state {t} overflows "
            "a float; use a smaller a_max (the shift is linear in it)"
        )
    return value, c, limit


def _budget_milp_unit(
    est: Any,
    t: int,
    budget: int,
    bound: np.ndarray,
    prot: np.ndarray,
    time_limit: float | None,
) -> tuple[float, np.ndarray, float]:
    """:func:`_budget_milp` for bounds of largest entry 1."""
    m, n = est.m, est.n
    scale = np.max(np.abs(est.H), axis=1)
    scale[scale == 0.0] = 1.0  # a meter that sees no state: any a_i on it is detected
    Hn = est.H / scale[:, None]
    M = sparse.diags(bound / scale)
    A = sparse.bmat(
        [
            [Hn, -M],
            [-Hn, -M],
            [None, sparse.csr_matrix(np.ones((1, m)))],
        ],
        format="csr",
    )
    upper = np.concatenate([np.zeros(2 * m), [budget]])
    cost = np.zeros(n + m)
    cost[t] = -1.0
    lb = np.concatenate([np.full(n, -np.inf), np.zeros(m)])
    ub = np.concatenate([np.full(n, np.inf), np.ones(m)])
    ub[n + prot] = 0.0
    options: dict[str, Any] = {"mip_rel_gap": 1e-9}
    if time_limit is not None:
        options["time_limit"] = float(time_limit)
    res = milp(
        cost,
        constraints=optimize.LinearConstraint(A, -np.inf, upper),
        integrality=np.concatenate([np.zeros(n), np.ones(m)]),
        bounds=optimize.Bounds(lb, ub),
        options=options,
    )
    if res.x is None:
        raise RuntimeError(f"HiGHS found no budgeted attack on state {t}: {res.message}")
    dual = getattr(res, "mip_dual_bound", None)
    limit = None if res.status == 0 or dual is None or not np.isfinite(dual) else -float(dual)
    if res.status != 0 and limit is None:
        limit = np.inf  # stopped early without a finite dual bound: nothing certified
    c = res.x[:n]
    # exact clean-up: zero the meters the MILP left off, re-solve c on the chosen meters' zeros
    used = np.flatnonzero(res.x[n:] > 0.5)
    zero = np.setdiff1d(np.arange(m), used)
    N = null_space(Hn[zero], n)  # rows of max-abs 1: a meter of small scale still counts
    if N.shape[1] == 0 or abs(c[t]) <= 1e-12:
        return 0.0, np.zeros(n), 0.0 if limit is None else max(limit, 0.0)
    c = N @ (N.T @ c)
    a = est.H @ c
    over = np.max(np.abs(a) / bound)
    if over > 1.0:  # rounding of the projection: scale back inside the box
        c = c / over
    value = float(c[t])
    return value, c, value if limit is None else max(limit, value)


def basic_measurement_set(estimation: Any = "ieee14") -> tuple[int, ...]:
    """A basic measurement set: n meters whose rows of H are linearly independent.

    Chosen by QR with column pivoting of ``H'`` (the best-conditioned greedy choice).
    Protecting them rules out every undetectable attack; see the module docstring.

    Example:
        >>> from baselines.stealth import basic_measurement_set
        >>> len(basic_measurement_set("ieee14"))
        13
    """
    est = as_estimation(estimation)
    _, _, piv = linalg.qr(est.H.T, pivoting=True, mode="economic")
    return tuple(sorted(int(i) for i in piv[: est.n]))


def undetectable_attack(estimation: Any = "ieee14", protected: Any = None) -> StealthyAttack | None:
    """An undetectable attack ``a = H c ≠ 0`` with ``a = 0`` on the protected meters, or None.

    ``c`` is a unit vector of the null space of the protected rows of H; ``None`` when those
    rows have rank n (they contain a basic measurement set).
    """
    est = as_estimation(estimation)
    prot = meter_indices(est, protected)
    N = null_space(est.H[prot], est.n)
    if N.shape[1] == 0:
        return None
    c = N[:, 0]
    a = est.H @ c
    a[prot] = 0.0
    return _attack(a, c, target=None, value=float(np.max(np.abs(c))), objective="exists")
