"""The security index of every state: the fewest meters an undetectable attack on it needs.

For state k, ``α_k = min |supp(H c)|`` over ``c`` with ``c_k = 1`` (Sandberg, Teixeira &
Johansson 2010), optionally with some meters protected (``a_i = 0`` forced). Four methods:

- ``"milp"`` (exact; any H, any protected meters): ``α_k = min |S|`` over the meter sets S
  that *hit* every set T of free meters whose rows, with the protected ones, span k's unit
  vector (rows spanning it force ``c_k = 0``). That minimum hitting set is found by a
  cutting-plane loop: solve it over the sets T found so far (a branch and bound on bit
  masks), test the rank of the rows it leaves (``attack_on_state``); if they still span k's
  vector, add the minimal sets T they contain. Every master optimum is a lower bound, and
  the first S that passes the rank test is an attack of that size, so the index and its
  bound are exact, whatever the scale of H. A big-M MILP (``|(D H c)_i| ≤ M_i y_i``,
  ``c_k = 1``, ``|c_j| ≤ c_max``, HiGHS; D scales H's rows to max-abs 1,
  ``M_i = c_max |(D H)_i|_1``) supplies a first attack, re-solved by the rank test;
  ``c_max`` only scales that first pass (an attack whose c needs more is still found by the
  loop). In the full-measurement case below, with nothing protected, the min cut's size is
  the certified bound and the loop is skipped.
- ``"mincut"`` (grid models, no protected meters): restrict c to 0/1 angle shifts (1 on a
  set S of buses holding bus k, 0 on the slack). With positive susceptances a meter's
  reading changes iff the set of buses in its row (a flow: its two ends; an injection: the
  bus and its neighbours) is split by S, so ``|supp(H c)|`` is the number of meters *cut*
  by S: a minimum s–t cut in the hypergraph whose hyperedges are the meters, computed as a
  max flow on Lawler's graph (one arc of capacity 1 per meter between two auxiliary nodes).
  With every branch flow and every bus injection metered and positive susceptances (the
  full-measurement case of Hendrickx, Johansson, Jungers, Sandberg & Sou 2014) an optimal
  attack is of this form and the cut is exact; otherwise it is an upper bound and its
  ``lower_bounds`` are 1. Protected meters are refused: attacks that spare them need not be
  0/1 shifts (use ``"milp"``). ``tests/test_stealth_baselines.py`` checks the cut equals the
  MILP on every state of the grid presets it runs.
- ``"binary"`` (grid models, ≤ 20 angles, no protected meters): every 0/1 shift c,
  enumerated: the brute-force check of the min cut (certified where the cut is).
- ``"brute"`` (any H, ≤ 20 meters): every meter set in order of size, by a rank test (state k is
  attackable with the meters A iff the k-th unit vector is not in the row space of H without A).

Call :func:`security_index`; it returns a :class:`SecurityIndex`.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass
from types import SimpleNamespace
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy import linalg, optimize, sparse

from baselines.stealth.common import (
    as_estimation,
    attack_on_state,
    meter_indices,
    milp,
    null_space,
    on_support,
    state_index,
    support,
)
from fdia_env._validation import check_positive

if TYPE_CHECKING:
    from baselines.stealth.policy import StealthPolicy

METHODS = ("milp", "mincut", "binary", "brute")
MAX_BRUTE = 20


@dataclass(frozen=True, eq=False)
class SecurityIndex:
    """Security indices and the attacks that reach them.

    Attributes:
        indices: (n,) float: the security index of each state (``inf`` where the protected
            meters leave no undetectable attack on it; NaN for states not computed).
        attacks: (n, m) the attack ``a = H c`` reaching each index (zeros where none).
        shifts: (n, n) its state shift c (``c_k = 1``).
        method: ``"milp"``, ``"mincut"``, ``"binary"`` or ``"brute"``.
        protected: Positions of the protected meters.
        meters: Meter names.
        seconds: Wall time.
        lower_bounds: (n,) float: a certified lower bound on each index: equal to ``indices``
            where the index is proved (always for ``"brute"``, and for ``"milp"`` except on
            states whose solve stopped at ``time_limit``: there ``indices`` is the best attack
            found and this the hitting-set loop's bound). ``"mincut"`` and ``"binary"`` prove
            their values only in the full-measurement case (module docstring); elsewhere
            their bound is 1.
    """

    indices: np.ndarray
    attacks: np.ndarray
    shifts: np.ndarray
    method: str
    protected: tuple[int, ...]
    meters: tuple[str, ...]
    seconds: float
    lower_bounds: np.ndarray

    @property
    def proved(self) -> np.ndarray:
        """(n,) bool: where :attr:`indices` is certified (equal to its lower bound)."""
        return self.indices == self.lower_bounds

    def meters_of(self, state: int) -> tuple[int, ...]:
        """Positions of the meters the attack on ``state`` corrupts."""
        return tuple(int(i) for i in support(self.attacks[state]))

    def policy(self, state: int | None = None) -> StealthPolicy:
        """The attack on ``state`` (default :attr:`weakest`) for ``stealth_attack_v0``.

        A ``"shift"`` action: the states its c shifts (0/1 shifts, as the ``"mincut"`` and
        ``"binary"`` methods find; the env's ``magnitude`` scales them).

        Raises:
            ValueError: When the attack's c is not 0/1 (use ``"mincut"``/``"binary"``, or play
                ``a`` with a ``"free"`` action).
        """
        from baselines.stealth.policy import StealthPolicy

        k = self.weakest if state is None else int(state)
        return StealthPolicy(self.shifts[k], kind="shift")

    @property
    def weakest(self) -> int:
        """The state with the smallest index (the minimum-meter attack's target)."""
        return int(np.nanargmin(self.indices))


def _check_method(method: Any) -> str:
    if method not in METHODS:
        raise ValueError(f"method must be one of {list(METHODS)}, got {method!r}")
    return method


def security_index(
    estimation: Any = "ieee14",
    *,
    method: str = "milp",
    states: Any = None,
    protected: Any = None,
    c_max: float = 100.0,
    time_limit: float | None = None,
) -> SecurityIndex:
    """Security index of every state (or of ``states``).

    Args:
        estimation: A :class:`~fdia_env.stealth.StaticEstimation` or anything
            :func:`~fdia_env.stealth.static_estimation` accepts (grid case or preset name, grid
            model, an (m, n) H).
        method: ``"milp"``, ``"mincut"``, ``"binary"`` or ``"brute"`` (module docstring).
        states: State positions to compute (default all).
        protected: Meters the attacker cannot touch (positions or names).
        c_max: MILP only: the bound on c (at ``c_k = 1``) of the first, big-M pass (finite,
            > 0). A numerical scaling only: the indices are exact for every value.
        time_limit: MILP only: seconds per state, ``None`` for none. A state stopped there
            keeps its best attack and a certified lower bound (``proved`` False).

    Returns:
        The :class:`SecurityIndex`.

    Raises:
        ValueError: Naming the parameter: an unknown method, meters or states; ``"mincut"`` or
            ``"binary"`` on an H without a grid model or with protected meters; ``"brute"``
            above 20 meters, ``"binary"`` above 20 angles.

    Example:
        >>> from baselines.stealth import security_index
        >>> security_index("ieee14", method="mincut").indices[:8].astype(int).tolist()
        [5, 5, 5, 5, 5, 5, 3, 5]
    """
    est = as_estimation(estimation)
    method = _check_method(method)
    prot = meter_indices(est, protected)
    if states is None:
        todo = list(range(est.n))
    else:
        todo = [state_index(est, s, "states") for s in np.atleast_1d(np.asarray(states, object))]
    c_max = check_positive("c_max", c_max)
    if time_limit is not None:
        time_limit = check_positive("time_limit", time_limit)
    if method in ("mincut", "binary") and est.grid is None:
        raise ValueError(
            f"method {method!r} needs a grid model (a case, a grid preset or a GridModel); "
            "use 'milp' or 'brute' for your own H"
        )
    if method in ("mincut", "binary") and prot.size:
        raise ValueError(
            f"method {method!r} searches 0/1 shifts, which miss attacks that spare protected "
            "meters: use method='milp' (or 'brute' up to 20 meters) with protected meters"
        )
    if method == "brute" and est.m > MAX_BRUTE:
        raise ValueError(
            f"method 'brute' enumerates meter sets: at most {MAX_BRUTE} meters, "
            f"got {est.m}; use 'milp'"
        )
    if method == "binary" and est.n > MAX_BRUTE:
        raise ValueError(
            f"method 'binary' enumerates bus sets: at most {MAX_BRUTE} angles, "
            f"got {est.n}; use 'mincut' or 'milp'"
        )
    start = time.perf_counter()
    # the index is a property of each row's support, invariant under scaling the rows: solve
    # on H with rows of max-abs 1, so no tolerance relative to the whole of H mistakes a meter
    # of small scale for an untouched one; the attacks are scaled back to H's units at the end
    row_scale = np.max(np.abs(est.H), axis=1)
    row_scale[row_scale == 0.0] = 1.0
    user, est = est, SimpleNamespace(H=est.H / row_scale[:, None], m=est.m, n=est.n, grid=est.grid)
    indices = np.full(est.n, np.nan)
    lower = np.full(est.n, np.nan)
    attacks = np.zeros((est.n, est.m))
    shifts = np.zeros((est.n, est.n))
    # the full-measurement theorem makes the cut a certified bound for the MILP too
    cut_bounds = method == "milp" and not prot.size and _cut_is_exact(est)
    graph = _lawler(est, prot) if method == "mincut" or cut_bounds else None
    solve = {
        "milp": lambda k: _milp(
            est, k, prot, c_max, time_limit, _mincut(est, k, prot, graph) if cut_bounds else None
        ),
        "mincut": lambda k: _mincut(est, k, prot, graph),
    }
    if method == "brute":
        found = _brute(est, todo, prot)
    elif method == "binary":
        found = _binary(est, todo, prot)
    else:
        found = {k: solve[method](k) for k in todo}
    exact = method in ("milp", "brute") or _cut_is_exact(est)
    for k, hit in found.items():
        bound = None
        if method == "milp":
            hit, bound = hit
        if hit is None:
            indices[k] = lower[k] = np.inf
            continue
        c, a = hit
        indices[k] = len(support(a))
        if bound is None:
            bound = indices[k] if exact else 1.0
        lower[k] = min(bound, indices[k])
        # no rounding residue off the support; the rows' units back
        attacks[k], shifts[k] = on_support(a) * row_scale, c
    for arr in (indices, lower, attacks, shifts):
        arr.setflags(write=False)
    return SecurityIndex(
        indices=indices,
        attacks=attacks,
        shifts=shifts,
        method=method,
        protected=tuple(int(i) for i in prot),
        meters=user.meters,
        seconds=time.perf_counter() - start,
        lower_bounds=lower,
    )


def _milp(
    est: Any,
    k: int,
    prot: np.ndarray,
    c_max: float,
    time_limit: float | None,
    cut: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[tuple[np.ndarray, np.ndarray] | None, float]:
    """The sparsest attack found on state k and the certified lower bound on its size.

    The attack is the best of three verified ones: the attack on every free meter, the big-M
    MILP's (:func:`_big_m`) and the first support of the hitting-set loop that admits one. The
    loop's master (a minimum hitting set of the cuts) is a relaxation of the problem, so its
    optimum is a lower bound; the loop stops when that bound reaches the attack's size or at
    ``time_limit`` (``(None, inf)``: the protected meters shield state k). ``cut``: the min
    cut's attack where the full-measurement theorem makes its size the index: a lower bound
    as well, unless an attack found is sparser (then the theorem's premise fails and it is
    ignored).
    """
    deadline = None if time_limit is None else time.perf_counter() + time_limit
    best = attack_on_state(est, k, prot)
    if best is None:
        return None, np.inf
    first = _big_m(est, k, prot, c_max, None if time_limit is None else time_limit / 2)
    if first is not None and len(support(first[1])) < len(support(best[1])):
        best = first
    upper = len(support(best[1]))
    lower = 1.0
    if cut is not None and len(support(cut[1])) <= upper:
        if len(support(cut[1])) < upper:
            best, upper = cut, len(support(cut[1]))
        lower = float(upper)
    free = np.setdiff1d(np.arange(est.m), prot)
    pos = np.full(est.m, -1)
    pos[free] = np.arange(free.size)
    cuts: set[tuple[int, ...]] = set()
    chosen = np.zeros(0, dtype=np.int64)
    while lower < upper:
        if deadline is not None and time.perf_counter() >= deadline:
            break
        hit = attack_on_state(est, k, np.setdiff1d(np.arange(est.m), chosen))
        if hit is not None and support(hit[1]).size:
            if len(support(hit[1])) < upper:
                best, upper = hit, len(support(hit[1]))
            break  # the master's optimum admits an attack: lower == its size == upper
        cuts.update(_cuts(est, k, prot, np.setdiff1d(free, chosen)))
        masks = [sum(1 << int(pos[i]) for i in cut) for cut in cuts]
        size, found = int(lower), None
        while size < upper:  # the smallest hitting set of the cuts (sizes below lower: none)
            if deadline is not None and time.perf_counter() >= deadline:
                break
            try:
                found = _hitting_set(masks, size, deadline)
            except _OutOfTime:  # sizes below ``size`` are ruled out, ``size`` is not
                break
            if found is not None:
                break
            size += 1
        lower = float(size)
        if size >= upper or found is None:
            break
        chosen = free[[i for i in range(free.size) if found >> i & 1]]
    return best, min(lower, float(upper))


class _OutOfTime(Exception):
    """The hitting-set search reached its deadline."""


def _hitting_set(cuts: list[int], size: int, deadline: float | None = None) -> int | None:
    """A set of at most ``size`` elements (a bitmask) meeting every cut (bitmasks), or None.

    Raises:
        _OutOfTime: At ``deadline`` (a ``time.perf_counter`` value).
    """

    def search(chosen: int, left: list[int], budget: int) -> int | None:
        if deadline is not None and time.perf_counter() >= deadline:
            raise _OutOfTime
        open_ = [c for c in left if not c & chosen]
        if not open_:
            return chosen
        if budget == 0:
            return None
        open_.sort(key=int.bit_count)
        if not open_[0]:
            return None
        used, disjoint = 0, 0
        for c in open_:
            if not c & used:
                used |= c
                disjoint += 1
                if disjoint > budget:
                    return None
        branch = open_[0]
        while branch:
            e = branch & -branch
            branch ^= e
            found = search(chosen | e, open_, budget - 1)
            if found is not None:
                return found
            open_ = [c & ~e for c in open_]  # e is ruled out in the remaining branches
            if not all(open_):
                return None
        return None

    return search(0, list(cuts), size)


def _admits(est: Any, k: int, zero: np.ndarray) -> bool:
    """Whether an attack on state k is zero on the meters ``zero`` (the rank test)."""
    return attack_on_state(est, k, zero) is not None


def _cut(est: Any, k: int, prot: np.ndarray, P: np.ndarray, zfree: np.ndarray) -> np.ndarray | None:
    """Free meters T ⊆ ``zfree`` with no attack on k zero on ``prot ∪ T``, few; None if none.

    Every attack on state k corrupts a meter of T (were T ∪ prot all zero, the rank test
    fails), so ``Σ_{i ∈ T} y_i ≥ 1`` is a valid cut. T is the support of the coefficients
    expressing k's row ``P_k`` of the protected rows' null space in independent rows of
    ``H[zfree] P`` (minimal: those rows are independent), verified by the rank test; where
    rounding makes that fail, all of ``zfree``.
    """
    if _admits(est, k, np.union1d(prot, zfree)):
        return None
    Hr = est.H[zfree] @ P
    _, R, piv = linalg.qr(Hr.T, pivoting=True, mode="economic")
    d = np.abs(np.diag(R))
    rank = int(np.sum(d > max(Hr.shape) * np.finfo(float).eps * (d[0] if d.size else 0.0)))
    basis = piv[:rank]
    lam = np.linalg.lstsq(Hr[basis].T, P[k], rcond=None)[0]
    keep = np.abs(lam) > 1e-12 * float(np.max(np.abs(lam), initial=0.0))
    cut = np.sort(zfree[basis[keep]])
    if cut.size == 0 or _admits(est, k, np.union1d(prot, cut)):
        return zfree
    return cut


def _cuts(est: Any, k: int, prot: np.ndarray, zfree: np.ndarray) -> list[tuple[int, ...]]:
    """Cuts for the zeros ``zfree``, whose rows (with the protected ones) span state k's.

    One cut, one avoiding each of its meters, and disjoint ones in what is left.
    """
    P = null_space(est.H[prot], est.n)
    first = _cut(est, k, prot, P, zfree)
    if first is None:
        return []
    found = [first]
    found += [c for i in first if (c := _cut(est, k, prot, P, zfree[zfree != i])) is not None]
    rest = np.setdiff1d(zfree, first)
    while rest.size and (more := _cut(est, k, prot, P, rest)) is not None:
        found.append(more)
        rest = np.setdiff1d(rest, more)
    return [tuple(int(i) for i in c) for c in found]


def _big_m(
    est: Any, k: int, prot: np.ndarray, c_max: float, time_limit: float | None
) -> tuple[np.ndarray, np.ndarray] | None:
    """A verified attack on state k from the big-M MILP over ``|c_j| ≤ c_max``, or None.

    ``min Σ y`` s.t. ``|(D H c)_i| ≤ M_i y_i``, ``c_k = 1``, ``|c_j| ≤ c_max`` (D scales the
    rows of H to max-abs 1, ``M_i = c_max |(D H)_i|_1``). It only supplies a first attack: its
    support is re-solved by the rank test (:func:`attack_on_state`), and a solve that fails
    (numerically, at ``time_limit``, or because the bound cuts every attack off) gives None.
    """
    m, n = est.m, est.n
    scale = np.max(np.abs(est.H), axis=1, keepdims=True)
    Hn = est.H / np.where(scale == 0.0, 1.0, scale)
    M = c_max * np.sum(np.abs(Hn), axis=1)
    if not np.all(np.isfinite(M)) or np.max(M) >= 1e15:  # beyond HiGHS' numerics
        return None
    A = sparse.bmat([[Hn, -sparse.diags(M)], [-Hn, -sparse.diags(M)]], format="csr")
    cons = optimize.LinearConstraint(A, -np.inf, 0.0)
    lb = np.concatenate([np.full(n, -c_max), np.zeros(m)])
    ub = np.concatenate([np.full(n, c_max), np.ones(m)])
    lb[k] = ub[k] = 1.0
    ub[n + prot] = 0.0
    cost = np.concatenate([np.zeros(n), np.ones(m)])
    integrality = np.concatenate([np.zeros(n), np.ones(m)])
    options: dict[str, Any] = {"mip_rel_gap": 0.0}
    if time_limit is not None:
        options["time_limit"] = time_limit
    res = milp(
        cost,
        constraints=cons,
        integrality=integrality,
        bounds=optimize.Bounds(lb, ub),
        options=options,
    )
    if res.x is None or not np.all(np.isfinite(res.x)):
        return None
    a = Hn @ res.x[:n]
    zero = np.flatnonzero(np.abs(a) <= 1e-7 * max(float(np.max(np.abs(a))), 1e-300))
    return attack_on_state(est, k, np.union1d(zero, prot))


def _cut_is_exact(est: Any) -> bool:
    """Whether 0/1 shifts reach every index: Hendrickx et al.'s full-measurement case.

    A grid model with an injection meter on every bus, a flow meter on every branch and
    positive susceptances (no protected meters: the methods refuse them).
    """
    grid = est.grid
    if grid is None:
        return False
    net = grid.network
    buses = {m.bus for m in grid.meters if m.kind == "injection"}
    branches = {m.branch for m in grid.meters if m.kind != "injection"}
    return len(buses) == net.n_buses and len(branches) == len(net.b) and bool(np.all(net.b > 0))


def _lawler(est: Any, prot: np.ndarray) -> tuple[sparse.csr_matrix, int]:
    """Lawler's graph of the meter hypergraph: buses 0..Nb−1, then (in, out) per meter."""
    rows = est.grid.H_full != 0.0
    m, Nb = rows.shape
    big = m + 1  # more than any cut: stands for infinity
    meter_in, meter_out = Nb + 2 * np.arange(m), Nb + 2 * np.arange(m) + 1
    cap = np.ones(m, dtype=np.int32)
    cap[prot] = big
    j, bus = np.nonzero(rows)
    src = np.concatenate([meter_in, bus, meter_out[j]])
    dst = np.concatenate([meter_out, meter_in[j], bus])
    w = np.concatenate([cap, np.full(2 * j.size, big, dtype=np.int32)])
    size = Nb + 2 * m
    return sparse.csr_matrix((w, (src, dst)), shape=(size, size)), big


def _mincut(
    est: Any, k: int, prot: np.ndarray, graph: tuple[sparse.csr_matrix, int] | None = None
) -> tuple[np.ndarray, np.ndarray] | None:
    from scipy.sparse import csgraph

    C, big = graph if graph is not None else _lawler(est, prot)
    Nb, slack = est.grid.network.n_buses, est.grid.network.slack
    state_bus = np.array([p for p in range(Nb) if p != slack])
    s = int(state_bus[k])
    flow = csgraph.maximum_flow(C, s, slack)
    if flow.flow_value >= big:
        return None
    residual = (C - flow.flow).tocsr()
    residual.data[residual.data < 0] = 0
    residual.eliminate_zeros()
    side = csgraph.breadth_first_order(residual, s, directed=True, return_predecessors=False)
    in_side = np.zeros(C.shape[0], dtype=bool)
    in_side[side] = True
    c = in_side[state_bus].astype(np.float64)
    return c, est.H @ c


def _binary(est: Any, todo: list[int], prot: np.ndarray) -> dict[int, Any]:
    n = est.n
    bits = (np.arange(1, 2**n)[:, None] >> np.arange(n)) & 1
    C = bits.astype(np.float64)
    A = C @ est.H.T
    scale = np.max(np.abs(A), axis=1, keepdims=True)
    nonzero = np.abs(A) > 1e-9 * scale
    cost = nonzero.sum(axis=1).astype(np.float64)
    if prot.size:
        cost[nonzero[:, prot].any(axis=1)] = np.inf
    out: dict[int, Any] = {}
    for k in todo:
        cand = np.where(bits[:, k] == 1, cost, np.inf)
        best = int(np.argmin(cand))
        out[k] = None if not np.isfinite(cand[best]) else (C[best], A[best])
    return out


def _brute(est: Any, todo: list[int], prot: np.ndarray) -> dict[int, Any]:
    free = [i for i in range(est.m) if i not in set(prot.tolist())]
    out: dict[int, Any] = {}
    left = set(todo)
    for size in range(1, len(free) + 1):
        for chosen in itertools.combinations(free, size):
            zero = np.setdiff1d(np.arange(est.m), chosen)
            N = null_space(est.H[zero], est.n)
            if N.shape[1] == 0:
                continue
            for k in [k for k in left if np.linalg.norm(N[k]) > 1e-10]:
                out[k] = attack_on_state(est, k, zero)
                left.discard(k)
            if not left:
                return out
    for k in left:
        out[k] = None
    return out
