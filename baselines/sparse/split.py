"""The split bound: the last step exactly, every earlier drop as a concave first-order term.

Split an attack into the pairs ``D`` of the last step N−1 and the *head* pairs ``H`` of steps
0..N−2. Write ``P̂`` for the no-attack posteriors and ``Y = (P̂⁻_{N−1})⁻¹`` for the information of
the nominal prediction into the last step. Two facts about the filter are used, nothing else
(in particular no submodularity, which does not hold):

1. **Concavity in the prior.** For fixed used information ``J`` the posterior map
   ``P⁻ ↦ ((P⁻)⁻¹ + J)⁻¹`` is operator concave, and Φ = tr or log det is monotone and concave,
   so ``φ_D(P⁻) = Φ(((P⁻)⁻¹ + J_D)⁻¹)`` lies below its tangent at the nominal prediction:

       Φ(H ∪ D) ≤ V(D) + tr(S_D Δ(H)),    Δ(H) = F (P_{N−2}(H) − P̂_{N−2}) F' ⪰ 0,

   with ``V(D)`` the exact value of dropping only ``D`` (nominal prior) and the gradient
   ``S_D = Y P_D Φ'(P_D) P_D Y`` (``Φ' = I`` for trace, ``P_D⁻¹`` for log det), ``P_D`` the
   last posterior of ``D``. ``V(D)`` and ``S_D`` come from one Woodbury downdate per set
   (:func:`baselines.sparse.tail.last_step` is the same algebra), every set of the last step
   enumerated; a set whose downdate ``I − G_DD`` is ill-conditioned (a sensor far more precise
   than the prior: ``1 − G`` cancels) is evaluated from the kept sensors' information, as the
   reference recursion does (:func:`baselines.sparse.tail.downdate_floor`).
2. **The head as a weighted smoother downdate.** ``P_{N−2}(H) − P̂_{N−2} = C_H' (I − G_HH)⁻¹
   C_H`` over the head window (the smoother bound of :mod:`baselines.sparse.bound`), so
   ``tr(W C_H' (I − G_HH)⁻¹ C_H)`` with ``W = F' S_D F`` is at most
   ``Σ_{q∈H} c_q W c_q' / (1 − λ)`` with ``λ ≥ λ_max(G_HH)`` by Weyl (sum of leverages), or the
   same per-pair terms over ``1 − l_q`` and ``1 − ω`` with the block Gershgorin ``ω``; the ``r``
   largest terms bound every head of ``r`` pairs. Dropping every head pair bounds any head in
   the Loewner order (monotonicity), so ``tr(W Δ_all)`` is a bound too; the smallest is used.

**Refinement.** Where these per-pair terms are loose (strongly interacting pairs: meters of
the same bus, the same meter at consecutive steps), the head is split again, recursively: the
drop sets of step N−2 are enumerated exactly (a linear term ``tr(W (P_{D'} − P̂_{N−2}))``), and
steps 0..N−3 enter through the tangent of step N−2's posterior map, with the weight
``F' Y' P_{D'} W P_{D'} Y' F``; the last window step, 0, is enumerated exactly from the fixed
``P[K|K]``. Only branches whose bound could beat the incumbent are refined (the target is the
best last-step set), and before any per-set weight is formed a weight valid for every set of
the step (``Y P_D W P_D Y ⪯ λ_max(P̂⁻^{1/2} W P̂⁻^{1/2}) Y`` since ``P_D ⪯ P̂⁻``) filters them.
Every value computed on the way is a valid bound, so stopping anywhere (deadline) is safe.

Where a last-step enumeration would be too large, ``S_D`` is replaced by a bound that holds for
every ``D`` (``P_D ⪯ P̂⁻`` gives ``tr(S_D Δ) ≤ λ_max(P̂⁻) tr(Y Δ)`` for trace and ``S_D ⪯ Y`` for
log det) and ``V(D)`` by its maximum over the count. The bound is the maximum over the number
of last-step drops ``b``; it is ``inf`` when a count of the last step has more than
:data:`ENUM_LIMIT` sets.

It is tight where the optimum concentrates on the last step and earlier drops are damped by the
process noise (meter-level grids: it proves grid-ieee14's optimum, 204 and 306 pairs, at the
root): the tangent is exact at ``Δ = 0``. The best last-step set with exactly ``c`` pairs is a
feasible attack and is returned as an incumbent.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass
from math import comb

import numpy as np

from baselines.sparse.bound import (
    SAFETY,
    allocation_bound,
    forward,
    measurement_factors,
    pair_terms,
    root_bound,
)
from baselines.sparse.problem import Pair, SparseProblem, make_problem
from baselines.sparse.tail import downdate_floor, well_conditioned
from fdia_env.kalman import objective, predict_cov
from fdia_env.kalman.linalg import mT, spd_inv, sym
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem

# Largest number of last-step sets enumerated for one count b.
ENUM_LIMIT = 1 << 22
# Largest (sets × head pairs × n²) product for per-set head weights; above it, one weight.
WEIGHT_WORK = 1 << 34
# Sets per batch.
CHUNK = 1 << 14
# (weight, set) pairs per batch of the refinement.
PAIR_CHUNK = 1 << 13


@dataclass(frozen=True)
class SplitBound:
    """The split bound of a problem.

    Attributes:
        bound: Upper bound on the optimum (``inf`` where a needed enumeration is too large).
        value: Exact Φ of ``pairs`` (``-inf`` when none).
        pairs: Best attack of exactly ``budget`` pairs at the last step (``None`` when
            ``budget > M`` or the enumeration is too large).
    """

    bound: float
    value: float
    pairs: list[Pair] | None


@dataclass
class _Head:
    """Weight-independent head quantities: ``c_q' c_q`` flattened, leverages, Gershgorin ω_r."""

    outer: np.ndarray  # (L, n²)
    lev: np.ndarray  # (L,)
    comp: np.ndarray  # (L,) 1 − lev without cancellation
    unreliable: np.ndarray  # (L,) pairs without smoother terms (bound.pair_terms)
    floor: float  # smallest trusted denominator 1 − μ (bound.gram_floor)
    omega: np.ndarray  # (r_max + 1,) ω for heads of r pairs
    full: np.ndarray  # (n²,) P_{N−2} with every head pair dropped, minus the nominal
    cross: np.ndarray  # (L, L) normalised off-diagonal norms ‖Ô_qq'‖ (zero diagonal)

    def bound(self, W: np.ndarray, r: int, need: np.ndarray | None = None) -> np.ndarray:
        """(S,) bound on ``tr(W ΔP(H))`` over heads of r pairs, for (S, n, n) weights W.

        The costlier per-pair term (r = 2) is only computed for rows still above ``need``.
        """
        if r == 0:
            return np.zeros(len(W))
        a = np.clip(W.reshape(len(W), -1) @ self.outer.T, 0.0, None)  # (S, L)
        a[:, self.unreliable] = np.inf
        L = a.shape[1]
        k = min(r, L)
        with np.errstate(divide="ignore", invalid="ignore"):
            e = np.where(self.comp > 0.0, a / np.maximum(self.comp, 1e-300), np.inf)
            top_a = -np.partition(-a, k - 1, axis=1)[:, :k].sum(axis=1)
            top_e = -np.partition(-e, k - 1, axis=1)[:, :k].sum(axis=1)
            # 1 − Σ of the k largest leverages: the largest enters by its complement
            order = np.argsort(self.lev)
            slack = self.comp[order[-1]] - self.lev[order[-k:-1]].sum()
            # a denominator below the rounding of G gives no bound (bound.gram_floor)
            weyl = top_a / slack if slack > 0.0 and slack >= self.floor else np.full(len(W), np.inf)
            omega = self.omega[min(r, len(self.omega) - 1)]
            gersh = (
                top_e / (1.0 - omega)
                if 1.0 - omega >= self.floor and omega < 1.0
                else np.full(len(W), np.inf)
            )
        out = np.minimum(weyl, gersh)
        out = np.where(np.isnan(out), np.inf, out)
        # dropping every head pair is a Loewner upper bound on any head (monotonicity)
        out = np.minimum(out, np.clip(W.reshape(len(W), -1) @ self.full, 0.0, None))
        if r == 2 and L >= 2:  # the 2×2 normalised block has λ_max ≤ ‖Ô_qq'‖: per pair
            rows = np.arange(len(W)) if need is None else np.nonzero(out > need)[0]
            if len(rows):
                out[rows] = np.minimum(out[rows], self._pairs(e[rows]))
        return out

    def _pairs(self, e: np.ndarray) -> np.ndarray:
        """(S,) ``max_{q≠q'} (e_q + e_q') / (1 − ‖Ô_qq'‖)`` (inf where the norm is ≥ 1)."""
        L = e.shape[1]
        with np.errstate(divide="ignore"):
            ok = (self.cross < 1.0) & (1.0 - self.cross >= self.floor)
            inv = np.where(ok, 1.0 / np.maximum(1.0 - self.cross, 1e-300), np.inf)
        np.fill_diagonal(inv, 0.0)
        out = np.empty(len(e))
        step = max(1, (1 << 23) // (L * L))
        for lo in range(0, len(e), step):
            x = e[lo : lo + step]
            with np.errstate(invalid="ignore"):
                out[lo : lo + step] = ((x[:, :, None] + x[:, None, :]) * inv).max(axis=(1, 2))
        return np.where(np.isnan(out), np.inf, out)


def _head(problem: SparseProblem, factors: np.ndarray, posts: np.ndarray, end: int) -> _Head:
    """Smoother terms of the window 0..``end`` (drops there, effect on ``P_end``)."""
    head = SparseProblem(problem.system, budget=0, horizon=end + 1, objective="trace")
    terms = pair_terms(head, factors, posts[:, : end + 1], 0, with_cross=True)
    c = terms.vectors[0]  # (L, nz, n)
    outer = np.einsum("lan,lam->lnm", c, c).reshape(len(c), -1)
    r_max = min(problem.budget, len(c))
    cross = terms.cross[0]
    omega = np.zeros(r_max + 1)
    srt = -np.sort(-cross, axis=1)
    for r in range(2, r_max + 1):
        omega[r] = srt[:, : r - 1].sum(axis=1).max()
    every = np.empty_like(posts[:, : end + 1])
    forward(head, every, np.ones((1, end + 1, problem.M), dtype=bool), 0)
    full = (every[0, end] - posts[0, end]).reshape(-1)
    return _Head(
        outer,
        terms.lev[0],
        terms.comp[0],
        terms.unreliable[0],
        float(terms.floor[0]),
        omega,
        full,
        cross,
    )


class _Step:
    """Nominal quantities of step t: posterior, prediction information, Gram of its sensors."""

    def __init__(self, problem: SparseProblem, factors: np.ndarray, posts: np.ndarray, t: int):
        sys = problem.system
        n, M, nz = sys.n, problem.M, factors.shape[2]
        prev = posts[0, t - 1] if t >= 1 else problem.P_start
        self.pred = predict_cov(prev, sys.F, sys.Q)
        np.linalg.cholesky(self.pred)  # LinAlgError when singular: no tangent here
        self.Y = spd_inv(self.pred)
        self.P = posts[0, t]
        U = factors.transpose(1, 0, 2).reshape(n, M * nz)
        self.PU = self.P @ U
        self.G = sym(U.T @ self.PU)
        self.K = sym(mT(self.PU) @ self.PU)  # tr(P_D) − tr(P) = tr((I − G_DD)⁻¹ K_DD)
        self.nz = nz
        self.J = sys.J
        self.floor = float(downdate_floor((self.Y + sys.J.sum(axis=0))[None], self.P[None])[0])

    def _system(self, sets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(S, b·nz) positions of ``sets``' rows and (S, b·nz, b·nz) ``A = I − G_DD``."""
        S, b = sets.shape
        nz = self.nz
        idx = (sets[:, :, None] * nz + np.arange(nz)).reshape(S, b * nz)
        return idx, np.eye(b * nz) - self.G[idx[:, :, None], idx[:, None, :]]

    def _direct(self, sets: np.ndarray) -> np.ndarray:
        """(S, n, n) posteriors of ``sets`` from the information of the kept sensors.

        ``(Y + Σ_{i ∉ D} J_i)⁻¹``: a sum of positive semidefinite terms, the reference
        recursion's arithmetic, exact where the downdate ``A = I − G_DD`` is ill-conditioned.
        """
        keep = np.ones((len(sets), self.J.shape[0]))
        np.put_along_axis(keep, sets, 0.0, axis=1)
        return spd_inv(self.Y + np.einsum("sm,mij->sij", keep, self.J))

    def values(self, sets: np.ndarray, kind: str) -> np.ndarray:
        """(S,) Φ of :meth:`drop`'s posteriors, without forming them where that is exact.

        With ``A = I − G_DD`` (b·nz × b·nz): ``tr P_D = tr P + tr(A⁻¹ K_DD)``, and by the
        matrix determinant lemma ``log det P_D = log det P − log det A`` (``U_D' P U_D =
        G_DD``), as :func:`baselines.sparse.tail.last_step` computes them. Where
        ``λ_min(A)`` is below :func:`baselines.sparse.tail.downdate_floor` the rounding of G
        dominates A (``1 − G`` cancels: a sensor far more precise than the prior), and the
        value is the reference recursion's (:meth:`_direct`).
        """
        base = float(objective(self.P, kind))
        if sets.shape[1] == 0:
            return np.full(len(sets), base)
        idx, A = self._system(sets)
        ok = well_conditioned(A, self.floor)
        out = np.empty(len(sets))
        if ok.any():
            if kind == "trace":
                K = self.K[idx[ok][:, :, None], idx[ok][:, None, :]]
                out[ok] = base + np.trace(np.linalg.solve(A[ok], K), axis1=1, axis2=2)
            else:
                out[ok] = base - np.linalg.slogdet(A[ok])[1]
        if not ok.all():
            out[~ok] = objective(self._direct(sets[~ok]), kind)
        return out

    def drop(self, sets: np.ndarray) -> np.ndarray:
        """(S, n, n) posterior of step t (nominal prior) after dropping each of ``sets``."""
        S, b = sets.shape
        if b == 0:
            return np.broadcast_to(self.P, (S, *self.P.shape)).copy()
        idx, A = self._system(sets)
        ok = well_conditioned(A, self.floor)
        out = np.empty((S, *self.P.shape))
        if ok.any():
            V = self.PU[:, idx[ok]].transpose(1, 0, 2)  # (S, n, b·nz)
            out[ok] = sym(self.P + V @ np.linalg.solve(A[ok], mT(V)))
        if not ok.all():
            out[~ok] = self._direct(sets[~ok])
        return out


class _Split:
    """The split bound's machinery: steps, heads and the recursive refinement."""

    def __init__(self, problem: SparseProblem, factors: np.ndarray, deadline: float | None):
        self.p = problem
        self.factors = factors
        self.deadline = deadline
        N, n = problem.horizon, problem.system.n
        self.posts = np.empty((1, N, n, n))
        forward(problem, self.posts, np.zeros((1, N, problem.M), dtype=bool), 0)
        self.steps: dict[int, _Step] = {}
        self.heads: dict[int, _Head] = {}
        self.units: dict[tuple[int, int], float] = {}

    def step(self, t: int) -> _Step:
        if t not in self.steps:
            self.steps[t] = _Step(self.p, self.factors, self.posts, t)
        return self.steps[t]

    def head(self, end: int) -> _Head:
        if end not in self.heads:
            self.heads[end] = _head(self.p, self.factors, self.posts, end)
        return self.heads[end]

    def unit(self, t: int, r: int) -> float:
        """Bound of r drops in steps 0..t−1 for the weight ``F' Y_t F``.

        ``Y_t`` is step t's prediction information; scaled by κ this bounds the tangent term
        of every set of step t.
        """
        key = (t, r)
        if key not in self.units:
            st, F = self.step(t), self.p.system.F
            W = (mT(F) @ st.Y @ F)[None]
            if t - 1 == 0:
                value = self.window(0, W, r, np.array([-np.inf]), 0)[0]
            else:
                value = self.head(t - 1).bound(W, r)[0]
            self.units[key] = float(value)
        return self.units[key]

    def late(self) -> bool:
        return self.deadline is not None and time.perf_counter() > self.deadline

    def counts(self, t: int, r: int) -> range:
        """Drops at step t (largest first) when r drops go to steps 0..t."""
        return range(min(r, self.p.M), max(0, r - t * self.p.M) - 1, -1)

    def window(self, t: int, W: np.ndarray, r: int, need: np.ndarray, depth: int) -> np.ndarray:
        """(S,) bound on ``max_{|H| = r, H ⊆ steps 0..t} tr(W_s (P_t(H) − P̂_t))``.

        Rows whose cheap bound (smoother terms) is above ``need`` are refined by enumerating
        step t's drop sets and recursing into steps 0..t−1 through the tangent (module
        docstring), while ``depth`` lasts; every value returned is a valid bound.
        """
        S = len(W)
        if r == 0:
            return np.zeros(S)
        M, F = self.p.M, self.p.system.F
        if t == 0:  # one step from the fixed P_start: exact, no tangent
            if comb(M, r) * S > ENUM_LIMIT:
                return np.full(S, np.inf)
            out = np.full(S, -np.inf)
            st = self.step(0)
            for sets in _subsets(M, r):
                X = (st.drop(sets) - st.P).reshape(len(sets), -1)
                out = np.maximum(out, (W.reshape(S, -1) @ X.T).max(axis=1))
            return out
        out = self.head(t).bound(W, r, need)
        rows = np.nonzero(out > need)[0]
        if depth <= 0 or len(rows) == 0 or self.late():
            return out
        try:
            st = self.step(t)
        except np.linalg.LinAlgError:
            return out
        Wr, nr = W[rows], need[rows]
        # A weight valid for every set of this step: Y P_D W P_D Y ⪯ κ Y with
        # κ = λ_max(P̂⁻^{1/2} W P̂⁻^{1/2}) (P_D ⪯ P̂⁻), and every head bound is positively
        # homogeneous in W, so the earlier part of any set is at most κ · u(r − b).
        half = np.linalg.cholesky(st.pred)
        kappa = np.clip(np.linalg.eigvalsh(sym(mT(half) @ Wr @ half))[:, -1], 0.0, None)
        best = np.full(len(rows), -np.inf)
        for b in self.counts(t, r):
            uniform = np.zeros(len(rows))
            if b < r:  # κ = 0: the tangent term vanishes whatever the unit bound (inf · 0)
                uniform = np.where(kappa > 0, kappa * self.unit(t, r - b), 0.0)
            for sets in _subsets(M, b, max(64, PAIR_CHUNK // len(rows))):
                if self.late():
                    return out
                post = st.drop(sets)  # (D, n, n)
                X = (post - st.P).reshape(len(sets), -1)
                lin = Wr.reshape(len(rows), -1) @ X.T  # (rows, D)
                val = lin + uniform[:, None]
                ri, di = np.nonzero(val > nr[:, None]) if b < r else ((), ())
                for lo in range(0, len(ri), PAIR_CHUNK):
                    i, d = ri[lo : lo + PAIR_CHUNK], di[lo : lo + PAIR_CHUNK]
                    # the set's own tangent weight F' Y P_D W P_D Y F
                    A = st.Y @ post[d]  # A' = P_D Y
                    Wn = mT(F) @ (A @ Wr[i] @ mT(A)) @ F
                    inner = self.window(t - 1, Wn, r - b, nr[i] - lin[i, d], depth - 1)
                    val[i, d] = np.minimum(val[i, d], lin[i, d] + inner)
                best = np.maximum(best, val.max(axis=1))
        out[rows] = np.minimum(out[rows], best)
        return out


def split_bound(
    problem: SparseProblem,
    factors: np.ndarray | None = None,
    deadline: float | None = None,
    depth: int = 8,
) -> SplitBound:
    """The split bound of ``problem`` (module docstring) and the best last-step attack.

    Args:
        problem: The instance.
        factors: (M, n, nz) measurement factors (computed when not given).
        deadline: ``time.perf_counter()`` value after which the computation gives up (the
            bound is then ``inf``; the incumbent, found first, is kept).
        depth: Earlier steps the refinement may enumerate below the last one.

    Returns:
        A :class:`SplitBound`; ``bound`` is ``inf`` when a last-step count it needs has more
        than :data:`ENUM_LIMIT` sets, the nominal prediction is singular, or the deadline passed.
    """
    N, M, c = problem.horizon, problem.M, problem.budget
    counts = range(min(c, M), max(0, c - (N - 1) * M) - 1, -1)  # b = c first: the incumbent
    if any(comb(M, b) > ENUM_LIMIT for b in counts):
        return SplitBound(np.inf, -np.inf, None)
    if factors is None:
        factors = measurement_factors(problem)
    work = _Split(problem, factors, deadline)
    try:
        last = work.step(N - 1)
    except np.linalg.LinAlgError:
        return SplitBound(np.inf, -np.inf, None)
    F, n = problem.system.F, problem.system.n
    L = (N - 1) * M
    trace = problem.objective == "trace"
    lam_pred = float(np.linalg.eigvalsh(last.pred)[-1])
    uniform_W = mT(F) @ ((lam_pred * last.Y) if trace else last.Y) @ F

    # b = c first: its best set is the incumbent, the target the refinement tries to beat
    best_value, best_pairs, bound = -np.inf, None, -np.inf
    for b in counts:
        r = c - b
        per_set = r > 0 and comb(M, b) * n * n * L <= WEIGHT_WORK
        count_best = -np.inf
        for sets in _subsets(M, b):
            if work.late():
                return SplitBound(np.inf, best_value, best_pairs)
            if (r == 0 or not per_set) and (not trace or b * last.nz <= n):
                # Φ alone, by b·nz × b·nz algebra: no (n, n) posteriors (for the trace only
                # where that system is no larger than the state, n ≥ b·nz)
                post, values = None, last.values(sets, problem.objective)
            else:
                post = last.drop(sets)
                values = objective(post, problem.objective)
            i = int(np.argmax(values))
            count_best = max(count_best, float(values[i]))
            if r == 0:
                if values[i] > best_value:
                    best_value = float(values[i])
                    best_pairs = [(N - 1, int(s)) for s in sets[i]]
            elif per_set:
                grad = last.Y @ (post @ post if trace else post) @ last.Y
                W = mT(F) @ grad @ F
                tangent = work.window(N - 2, W, r, best_value - values, depth)
                bound = max(bound, float((values + tangent).max()))
        if r == 0:
            bound = max(bound, count_best)
        elif not per_set:
            need = np.array([best_value - count_best])
            bound = max(
                bound, count_best + float(work.window(N - 2, uniform_W[None], r, need, depth)[0])
            )
    if work.late():
        return SplitBound(np.inf, best_value, best_pairs)
    scale = abs(bound) if trace else max(abs(bound), 1.0)
    return SplitBound(bound + SAFETY * scale, best_value, best_pairs)


def _subsets(M: int, b: int, chunk: int = CHUNK):
    """Chunks (≤ ``chunk``, b) of every b-subset of range(M), lexicographic."""
    it = itertools.combinations(range(M), b)
    while True:
        rows = list(itertools.islice(it, max(1, chunk)))
        if not rows:
            return
        yield np.array(rows, dtype=np.intp).reshape(len(rows), b)


def upper_bound(
    system_or_scenario: str | Scenario | LinearSystem,
    budget: int | None = None,
    horizon: int | None = None,
    objective: str = "trace",
) -> float:
    """A provable upper bound on ``max_{|A| = c} Φ(P[K+N|K+N])`` (the EXS optimum).

    The smallest of three bounds: the *smoother bound* and the *allocation bound*
    (:mod:`baselines.sparse.bound`) and the *split bound* (:func:`split_bound`, this module:
    the last step enumerated exactly, earlier drops through a tangent of the posterior map,
    which is concave in the prior). Why they are valid, in short: dropping measurements never
    decreases the filter's covariance in the Loewner order (so the optimum over sets of size c
    is bounded by any relaxation that drops at least as much information, step by step, as
    every feasible set),
    and the final covariance after dropping a set ``T`` is the *exact* covariance downdate
    ``P + C_T'(I − G_T)⁻¹ C_T`` of the batch (smoothing) posterior, whose increase is bounded by
    per-pair terms over ``1 − λ_max``, with ``λ_max`` bounded by Weyl's inequality and the
    block Gershgorin theorem. Submodularity is not assumed (it does not hold). Exact (equal to
    the optimum) when every sensor's information is proportional to one matrix (scalar position
    sensors sharing H).

    Args: as :func:`~baselines.sparse.make_problem` (the instance, c, N and Φ).

    Returns:
        The bound on Φ (trace, or log-determinant).

    Raises:
        ValueError: For a bad budget, horizon, objective or scenario (naming the parameter).

    Example:
        >>> round(upper_bound("ch4-position", budget=5, horizon=6), 4)
        0.0328
    """
    problem = make_problem(system_or_scenario, budget, horizon, objective)
    bounds = [allocation_bound(problem)[0], root_bound(problem)]
    if problem.budget > 0:
        bounds.append(split_bound(problem).bound)
    return min(bounds)
