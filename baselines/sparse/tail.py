"""The mixed (tail-enumeration) bound: exact at the last two steps, Loewner-relaxed before.

Notation: ``P_k`` the posterior after step k, ``Y`` information matrices, ``J_i = B_i B_i'``.
Only one fact about the filter is used: the recursion ``P⁺ = ((F P F' + Q)⁻¹ + J)⁻¹`` is
monotone in P and antitone in the information J used at the step (Loewner order), and Φ = tr or
log det is monotone. No submodularity is assumed.

**Exact tail.** With the posterior before step t ∈ {N−2, N−1} fixed, the best completion that
drops ``s`` of the free pairs of steps t..N−1 is found by enumeration. At the last step every
candidate set ``D`` is a Woodbury downdate of the posterior ``P`` that uses every free pair:
``(Y − U_D U_D')⁻¹ = P + P U_D (I − G_DD)⁻¹ U_D' P`` with ``G = U' P U``, so

    tr P_D = tr P + tr((I − G_DD)⁻¹ K_DD),  K = U' P² U,
    log det P_D = log det P − log det(I − G_DD),

small ``(s·nz)``-square problems built from one ``(M·nz)``-square matrix per posterior. Where
``λ_min(I − G_DD)`` is below the rounding of G over :data:`SAFETY` (:func:`downdate_floor`: a
sensor far more precise than the prior, ``1 − G`` cancels) the set is evaluated from the kept
sensors' information instead, ``(Y + Σ_{i ∉ D} J_i)⁻¹``, the reference recursion's arithmetic;
information is only ever summed, never differenced. At step
N−2 every subset of the free sensors is enumerated explicitly (one inversion each), then the last
step as above. This is the exact maximum (up to rounding, see :data:`SAFETY`).

**Relaxed head, table of tails.** Let ``V(P, b)`` be the exact best value of the last two steps
from the posterior ``P`` at step N−3 with ``b`` drops among all their pairs. ``V`` is monotone in
P: each completion's value is a composition of monotone maps of P, and a maximum of monotone
functions is monotone. Fix a reference ``P̂`` (the no-attack posterior at N−3) and a direction
``W = F P̂ F' + Q ≻ 0``. For any ``P`` with ``P ⪯ P̂ + σ W`` we have ``V(P, b) ≤ V(P̂ + σ W, b)``;
the smallest such σ is ``λ_max(W^{-1/2} (P − P̂) W^{-1/2})`` (or 0). :class:`TailTable` stores
``V(P̂ + σ_j W, ·)`` on a geometric grid σ_j, computed on demand, and answers with the grid
point at or above σ (so the answer is a valid upper bound, never an interpolation).

For a node whose next pair is at step k ≤ N−3 and an allocation ``(e_k, r_{k+1}, ..., r_{N−3})``
of drops to the head steps, ``b`` drops being left for the tail: the information kept at a head
step with ``r`` drops is at least ``J_all − D(r)`` (``D(r)`` the Loewner upper bound of the
allocation bound, :func:`baselines.sparse.bound.information_groups`), restricted to the free
sensors at step k. Running the recursion with that information from the node's exact posterior
gives ``P̄_{N−3}`` ⪰ the posterior of every completion with this allocation (monotonicity, step
by step), so ``V(P̄_{N−3}, b) ≤`` table value. The subtree bound is the maximum over all
allocations (``Σ ≤`` the remaining budget; attacking more never lowers Φ).
"""

from __future__ import annotations

import itertools
from functools import cache
from math import comb

import numpy as np

from baselines.sparse.bound import GRAM_ROUNDING, SAFETY, unit_information
from baselines.sparse.problem import SparseProblem
from fdia_env.kalman import objective, predict_cov
from fdia_env.kalman.linalg import mT, spd_inv, sym

# Largest number of (row, subset) small problems materialised at once.
CHUNK = 1 << 15
# Grid of the table: σ_j = SIGMA_0 · SIGMA_RATIO^j, j = 0..; σ beyond the last point: no bound.
SIGMA_0 = 1e-3
SIGMA_RATIO = 2.0
SIGMA_MAX = 1e3


@cache
def combos(M: int, s: int) -> np.ndarray:
    """(C(M, s), s) every s-subset of range(M), lexicographic."""
    out = np.array(list(itertools.combinations(range(M), s)), dtype=np.intp)
    return out.reshape(max(len(out), 1), s)


def enumeration_size(M: int, r: int) -> int:
    """Small problems of one exact two-step tail from one posterior with budget r."""
    ones = [comb(M, s) for s in range(r + 1)]
    return sum(ones[a] * sum(ones[: r - a + 1]) for a in range(r + 1))


def _valid(free: np.ndarray, sets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(row, set) index pairs with every sensor of the set free in the row (row blocks)."""
    block = max(1, (1 << 22) // max(sets.size, 1))
    rows, cols = [], []
    for lo in range(0, len(free), block):
        r, c = np.nonzero(free[lo : lo + block][:, sets].all(axis=2))
        rows.append(r + lo)
        cols.append(c)
    return np.concatenate(rows), np.concatenate(cols)


def _raise(problem: SparseProblem, values: np.ndarray) -> np.ndarray:
    scale = np.abs(values) if problem.objective == "trace" else np.maximum(np.abs(values), 1.0)
    with np.errstate(invalid="ignore"):
        return np.where(np.isfinite(values), values + SAFETY * scale, values)


def downdate_floor(info: np.ndarray, P: np.ndarray) -> np.ndarray:
    """(R,) smallest ``λ_min(I − G_DD)`` for which the Woodbury downdate is trusted.

    A downdate whose ``λ_min(A)``, ``A = I − G_DD``, is below the rounding of G divided by
    :data:`SAFETY` loses more than the safety margin to cancellation in ``1 − G`` (a sensor
    far more precise than the prior); such sets are evaluated from the kept sensors'
    information instead, as the reference recursion does. ``info`` and ``P`` are (R, n, n)
    information matrices and their inverses.
    """
    norm = np.linalg.norm(info, axis=(-2, -1)) * np.linalg.norm(P, axis=(-2, -1))
    return GRAM_ROUNDING * np.finfo(float).eps * norm / SAFETY


def well_conditioned(A: np.ndarray, floor: np.ndarray | float) -> np.ndarray:
    """(S,) whether ``λ_min(A) >= floor`` for the (S, d, d) symmetric ``A`` (per-row floor)."""
    floor = np.broadcast_to(np.asarray(floor, dtype=float), A.shape[:1])
    if A.shape[-1] == 1:
        return A[:, 0, 0] >= floor
    eye = np.eye(A.shape[-1])
    try:  # the common case: every set passes, one batched Cholesky says so
        np.linalg.cholesky(A - floor[:, None, None] * eye)
        return np.ones(len(A), dtype=bool)
    except np.linalg.LinAlgError:
        return np.linalg.eigvalsh(sym(A))[:, 0] >= floor


def _information(
    problem: SparseProblem, prev: np.ndarray, fixed_info: np.ndarray, free: np.ndarray
) -> np.ndarray:
    """(R, n, n) information at a step with every free sensor used, before any drop.

    The prior predicted from the posterior ``prev``, plus ``fixed_info`` (the decided, used
    sensors) and the information of the sensors still ``free``.
    """
    return _prior_information(problem, prev, fixed_info) + _kept(problem, free)


def _prior_information(
    problem: SparseProblem, prev: np.ndarray, fixed_info: np.ndarray
) -> np.ndarray:
    """(R, n, n) predicted information from ``prev`` plus the decided, used sensors'."""
    sys = problem.system
    return spd_inv(predict_cov(prev, sys.F, sys.Q)) + fixed_info


def _kept(problem: SparseProblem, keep: np.ndarray) -> np.ndarray:
    """(R, n, n) ``Σ_{i kept} J_i`` for (R, M) booleans: a sum, never a difference."""
    return np.einsum("rm,mij->rij", keep.astype(float), problem.system.J)


def _without(free: np.ndarray, sets: np.ndarray) -> np.ndarray:
    """(R, M) ``free`` rows with the sensors of the matching (R, s) ``sets`` rows removed."""
    keep = free.copy()
    np.put_along_axis(keep, sets, False, axis=1)
    return keep


def last_step(
    problem: SparseProblem,
    factors: np.ndarray,
    prev: np.ndarray,
    fixed_info: np.ndarray,
    free: np.ndarray,
    r: int,
) -> np.ndarray:
    """(R, r + 1): entry s is the best Φ after the last step dropping exactly s free sensors.

    Args:
        problem: The instance.
        factors: (M, n, nz) ``B_i`` with ``B_i B_i' = J_i``.
        prev: (R, n, n) posterior before the last step.
        fixed_info: (R, n, n) information of the decided, used sensors at the last step.
        free: (R, M) sensors still free at the last step.
        r: Largest number of drops.

    Returns:
        Values (not raised by :data:`SAFETY`); ``-inf`` where fewer than s sensors are free.
    """
    sys = problem.system
    R_, M = free.shape
    nz = factors.shape[2]
    prior = _prior_information(problem, prev, fixed_info)
    info = prior + _kept(problem, free)
    P = spd_inv(info)
    floor = downdate_floor(info, P)
    U = factors.transpose(1, 0, 2).reshape(sys.n, M * nz)  # (n, M·nz)
    PU = P @ U  # (R, n, M·nz)
    G = sym(U.T @ PU)  # (R, M·nz, M·nz)
    K = sym(mT(PU) @ PU) if problem.objective == "trace" else None
    base = objective(P, problem.objective)
    out = np.full((R_, r + 1), -np.inf)
    out[:, 0] = base
    for s in range(1, min(r, M) + 1):
        sets = combos(M, s)
        rows, cols = _valid(free, sets)
        if len(rows) == 0:
            continue
        idx = (sets[:, :, None] * nz + np.arange(nz)).reshape(len(sets), s * nz)
        eye = np.eye(s * nz)
        for lo in range(0, len(rows), CHUNK):
            rr, cc = rows[lo : lo + CHUNK], cols[lo : lo + CHUNK]
            ii = idx[cc]
            A = eye - G[rr[:, None, None], ii[:, :, None], ii[:, None, :]]
            ok = well_conditioned(A, floor[rr])
            if problem.objective == "trace":
                Kd = K[rr[:, None, None], ii[:, :, None], ii[:, None, :]]
                with np.errstate(all="ignore"):
                    inc = np.trace(
                        np.linalg.solve(np.where(ok[:, None, None], A, eye), Kd),
                        axis1=1,
                        axis2=2,
                    )
                vals = base[rr] + inc
            else:
                vals = base[rr] - np.linalg.slogdet(np.where(ok[:, None, None], A, eye))[1]
            if not ok.all():  # I − G_DD cancels: the kept sensors' information instead
                bad = np.flatnonzero(~ok)
                keep = _without(free[rr[bad]], sets[cc[bad]])
                post = spd_inv(prior[rr[bad]] + _kept(problem, keep))
                vals[bad] = objective(post, problem.objective)
            np.maximum.at(out[:, s], rr, vals)
    return out


def two_steps(
    problem: SparseProblem,
    factors: np.ndarray,
    prev: np.ndarray,
    fixed_info: np.ndarray,
    free: np.ndarray,
    r: int,
) -> np.ndarray:
    """(R, r + 1): best Φ over steps N−2 and N−1 dropping exactly s pairs.

    The drops at N−2 are among its ``free`` sensors, those at N−1 among all; ``prev`` is the
    posterior before step N−2 (other arguments as :func:`last_step`).
    """
    R_, M = free.shape
    prior = _prior_information(problem, prev, fixed_info)
    out = np.full((R_, r + 1), -np.inf)
    for a in range(0, min(r, M) + 1):
        sets = combos(M, a)
        rows, cols = _valid(free, sets)
        step = max(1, CHUNK // max(len(combos(M, min(r - a, M))), 1))
        for lo in range(0, len(rows), step):
            rr, cc = rows[lo : lo + step], cols[lo : lo + step]
            post = spd_inv(prior[rr] + _kept(problem, _without(free[rr], sets[cc])))
            zeros = np.zeros_like(post)
            tail = last_step(problem, factors, post, zeros, np.ones((len(rr), M), bool), r - a)
            for s in range(r - a + 1):
                np.maximum.at(out[:, a + s], rr, tail[:, s])
    return out


def at_most(values: np.ndarray) -> np.ndarray:
    """Running maximum over the budget axis: best with at most s drops."""
    return np.maximum.accumulate(values, axis=-1)


class TailTable:
    """``V(P̂ + σ_j W, b)`` for b = 0..budget on a geometric σ grid, computed on demand."""

    def __init__(self, problem: SparseProblem, factors: np.ndarray, nominal: np.ndarray):
        sys = problem.system
        self.p = problem
        self.factors = factors
        self.P_hat = nominal
        self.W = predict_cov(nominal, sys.F, sys.Q)
        self.W_inv_chol = np.linalg.inv(np.linalg.cholesky(self.W))
        count = int(np.ceil(np.log(SIGMA_MAX / SIGMA_0) / np.log(SIGMA_RATIO))) + 1
        self.sigmas = np.concatenate([[0.0], SIGMA_0 * SIGMA_RATIO ** np.arange(count)])
        # children have at most budget − 1 pairs left; the tail gets at most that many
        self.budget = max(problem.budget - 1, 0)
        self.values = np.full((len(self.sigmas), self.budget + 1), np.nan)
        self.computed = 0

    def sigma(self, P: np.ndarray) -> np.ndarray:
        """(R,) smallest σ ≥ 0 with ``P ⪯ P̂ + σ W``."""
        L = self.W_inv_chol
        X = sym(L @ (P - self.P_hat) @ L.T)
        return np.maximum(np.linalg.eigvalsh(X)[..., -1], 0.0)

    def lookup(self, sigma: np.ndarray, budget: np.ndarray) -> np.ndarray:
        """(R,) table value at the grid point at or above σ (``inf`` beyond the grid)."""
        j = np.searchsorted(self.sigmas, sigma * (1 + 1e-12), side="left")
        out = np.full(sigma.shape, np.inf)
        inside = j < len(self.sigmas)
        need = np.unique(j[inside])
        missing = need[np.isnan(self.values[need, 0])]
        if len(missing):
            self._compute(missing)
        out[inside] = self.values[j[inside], budget[inside]]
        return out

    def _compute(self, js: np.ndarray) -> None:
        p, n, M = self.p, self.p.system.n, self.p.M
        prev = self.P_hat[None] + self.sigmas[js][:, None, None] * self.W[None]
        vals = two_steps(
            p,
            self.factors,
            prev,
            np.zeros((len(js), n, n)),
            np.ones((len(js), M), bool),
            self.budget,
        )
        self.values[js] = _raise(p, at_most(vals))
        self.computed += len(js)


def _kept_free(problem: SparseProblem, groups, free: np.ndarray, e: int) -> np.ndarray:
    """(R, n, n) Loewner lower bound on the information of the free sensors after any e drops."""
    J = problem.system.J
    unit = unit_information(J)[0]
    out = np.zeros((free.shape[0], problem.system.n, problem.system.n))
    for idx, w in groups:
        wf = free[:, idx] * w  # (R, |g|), weights descending
        count = np.cumsum(free[:, idx], axis=1)
        kept = (wf * (count > e)).sum(axis=1)  # drop the e largest free weights of the group
        out += kept[:, None, None] * unit[idx[0]]
    return out


def tail_child_bounds(
    problem: SparseProblem,
    factors: np.ndarray,
    table: TailTable | None,
    groups,
    attacked: np.ndarray,
    last: np.ndarray,
    posts: np.ndarray,
    start: int,
    remaining: int,
    limit: int,
) -> np.ndarray:
    """(R, T·M) mixed bound of every child "node + pair q + ``remaining`` later pairs".

    Same layout as :func:`baselines.sparse.bound.child_bounds`: column q is the pair at flat
    index ``start·M + q``; columns that are not children are ``-inf``; children whose
    enumeration would exceed ``limit`` small problems (or need the table when there is none)
    are ``+inf`` (no bound).

    Args:
        problem: The instance.
        factors: (M, n, nz) measurement factors.
        table: The tail table (None when N < 3 or too large to build).
        groups: :func:`baselines.sparse.bound.information_groups` of the sensors.
        attacked: (R, N, M) the nodes' attacked masks.
        last: (R,) flat index of each node's last pair (−1 for the root).
        posts: (R, N, n, n) the nodes' posteriors (valid at every step before the child's).
        start: First step of the columns.
        remaining: Pairs still to add after the child's pair.
        limit: Largest enumeration per child.
    """
    p, sys = problem, problem.system
    N, M, n = p.horizon, p.M, sys.n
    L = (N - start) * M
    flat = start * M + np.arange(L)
    feasible = (flat[None, :] > last[:, None]) & (flat[None, :] <= p.size - 1 - remaining)
    out = np.where(feasible, np.inf, -np.inf)
    rows, cols = np.nonzero(feasible)
    if len(rows) == 0:
        return out
    f = flat[cols]
    k, i = f // M, f % M
    for step in np.unique(k):
        sel = np.flatnonzero(k == step)
        rr, ii = rows[sel], i[sel]
        prev = posts[rr, step - 1] if step > 0 else np.broadcast_to(p.P_start, (len(rr), n, n))
        done = attacked[rr, step].copy()
        done[np.arange(len(rr)), ii] = True
        below = np.arange(M)[None, :] < ii[:, None]
        used = below & ~done
        free = np.arange(M)[None, :] > ii[:, None]
        fixed = np.einsum("rm,mij->rij", used.astype(float), sys.J)
        nfree = free.sum(axis=1)
        if step >= N - 2:
            size = np.array(
                [enumeration_size_partial(int(m), M, remaining, two=step == N - 2) for m in nfree]
            )
            ok = size <= limit
            if not ok.any():
                continue
            fn = two_steps if step == N - 2 else last_step
            vals = fn(p, factors, prev[ok], fixed[ok], free[ok], remaining)[:, remaining]
            out[rr[ok], cols[sel][ok]] = _raise(p, vals)
            continue
        if table is None:
            continue
        # head steps step..N−3 relaxed, allocations enumerated as a growing batch of states
        cap = max(len(idx) for idx, _ in groups)
        states, spent, owner = [], [], []
        pred_info = spd_inv(predict_cov(prev, sys.F, sys.Q))
        for e in range(0, min(remaining, cap) + 1):
            info = fixed + _kept_free(p, groups, free, e)
            states.append(spd_inv(pred_info + info))
            spent.append(np.full(len(rr), e))
            owner.append(np.arange(len(rr)))
        P = np.concatenate(states)
        spent = np.concatenate(spent)
        owner = np.concatenate(owner)
        levels = [_kept_free(p, groups, np.ones((1, M), bool), r)[0] for r in range(cap + 1)]
        for _ in range(step + 1, N - 2):
            Y = spd_inv(predict_cov(P, sys.F, sys.Q))
            new_P, new_s, new_o = [], [], []
            for r, info in enumerate(levels):
                keep = spent + r <= remaining
                if not keep.any():
                    break
                new_P.append(spd_inv(Y[keep] + info))
                new_s.append(spent[keep] + r)
                new_o.append(owner[keep])
            P, spent, owner = np.concatenate(new_P), np.concatenate(new_s), np.concatenate(new_o)
        vals = table.lookup(table.sigma(P), remaining - spent)
        best = np.full(len(rr), -np.inf)
        np.maximum.at(best, owner, vals)
        out[rr, cols[sel]] = best
    return out


def enumeration_size_partial(free: int, M: int, r: int, two: bool) -> int:
    """Small problems of one child's exact tail: ``free`` free sensors at its step."""
    if not two:
        return sum(comb(free, s) for s in range(r + 1))
    return sum(comb(free, a) * sum(comb(M, s) for s in range(r - a + 1)) for a in range(r + 1))
