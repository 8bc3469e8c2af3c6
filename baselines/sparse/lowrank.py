"""Single-pair toggles of a sparse attack by rank-one updates (fast greedy steps for large n).

The greedy solvers score, at every step, one candidate per sensor-time pair: the current attack
set with that pair flipped. Evaluated from scratch each costs N covariance recursions with n×n
inverses, O(N n³); for the power-grid presets (n = 117, M·N = 912 pairs) SBS would need hours.
A flip of a scalar sensor i at step k0 changes the information at that step by ``±h h' / r``
(``h = H_i'``, ``r = R_i``), so the covariance changes by a rank-one term, and a rank-one
difference stays rank one through the rest of the Riccati recursion. Writing the difference as
``s w w'`` (base trajectory ``P_k = P[k|k]``, ``Y_k = (F P_{k−1} F' + Q)⁻¹``):

    step k0 (flip, δ = +1 restores the measurement, −1 drops it):
        w = P_k0 h,   s = −δ / (r + δ h' P_k0 h)                        (Sherman–Morrison)
    every later step k:
        v = F w,  a = Y_k v,  c = s / (1 + s v' a)                       (prediction, inverted)
        w ← P_k a,  s ← c / (1 − c a' P_k a)                              (update, inverted)

and at the end ``tr(P + s w w') = tr P + s |w|²``, ``log det(P + s w w') = log det P +
log(1 + s w' P⁻¹ w)``. Each candidate costs O(N n²), done for all candidates of a step at once
as matrix products. Only scalar sensors (one measurement row each) take this path; the tests
check it against the full recursion of :meth:`SparseProblem.evaluate_masks`.
"""

from __future__ import annotations

import numpy as np

from baselines.sparse.problem import SparseProblem
from fdia_env.kalman import information_update, predict_cov
from fdia_env.kalman.linalg import sym

MIN_STATE = 8
"""Smallest state size that takes the rank-one path (below it the full recursion is as fast)."""


def applies(problem: SparseProblem) -> bool:
    """Whether :func:`toggle_values` serves ``problem`` (scalar sensors, n >= MIN_STATE)."""
    sys = problem.system
    return sys.n >= MIN_STATE and sys.nz == sys.M


def _trajectory(problem: SparseProblem, attacked: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, n, n) posteriors P[k|k] and predicted informations Y_k of one attack pattern."""
    sys = problem.system
    P = problem.P_start
    posts, infos = [], []
    for k in range(problem.horizon):
        P_pred = predict_cov(P, sys.F, sys.Q)
        infos.append(sym(np.linalg.inv(P_pred)))
        P = information_update(P_pred, sys.J, ~attacked[k])
        posts.append(P)
    return np.stack(posts), np.stack(infos)


def toggle_values(problem: SparseProblem, attacked: np.ndarray, flats: np.ndarray) -> np.ndarray:
    """Φ of ``attacked`` with each pair of ``flats`` flipped (see the module docstring).

    Args:
        problem: A problem with scalar sensors (:func:`applies`).
        attacked: (N·M,) current pattern, flat in the canonical (step, sensor) order.
        flats: (C,) flat pair indices to flip, one candidate each.

    Returns:
        (C,) objective values, in the order of ``flats``.
    """
    sys = problem.system
    N, M = problem.horizon, problem.M
    pattern = attacked.reshape(N, M)
    posts, infos = _trajectory(problem, pattern)
    h_all = sys.H  # (M, n): row i is sensor i's h'
    r_all = np.diag(sys.R)
    flats = np.asarray(flats, dtype=np.int64)
    steps, sensors = np.divmod(flats, M)
    out = np.empty(len(flats))
    final = posts[-1]
    if problem.objective == "logdet":
        final_info = sym(np.linalg.inv(final))
        base = float(np.linalg.slogdet(final)[1])
    else:
        base = float(np.trace(final))
    for k0 in np.unique(steps):
        pick = np.flatnonzero(steps == k0)
        i = sensors[pick]
        delta = np.where(pattern[k0, i], 1.0, -1.0)  # attacked now: flipping restores it
        h = h_all[i]  # (C, n)
        w = h @ posts[k0]  # P h, P symmetric
        s = -delta / (r_all[i] + delta * np.einsum("cj,cj->c", w, h))
        for k in range(k0 + 1, N):
            v = w @ sys.F.T  # F w
            a = v @ infos[k]  # Y v
            c = s / (1.0 + s * np.einsum("cj,cj->c", v, a))
            w = a @ posts[k]  # P a
            s = c / (1.0 - c * np.einsum("cj,cj->c", a, w))
        if problem.objective == "trace":
            out[pick] = base + s * np.einsum("cj,cj->c", w, w)
        else:
            out[pick] = base + np.log1p(s * np.einsum("cj,cj->c", w @ final_info, w))
    return out
