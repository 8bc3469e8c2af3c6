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
   enumerated.
2. **The head as a weighted smoother downdate.** ``P_{N−2}(H) − P̂_{N−2} = C_H' (I − G_HH)⁻¹
   C_H`` over the head window (the smoother bound of :mod:`baselines.sparse.bound`), so
   ``tr(W C_H' (I − G_HH)⁻¹ C_H)`` with ``W = F' S_D F`` is at most
   ``Σ_{q∈H} c_q W c_q' / (1 − λ)`` with ``λ ≥ λ_max(G_HH)`` by Weyl (sum of leverages), or the
   same per-pair terms over ``1 − l_q`` and ``1 − ω`` with the block Gershgorin ``ω``; the ``r``
   largest terms bound every head of ``r`` pairs. Dropping every head pair bounds any head in
   the Loewner order (monotonicity), so ``tr(W Δ_all)`` is a bound too; the smallest is used.

Where a last-step enumeration would be too large, ``S_D`` is replaced by a bound that holds for
every ``D`` (``P_D ⪯ P̂⁻`` gives ``tr(S_D Δ) ≤ λ_max(P̂⁻) tr(Y Δ)`` for trace and ``S_D ⪯ Y`` for
log det) and ``V(D)`` by its maximum over the count. The bound is the maximum over the number
of last-step drops ``b``; it is finite only when every needed count can be enumerated.

It is tight where the optimum concentrates on the last step and earlier drops are damped by the
process noise (meter-level grids): the tangent is exact at ``Δ = 0``. The best last-step set
with exactly ``c`` pairs is a feasible attack and is returned as an incumbent.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass
from math import comb

import numpy as np

from baselines.sparse.bound import forward, measurement_factors, pair_terms
from baselines.sparse.problem import Pair, SparseProblem
from baselines.sparse.tail import SAFETY
from fdia_env.kalman import objective, predict_cov
from fdia_env.kalman.linalg import mT, spd_inv, sym

# Largest number of last-step sets enumerated for one count b.
ENUM_LIMIT = 1 << 22
# Largest (sets × head pairs × n²) product for per-set head weights; above it, one weight.
WEIGHT_WORK = 1 << 34
# Sets per batch.
CHUNK = 1 << 14


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
    omega: np.ndarray  # (r_max + 1,) ω for heads of r pairs
    full: np.ndarray  # (n²,) P_{N−2} with every head pair dropped, minus the nominal
    cross: np.ndarray  # (L, L) normalised off-diagonal norms ‖Ô_qq'‖ (zero diagonal)

    def bound(self, W: np.ndarray, r: int) -> np.ndarray:
        """(S,) bound on ``tr(W ΔP(H))`` over heads of r pairs, for (S, n, n) weights W."""
        if r == 0:
            return np.zeros(len(W))
        a = np.clip(W.reshape(len(W), -1) @ self.outer.T, 0.0, None)  # (S, L)
        L = a.shape[1]
        k = min(r, L)
        with np.errstate(divide="ignore", invalid="ignore"):
            e = np.where(self.lev < 1.0, a / np.maximum(1.0 - self.lev, 1e-300), np.inf)
            top_a = -np.partition(-a, k - 1, axis=1)[:, :k].sum(axis=1)
            top_e = -np.partition(-e, k - 1, axis=1)[:, :k].sum(axis=1)
            lev_sum = np.sort(self.lev)[-k:].sum()
            weyl = top_a / (1.0 - lev_sum) if lev_sum < 1.0 else np.full(len(W), np.inf)
            omega = self.omega[min(r, len(self.omega) - 1)]
            gersh = top_e / (1.0 - omega) if omega < 1.0 else np.full(len(W), np.inf)
        out = np.minimum(weyl, gersh)
        if r == 2 and L >= 2:  # the 2×2 normalised block has λ_max ≤ ‖Ô_qq'‖: per pair
            out = np.minimum(out, self._pairs(e))
        out = np.where(np.isnan(out), np.inf, out)
        # dropping every head pair is a Loewner upper bound on any head (monotonicity)
        return np.minimum(out, np.clip(W.reshape(len(W), -1) @ self.full, 0.0, None))

    def _pairs(self, e: np.ndarray) -> np.ndarray:
        """(S,) ``max_{q≠q'} (e_q + e_q') / (1 − ‖Ô_qq'‖)`` (inf where the norm is ≥ 1)."""
        L = e.shape[1]
        with np.errstate(divide="ignore"):
            inv = np.where(self.cross < 1.0, 1.0 / np.maximum(1.0 - self.cross, 1e-300), np.inf)
        np.fill_diagonal(inv, 0.0)
        out = np.empty(len(e))
        step = max(1, (1 << 23) // (L * L))
        for lo in range(0, len(e), step):
            x = e[lo : lo + step]
            with np.errstate(invalid="ignore"):
                out[lo : lo + step] = ((x[:, :, None] + x[:, None, :]) * inv).max(axis=(1, 2))
        return np.where(np.isnan(out), np.inf, out)


def _head(problem: SparseProblem, factors: np.ndarray, posts: np.ndarray) -> _Head | None:
    """The head window's smoother terms (``None`` for a one-step window)."""
    N = problem.horizon
    if N < 2:
        return None
    head = SparseProblem(problem.system, budget=0, horizon=N - 1, objective="trace")
    terms = pair_terms(head, factors, posts[:, : N - 1], 0, with_cross=True)
    c = terms.vectors[0]  # (L, nz, n)
    outer = np.einsum("lan,lam->lnm", c, c).reshape(len(c), -1)
    r_max = min(problem.budget, len(c))
    cross = terms.cross[0]
    omega = np.zeros(r_max + 1)
    srt = -np.sort(-cross, axis=1)
    for r in range(2, r_max + 1):
        omega[r] = srt[:, : r - 1].sum(axis=1).max()
    every = np.empty_like(posts[:, : N - 1])
    forward(head, every, np.ones((1, N - 1, problem.M), dtype=bool), 0)
    full = (every[0, N - 2] - posts[0, N - 2]).reshape(-1)
    return _Head(outer, terms.lev[0], omega, full, cross)


def split_bound(
    problem: SparseProblem, factors: np.ndarray | None = None, deadline: float | None = None
) -> SplitBound:
    """The split bound of ``problem`` (module docstring) and the best last-step attack.

    Args:
        problem: The instance.
        factors: (M, n, nz) measurement factors (computed when not given).
        deadline: ``time.perf_counter()`` value after which the computation gives up (the
            bound is then ``inf``; the incumbent, found first, is kept).

    Returns:
        A :class:`SplitBound`; ``bound`` is ``inf`` when a last-step count it needs has more
        than :data:`ENUM_LIMIT` sets, the nominal prediction is singular, or the deadline passed.
    """
    sys, N, M, c = problem.system, problem.horizon, problem.M, problem.budget
    n = sys.n
    counts = range(min(c, M), max(0, c - (N - 1) * M) - 1, -1)  # b = c first: the incumbent
    if any(comb(M, b) > ENUM_LIMIT for b in counts):
        return SplitBound(np.inf, -np.inf, None)
    if factors is None:
        factors = measurement_factors(problem)
    nz = factors.shape[2]
    posts = np.empty((1, N, n, n))
    forward(problem, posts, np.zeros((1, N, M), dtype=bool), 0)
    prev = posts[0, N - 2] if N >= 2 else problem.P_start
    pred = predict_cov(prev, sys.F, sys.Q)
    try:
        np.linalg.cholesky(pred)
    except np.linalg.LinAlgError:
        return SplitBound(np.inf, -np.inf, None)
    Y = spd_inv(pred)
    P = posts[0, N - 1]
    U = factors.transpose(1, 0, 2).reshape(n, M * nz)
    PU = P @ U
    G = sym(U.T @ PU)
    head = _head(problem, factors, posts)
    F = sys.F
    lam_pred = float(np.linalg.eigvalsh(pred)[-1])
    uniform_W = mT(F) @ ((lam_pred * Y) if problem.objective == "trace" else Y) @ F

    best_bound, best_value, best_pairs = -np.inf, -np.inf, None
    for b in counts:
        r = c - b
        per_set = r > 0 and comb(M, b) * n * n * len(head.lev) <= WEIGHT_WORK
        count_best = -np.inf
        for chunk in _subsets(M, b):
            if deadline is not None and time.perf_counter() > deadline:
                return SplitBound(np.inf, best_value, best_pairs)
            values, post = _drop(problem, P, PU, G, chunk, nz)
            if per_set:
                grad = Y @ (post @ post if problem.objective == "trace" else post) @ Y
                values = values + head.bound(mT(F) @ grad @ F, r)
            i = int(np.argmax(values))
            if values[i] > count_best:
                count_best = float(values[i])
                if r == 0:
                    best_value = count_best
                    best_pairs = [(N - 1, int(s)) for s in chunk[i]]
        if r > 0 and not per_set:
            count_best += float(head.bound(uniform_W[None], r)[0])
        best_bound = max(best_bound, count_best)
    scale = abs(best_bound) if problem.objective == "trace" else max(abs(best_bound), 1.0)
    return SplitBound(best_bound + SAFETY * scale, best_value, best_pairs)


def _subsets(M: int, b: int):
    """Chunks (≤ :data:`CHUNK`, b) of every b-subset of range(M), lexicographic."""
    it = itertools.combinations(range(M), b)
    while True:
        rows = list(itertools.islice(it, CHUNK))
        if not rows:
            return
        yield np.array(rows, dtype=np.intp).reshape(len(rows), b)


def _drop(
    problem: SparseProblem,
    P: np.ndarray,
    PU: np.ndarray,
    G: np.ndarray,
    sets: np.ndarray,
    nz: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Φ and the last posterior after dropping each of ``sets`` (S, b) at the last step."""
    S, b = sets.shape
    if b == 0:
        return np.full(S, objective(P, problem.objective)), np.broadcast_to(P, (S, *P.shape))
    idx = (sets[:, :, None] * nz + np.arange(nz)).reshape(S, b * nz)
    A = np.eye(b * nz) - G[idx[:, :, None], idx[:, None, :]]
    V = PU[:, idx].transpose(1, 0, 2)  # (S, n, b·nz)
    post = sym(P + V @ np.linalg.solve(A, mT(V)))
    return objective(post, problem.objective), post
