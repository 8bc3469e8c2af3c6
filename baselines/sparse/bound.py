"""Provable upper bounds on the sparse-attack optimum (docs/math.md §4), for branch and bound.

Two bounds, both valid for any instance; :func:`baselines.sparse.split.upper_bound` returns the
smallest of them and the split bound.

**Smoother (downdate) bound.** The Kalman covariance ``P[K+N|K+N]`` is the marginal covariance
of the final state given every measurement the filter used: filtering and batch (smoothing)
posteriors of a linear Gaussian model coincide. Write ``Σ`` for the joint posterior covariance
of the window's states when the pairs of a base set ``S`` are dropped and every other pair is
used. Dropping more pairs ``T`` is a covariance *downdate* (Woodbury, exact, no information
matrix needed, so a singular Q is fine):

    P_{S∪T} = P_S + C_T' (I − G_T)⁻¹ C_T,    C_T = B_T' Σ e_N,   G_T = B_T' Σ B_T

with ``B_q = H_i' R_i^{-1/2}`` for the pair ``q = (k, i)`` placed at step k. Here ``c_q = B_q'
Σ_{k,N}`` uses the smoothed cross-covariance of ``x_k`` and the final state, and ``G_T`` is the
Gram matrix of the smoothed covariances; ``G_T ≺ I`` always. With ``D`` the block diagonal of
``G_T`` (the leverages ``l_q = λ_max(G_qq) < 1``) and ``Ô = (I − D)^{-1/2} (G_T − D) (I −
D)^{-1/2}`` (zero diagonal blocks), ``(I − G_T)⁻¹ = (I − D)^{-1/2} (I − Ô)⁻¹ (I − D)^{-1/2}``
and ``(I − Ô)⁻¹ ⪯ I / (1 − ω)`` for any ``ω ≥ λ_max(Ô)``, ``ω < 1``; the block Gershgorin
theorem gives ``λ_max(Ô) ≤ max_q Σ_{q'≠q} ‖Ô_qq'‖_F``. Hence

    tr P_{S∪T} − tr P_S ≤ Σ_{q∈T} e_q / (1 − ω_T),    e_q = ‖c_q‖² / (1 − l_q)

(for one scalar measurement this is the exact single-drop increase). Without the cross terms,
``λ_max(G_T) ≤ Σ_{q∈T} l_q`` (Weyl) gives ``Σ ‖c_q‖² / (1 − Σ l_q)`` as well; both are valid,
the smaller is used. For log det, ``log det(P + Z) − log det P ≤ m log(1 + tr(P⁻¹Z)/m)`` for
``rank Z ≤ m`` (Jensen on the eigenvalues), with the same per-pair terms weighted by ``P⁻¹``.
A subtree "base S plus up to r of the free pairs" is bounded by taking the r largest terms.

**Computing ``1 − l_q``.** A measurement far more precise than the prior has ``l_q`` within
rounding of 1, and ``1 − l_q`` formed by subtraction is then the rounding of ``G_qq`` (it can
even come out negative), which the terms divide by: the bound falls below the optimum. So a
leverage above :data:`HIGH_LEVERAGE` takes its complement from the identity ``I − B_q' Σ B_q =
(I + B_q' Σ₋ B_q)⁻¹``, ``Σ₋`` the smoothed covariance without the pair, whose information
(predicted, backward and the other sensors') is a sum of positive semidefinite terms; Weyl's
denominator is ``(1 − l_q) − Σ_{q'≠q} l_q'``, never ``1 − Σ l``. Where the subtraction and the
identity disagree by more than :data:`COMPLEMENT_RTOL`, or the complement is below
:data:`COMPLEMENT_MIN`, ``a_q`` and the Gram entries of q carry the same rounding amplified by
``1/(1 − l_q)``: the pair gets no smoother term (``inf``) and the other bounds decide.
No submodularity is used (it does not hold: dropping the same sensor at consecutive steps is
worth more than the sum of the single drops, see tests/test_bnb.py); the interaction between
dropped pairs is what the ``1/(1 − ω)`` factor covers.

**Allocation (Loewner) bound.** Dropping measurements never decreases P in the Loewner order and
the Riccati map is monotone. Group sensors whose information matrices are proportional,
``J_i = w_i J_g``; any r sensors dropped at one step remove at most
``D(r) = Σ_g (sum of the min(r, |g|) largest w_i of g) J_g`` (Loewner). Propagating the filter
with information ``J_all − D(r_k)`` at each step and maximising over every count allocation
``(r_0, ..., r_{N−1})``, ``Σ r_k ≤ c``, bounds every attack. The information kept,
``J_all − D(r)``, is summed from the weights each group keeps (a difference would cancel where
one sensor dominates). A sensor without information (``J_i = 0``) has weight 0 in any group.
With one group (scalar position sensors sharing H, as in ch4-position and ch4-random) ``D(r)``
is attained by the r largest-information sensors, so the bound *is* the optimum and its argmax
is an optimal set.
"""

from __future__ import annotations

import itertools
import time
from dataclasses import dataclass

import numpy as np

from baselines.sparse.problem import Pair, SparseProblem
from fdia_env.kalman import information_update, objective, predict_cov
from fdia_env.kalman.linalg import mT, spd_inv, sym

# Upper bound on how many Gram entries (rows × T² × M²) one smoother call materialises.
GRAM_ENTRIES = 1 << 22
# Rounding of the Gram matrix ``G = U' P U`` in units of eps·‖Λ‖·‖P‖ (Λ = P⁻¹ the information):
# a backward-stable inverse errs by ``P δΛ P`` with ``‖δΛ‖ ≲ eps ‖Λ‖``, so an entry of G with
# ``G ⪯ I`` errs by at most about ``eps ‖Λ‖ ‖P‖``; the constant covers the few operations.
GRAM_ROUNDING = 64.0
# The tail enumeration (baselines.sparse.tail) is exact in exact arithmetic; its float path
# differs from the reference recursion by a few ulps times the condition number of I − G_DD.
# Tail bounds are raised by this relative amount (of max(|Φ|, 1) for log det) so that rounding
# can never make them invalid.
SAFETY = 1e-9
# Leverage above which ``1 − l_q`` is recomputed from information sums (no cancellation).
HIGH_LEVERAGE = 0.5
# A high-leverage pair's smoother terms are used only where the recomputed ``1 − l_q`` is at
# least COMPLEMENT_MIN and the subtraction ``1 − l_q`` agrees with it to COMPLEMENT_RTOL: the
# disagreement is the rounding of ``G_qq``, which ``a_q`` and the Gram entries share, relative
# to ``1 − l_q``, the factor by which the bound amplifies it. Elsewhere the pair's terms are
# ``inf`` (a valid bound; the other bounds of branch and bound take over).
COMPLEMENT_MIN = 1e-6
COMPLEMENT_RTOL = 1e-6


def measurement_factors(problem: SparseProblem) -> np.ndarray:
    """(M, n, nz_max) ``B_i = H_i' L_i`` with ``L_i L_i' = R_i⁻¹`` (so ``B_i B_i' = J_i``).

    Sensors with fewer measurement rows than ``nz_max`` are padded with zero columns (they add
    zero eigenvalues, which changes no bound).
    """
    sensors = problem.system.sensors
    nz = max(s.dim for s in sensors)
    out = np.zeros((len(sensors), problem.system.n, nz))
    for i, s in enumerate(sensors):
        L = np.linalg.cholesky(np.linalg.inv(s.R))
        out[i, :, : s.dim] = s.H.T @ L
    return out


# --- filter passes on batches of nodes ------------------------------------------------------


def forward(
    problem: SparseProblem, posts: np.ndarray, attacked: np.ndarray, start: int
) -> np.ndarray:
    """Posteriors ``P[k|k]`` from step ``start`` on, in place of ``posts[:, start:]``.

    Args:
        problem: The instance.
        posts: (R, N, n, n) posteriors; ``posts[:, start − 1]`` (or ``P_start`` for
            ``start = 0``) is the state the pass starts from. Overwritten from ``start`` on.
        attacked: (R, N, M) attacked masks.
        start: First step to recompute.

    Returns:
        ``posts`` (the same array).
    """
    sys = problem.system
    P = posts[:, start - 1] if start > 0 else np.broadcast_to(problem.P_start, posts[:, 0].shape)
    for k in range(start, problem.horizon):
        P = information_update(predict_cov(P, sys.F, sys.Q), sys.J, ~attacked[:, k])
        posts[:, k] = P
    return posts


def final_value(
    problem: SparseProblem, prior: np.ndarray, attacked: np.ndarray, start: int
) -> np.ndarray:
    """(R,) Φ(P[N−1|N−1]) running steps ``start..N−1`` from the (R, n, n) ``prior`` state."""
    sys = problem.system
    P = prior
    for k in range(start, problem.horizon):
        P = information_update(predict_cov(P, sys.F, sys.Q), sys.J, ~attacked[:, k])
    return objective(P, problem.objective)


@dataclass
class PairTerms:
    """Per-pair bound terms of a batch of nodes over the tail steps ``start..N−1``.

    Attributes:
        start: First tail step t; pair ``(k, i)`` is column ``(k − t)·M + i``.
        base: (R,) Φ of the node's base set (every other pair used).
        a: (R, T·M) ``‖c_q‖²`` (trace) or ``tr(P⁻¹ c_q' c_q)`` (log det).
        lev: (R, T·M) leverages ``l_q = λ_max(B_q' Σ_kk B_q)``.
        comp: (R, T·M) their complements ``1 − l_q`` (for a leverage above
            :data:`HIGH_LEVERAGE` computed without cancellation, see :func:`_complements`).
        e: (R, T·M) ``a_q / (1 − l_q)``.
        cross: (R, T·M, T·M) ``‖Ô_qq'‖_F`` (zero on the diagonal), or None when not computed.
        vectors: (R, T·M, nz, n) the ``c_q`` themselves (trace objective only, else None).
        unreliable: (R, T·M) pairs whose terms are rounding, not value (``a``, ``e`` and
            their ``cross`` entries are ``inf`` there; see :data:`COMPLEMENT_MIN`).
        floor: (R,) smallest trusted denominator ``1 − μ`` (:func:`gram_floor`).
    """

    start: int
    base: np.ndarray
    a: np.ndarray
    lev: np.ndarray
    comp: np.ndarray
    e: np.ndarray
    cross: np.ndarray | None
    vectors: np.ndarray | None = None
    unreliable: np.ndarray | None = None
    floor: np.ndarray | None = None


def pair_terms(
    problem: SparseProblem,
    factors: np.ndarray,
    posts: np.ndarray,
    start: int,
    with_cross: bool = True,
    attacked: np.ndarray | None = None,
) -> PairTerms:
    """Smoother quantities of the bound for every pair at steps ``start..N−1`` (batched RTS).

    ``Σ_{k,l}`` (smoothed covariance of ``x_k, x_l`` given all used measurements) follows the
    Rauch–Tung–Striebel recursion ``Σ_kk = P_k + A_k (Σ_{k+1,k+1} − P_{k+1|k}) A_k'``,
    ``Σ_{k,l} = A_k Σ_{k+1,l}``, ``A_k = P_k F' P_{k+1|k}⁻¹``, ``Σ_{N−1,N−1} = P_{N−1}``.
    """
    sys = problem.system
    N, M = problem.horizon, problem.M
    T = N - start
    R_, n = posts.shape[0], sys.n
    X = np.empty((R_, T, T, n, n))  # X[:, a, b] = Σ_{start+a, start+b}
    X[:, T - 1, T - 1] = posts[:, N - 1]
    gains = np.empty((R_, T, n, n))  # gains[:, a] = A_{start+a}
    for a in range(T - 2, -1, -1):
        k = start + a
        Pk = posts[:, k]
        pred = predict_cov(Pk, sys.F, sys.Q)
        A = Pk @ sys.F.T @ spd_inv(pred)
        gains[:, a] = A
        X[:, a, a] = sym(Pk + A @ (X[:, a + 1, a + 1] - pred) @ mT(A))
        for b in range(a + 1, T):
            X[:, a, b] = A @ X[:, a + 1, b]
            X[:, b, a] = mT(X[:, a, b])
    P_fin = posts[:, N - 1]
    base = objective(P_fin, problem.objective)
    C = X[:, :, T - 1]  # (R, T, n, n) Σ_{k, N−1}
    if problem.objective == "logdet":
        # tr(P⁻¹ c' c) = ‖c L⁻ᵀ‖² with P = L L'
        L = np.linalg.cholesky(P_fin)
        C = mT(np.linalg.solve(L[:, None], mT(C)))  # C L⁻ᵀ
    c = np.einsum("ina,rtnp->rtiap", factors, C)  # (R, T, M, nz, n) c_q = B_i' Σ_{k,N−1}
    a_term = (c**2).sum(axis=(-1, -2)).reshape(R_, T * M)
    diag = np.einsum("ina,rtnp,ipb->rtiab", factors, X[:, np.arange(T), np.arange(T)], factors)
    if diag.shape[-1] == 1:
        lev = diag[..., 0, 0]
    else:
        lev = np.linalg.eigvalsh(sym(diag))[..., -1]
    lev = np.clip(lev.reshape(R_, T * M), 0.0, None)
    comp = np.clip(1.0 - lev, 0.0, None)
    high = lev > HIGH_LEVERAGE
    unreliable = np.zeros_like(high)
    if high.any():
        exact = _complements(problem, factors, posts, start, attacked, high)
        # the subtraction's error is the rounding of G along B_q, which a_q and the Gram
        # entries carry as well: where it is not small against 1 − l_q, no smoother term
        unreliable[high] = (exact < COMPLEMENT_MIN) | (
            np.abs(comp[high] - exact) > COMPLEMENT_RTOL * exact
        )
        comp[high] = exact
        lev[high] = 1.0 - exact
    a_term = np.where(unreliable, np.inf, a_term)
    with np.errstate(divide="ignore"):
        e = np.where(comp > 0.0, a_term / np.maximum(comp, 1e-300), np.inf)
    cross = None
    if with_cross:
        scale = 1.0 / np.sqrt(np.maximum(comp, 1e-300))  # (R, T·M)
        cross = np.empty((R_, T * M, T * M))
        for a in range(T):
            # G[(a, i), (b, j)] = B_i' Σ_ab B_j for every b, i, j
            G = np.einsum("ina,rbnp,jpc->ribjac", factors, X[:, a], factors)
            norm = np.sqrt((G**2).sum(axis=(-1, -2))).reshape(R_, M, T * M)
            cross[:, a * M : (a + 1) * M] = norm
        cross *= scale[:, :, None] * scale[:, None, :]
        cross = np.where(unreliable[:, :, None] | unreliable[:, None, :], np.inf, cross)
        idx = np.arange(T * M)
        cross[:, idx, idx] = 0.0
    vectors = c.reshape(R_, T * M, *c.shape[-2:]) if problem.objective == "trace" else None
    floor = gram_floor(posts[:, start:])
    return PairTerms(start, base, a_term, lev, comp, e, cross, vectors, unreliable, floor)


def gram_floor(posts: np.ndarray) -> np.ndarray:
    """(R,) smallest denominator ``1 − μ`` (or ``1 − ω``) the bounds divide by, per row.

    The Gram entries carry a rounding of about ``GRAM_ROUNDING · eps · κ`` (κ the condition
    number of the (R, T, n, n) posteriors, the largest over the steps); a denominator below
    that over :data:`SAFETY` would let the rounding, amplified by its
    inverse, exceed the safety margin, so the bound is ``inf`` there (valid, uninformative).
    """
    w = np.linalg.eigvalsh(posts)
    with np.errstate(divide="ignore", invalid="ignore"):
        kappa = np.where(w[..., 0] > 0.0, w[..., -1] / w[..., 0], np.inf)
    kappa = kappa.reshape(len(posts), -1).max(axis=1)

    return GRAM_ROUNDING * np.finfo(float).eps * kappa / SAFETY


def _complements(
    problem: SparseProblem,
    factors: np.ndarray,
    posts: np.ndarray,
    start: int,
    attacked: np.ndarray | None,
    high: np.ndarray,
) -> np.ndarray:
    """``1 − l_q`` of the pairs flagged ``high``, without the cancellation of ``1 − l_q``.

    ``I − B_q' Σ_kk B_q = (I + B_q' Σ⁻_kk B_q)⁻¹`` (Woodbury), with ``Σ⁻_kk`` the smoothed
    covariance of ``x_k`` without the pair q: the inverse of the information ``Y_k + Ω_k +
    Σ_{j used at k, j ≠ i} J_j``, built as a sum of positive semidefinite terms (``Y_k`` the
    filter's predicted information, ``Ω_k`` the backward information of steps k+1..N−1).
    So ``1 − l_q = 1 / (1 + λ_max(B_q' Σ⁻_kk B_q))``. Returns the values in ``high``'s order.
    """
    sys = problem.system
    N, M, n = problem.horizon, problem.M, sys.n
    T = N - start
    R_ = posts.shape[0]
    J_all = sys.J.sum(axis=0)
    omega = np.zeros((R_, T, n, n))  # Ω_{start+a}: information of the later measurements
    eye = np.eye(n)
    for a in range(T - 2, -1, -1):
        lam = omega[:, a + 1] + J_all  # every pair after the node's step is used
        omega[:, a] = sym(mT(sys.F) @ np.linalg.solve(eye + lam @ sys.Q, lam) @ sys.F)
    rows, flat = np.nonzero(high)
    steps, sensors = flat // M, flat % M
    k = start + steps
    prev = np.where(
        (k > 0)[:, None, None], posts[rows, np.maximum(k - 1, 0)], problem.P_start[None]
    )
    info = spd_inv(predict_cov(prev, sys.F, sys.Q)) + omega[rows, steps]
    used = np.ones((len(rows), M))
    if attacked is not None:
        used = (~attacked[rows, k]).astype(float)
    used[np.arange(len(rows)), sensors] = 0.0
    Sm = spd_inv(info + np.einsum("qm,mij->qij", used, sys.J))
    B = factors[sensors]  # (Q, n, nz)
    g = sym(mT(B) @ Sm @ B)
    top = g[:, 0, 0] if g.shape[-1] == 1 else np.linalg.eigvalsh(g)[:, -1]
    return 1.0 / (1.0 + np.clip(top, 0.0, None))


# --- combining terms into subtree bounds ---------------------------------------------------


def suffix_top_sums(x: np.ndarray, r: int) -> np.ndarray:
    """(R, L + 1): entry j is the sum of the r largest of ``x[:, j:]`` (fewer if fewer remain).

    ``-inf`` entries count as absent.
    """
    R_, L = x.shape
    out = np.zeros((R_, L + 1))
    if r <= 0:
        return out
    top = np.full((R_, r), -np.inf)  # ascending
    for j in range(L - 1, -1, -1):
        col = x[:, j : j + 1]
        top = np.sort(np.concatenate([top, col], axis=1), axis=1)[:, 1:]
        out[:, j] = np.where(np.isfinite(top), top, 0.0).sum(axis=1)
        out[:, j] = np.where(np.isposinf(top).any(axis=1), np.inf, out[:, j])
    return out


def increase_bound(
    objective_name: str,
    total: np.ndarray,
    mu: np.ndarray,
    m: int,
    slack: np.ndarray | None = None,
) -> np.ndarray:
    """``total / (1 − μ)`` (trace) or ``m log(1 + total / (m (1 − μ)))`` (log det); inf if μ ≥ 1.

    ``slack``, when given, is ``1 − μ`` computed without cancellation (and used instead).
    """
    if slack is None:
        slack = 1.0 - mu
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        scaled = np.where(slack > 0.0, total / np.maximum(slack, 1e-300), np.inf)
        if objective_name == "trace":
            out = scaled
        else:
            out = m * np.log1p(scaled / m)
    return np.where(np.isnan(out), np.inf, out)


def child_bounds(
    problem: SparseProblem, terms: PairTerms, first_free: np.ndarray, remaining: int, nz_max: int
) -> np.ndarray:
    """(R, T·M) bound on every completion of "node + pair q + up to ``remaining`` later pairs".

    Column q is the pair at flat index ``start·M + q``; entries that are not free (before
    ``first_free``) or leave too few pairs for ``remaining`` are ``-inf``.

    Args:
        problem: The instance.
        terms: The node batch's :class:`PairTerms`.
        first_free: (R,) first free flat pair index of each node.
        remaining: Pairs still to add after q.
        nz_max: Largest measurement size (for the rank of the log-det increase).
    """
    R_, L = terms.a.shape
    offset = terms.start * problem.M
    cols = offset + np.arange(L)
    free = cols[None, :] >= first_free[:, None]
    feasible = free & (cols[None, :] <= problem.size - 1 - remaining)
    a = np.where(free, terms.a, -np.inf)
    lev = np.where(free, terms.lev, -np.inf)
    e = np.where(free, terms.e, -np.inf)
    m = min(problem.system.n, (remaining + 1) * nz_max)
    # Weyl: λ_max(G_T) ≤ Σ l_q
    tot_a = terms.a + suffix_top_sums(a, remaining)[:, 1:]
    # 1 − μ as comp_q − Σ l (the complement of q's own leverage without cancellation)
    slack = terms.comp - suffix_top_sums(lev, remaining)[:, 1:]
    floor = terms.floor[:, None]
    slack = np.where(slack >= floor, slack, 0.0)  # below the rounding of G: no bound
    inc = increase_bound(problem.objective, tot_a, 1.0 - slack, m, slack)
    tot_e = terms.e + suffix_top_sums(e, remaining)[:, 1:]
    if remaining == 0:
        inc = np.minimum(inc, increase_bound(problem.objective, tot_e, np.zeros_like(slack), m))
    elif terms.cross is not None:
        # Gershgorin on the normalised off-diagonal: row q sums its r largest entries over the
        # free columns; ω(p) is the largest such row sum over the candidates q ≥ p.
        cross = np.where(free[:, None, :], terms.cross, 0.0)
        k = min(remaining, L - 1)
        rows = -np.sort(-cross, axis=2)[:, :, :k].sum(axis=2) if k > 0 else np.zeros((R_, L))
        rows = np.where(free, rows, -np.inf)
        omega = np.maximum.accumulate(rows[:, ::-1], axis=1)[:, ::-1]
        omega = np.where(1.0 - omega >= floor, omega, np.inf)
        inc = np.minimum(inc, increase_bound(problem.objective, tot_e, omega, m))
    out = terms.base[:, None] + inc
    return np.where(feasible, out, -np.inf)


# --- the allocation bound -------------------------------------------------------------------


def unit_information(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each sensor's information split as ``J_i = w_i U_i``: ``(U, w)``, ``w_i = tr J_i``.

    ``U_i`` has unit trace; a sensor that carries no information (``J_i = 0``: a zero row of H,
    or an R so large that ``H' R⁻¹ H`` underflows) has ``w_i = 0`` and ``U_i = 0``. It never
    matters to any attack, and no division by its zero trace happens.
    """
    w = np.trace(J, axis1=1, axis2=2)
    positive = w > 0.0
    unit = np.zeros_like(J)
    unit[positive] = J[positive] / w[positive, None, None]
    return unit, np.where(positive, w, 0.0)


def information_groups(J: np.ndarray, rtol: float = 1e-9) -> list[tuple[np.ndarray, np.ndarray]]:
    """Sensors whose information matrices are proportional: ``[(indices, weights), ...]``.

    Within a group ``J_i = w_i U_g`` with ``U_g`` the group's first unit-trace matrix
    (:func:`unit_information`); weights are returned sorted descending with their indices.
    Sensors without information (``w_i = 0``) join the first group with weight 0 (``0 = 0·U_g``
    for any g), so they never split a group that is otherwise one. One pass over the sensors:
    each joins the first group whose matrix it matches, or opens a new one.
    """
    unit, weight = unit_information(J)
    members: list[list[int]] = []
    empty = []
    for i in range(J.shape[0]):
        if weight[i] == 0.0:
            empty.append(i)
            continue
        for group in members:
            g = group[0]
            if np.abs(unit[i] - unit[g]).max() <= rtol * np.abs(unit[g]).max():
                group.append(i)
                break
        else:
            members.append([i])
    if not members:  # no sensor carries information: one group of weight-0 sensors
        members.append([])
    members[0] += empty
    groups = []
    for group in members:
        w = weight[group]
        order = np.argsort(-w, kind="stable")
        groups.append((np.asarray(group)[order], w[order]))
    return groups


def allocation_bound(
    problem: SparseProblem, deadline: float | None = None
) -> tuple[float, list[Pair] | None]:
    """The Loewner allocation bound and, when it is attained (one group), an optimal set.

    Args:
        problem: The instance.
        deadline: ``time.perf_counter()`` value after which the recursion gives up (checked at
            every step): the bound is then ``inf`` (valid, uninformative) and no set is given.

    Returns:
        ``(bound, pairs)``: ``pairs`` has exactly ``budget`` pairs and value equal to the bound
        when every sensor's information is proportional to one matrix, else ``None``.
    """
    sys, N, c = problem.system, problem.horizon, problem.budget
    groups = information_groups(sys.J)
    unit = unit_information(sys.J)[0]
    cap = min(c, max(len(idx) for idx, _ in groups))
    # information used with r dropped at a step, J_all − D(r): summed from the weights each
    # group keeps (a difference of the two would cancel where one sensor dominates)
    info = np.zeros((cap + 1, sys.n, sys.n))
    for r in range(cap + 1):
        for idx, w in groups:
            info[r] += w[min(r, len(idx)) :].sum() * unit[idx[0]]
    if len(groups) == 1:  # attained: sum what is left, as the reference recursion does
        order = groups[0][0]
        info = np.stack([sys.J[np.sort(order[r:])].sum(axis=0) for r in range(cap + 1)])
    states = problem.P_start[None]
    spent = np.zeros(1, dtype=int)
    history = np.zeros((1, 0), dtype=int)
    for _ in range(N):
        if deadline is not None and time.perf_counter() > deadline:
            return np.inf, None
        Y = spd_inv(predict_cov(states, sys.F, sys.Q))
        rs = np.arange(cap + 1)
        parent, r = np.meshgrid(np.arange(len(states)), rs, indexing="ij")
        parent, r = parent.ravel(), r.ravel()
        keep = spent[parent] + r <= c
        parent, r = parent[keep], r[keep]
        states = spd_inv(Y[parent] + info[r])
        spent = spent[parent] + r
        history = np.concatenate([history[parent], r[:, None]], axis=1)
    values = objective(states, problem.objective)
    best = int(np.argmax(values))
    bound = float(values[best])
    if len(groups) != 1:
        return bound, None
    order = groups[0][0]
    pairs = [(k, int(i)) for k in range(N) for i in order[: history[best, k]]]
    extra = [p for p in problem.pairs() if p not in set(pairs)]
    pairs += extra[: c - len(pairs)]  # attacking more never lowers Φ
    return bound, pairs


# --- public ---------------------------------------------------------------------------------


def root_bound(problem: SparseProblem) -> float:
    """The smoother bound at the root (no pair fixed): max over first pairs of child bounds."""
    if problem.budget == 0:
        return problem.evaluate([])
    factors = measurement_factors(problem)
    posts = np.empty((1, problem.horizon, problem.system.n, problem.system.n))
    forward(problem, posts, np.zeros((1, problem.horizon, problem.M), dtype=bool), 0)
    with_cross = problem.size**2 * problem.system.n <= GRAM_ENTRIES * 4
    terms = pair_terms(problem, factors, posts, 0, with_cross=with_cross)
    first = np.zeros(1, dtype=int)
    bounds = child_bounds(problem, terms, first, problem.budget - 1, factors.shape[2])
    return float(bounds.max())


def brute_force_optimum(
    problem: SparseProblem, base: list[Pair], free: list[Pair], r: int
) -> float:
    """Largest Φ over ``base`` plus exactly ``r`` pairs of ``free`` (enumeration; debug only)."""
    sets = [base + list(extra) for extra in itertools.combinations(free, r)]
    if not sets:
        return -np.inf
    return float(problem.evaluate_masks(problem.masks(sets)).max())
