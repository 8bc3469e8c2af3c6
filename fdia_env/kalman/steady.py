"""Steady state of the Kalman filter for a fixed sensor subset (MATH.md §1)."""

from __future__ import annotations

import weakref

import numpy as np
import scipy.linalg

from fdia_env.kalman.filter import information_update, masked_gain, predict_cov
from fdia_env.kalman.linalg import sym
from fdia_env.systems import LinearSystem


def _sensor_rows(system: LinearSystem, mask: np.ndarray | None) -> np.ndarray:
    if mask is None:
        return np.ones(system.nz, dtype=bool)
    mask = np.asarray(mask, dtype=bool)
    if mask.shape != (system.M,):
        raise ValueError(f"mask must have shape ({system.M},), got {mask.shape}")
    if not mask.any():
        raise ValueError("mask must select at least one sensor for a steady state to exist")
    return system.row_mask(mask)


# system -> {used-sensor key: (P_pred, P_post, W)}; systems are immutable, so results are too
_CACHE: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def steady_state(
    system: LinearSystem, mask: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Steady-state ``(P[k+1|k], P[k|k], W)`` from the discrete algebraic Riccati equation.

    ``scipy.linalg.solve_discrete_are(F', H', Q, R)`` gives the predicted covariance; one
    update gives the filtered one. Falls back to :func:`steady_state_iterate` when the DARE
    solver fails (e.g. Q = 0, where the filtered covariance tends to zero). Results are cached
    per (system, subset) and returned as read-only arrays: a :class:`LinearSystem` is immutable.

    Args:
        system: The system.
        mask: (M,) sensors used (default all).

    Returns:
        Predicted covariance (n, n), filtered covariance (n, n), gain (n, nz) with zero columns
        for unused sensors.
    """
    rows = _sensor_rows(system, mask)
    key = rows.tobytes()
    cached = _CACHE.setdefault(system, {})
    if key not in cached:
        result = _solve_dare(system, mask, rows)
        for a in result:
            a.setflags(write=False)
        cached[key] = result
    return cached[key]


def _solve_dare(
    system: LinearSystem, mask: np.ndarray | None, rows: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    H, R = system.H[rows], system.R[np.ix_(rows, rows)]
    try:
        P_pred = sym(scipy.linalg.solve_discrete_are(system.F.T, H.T, system.Q, R))
        if not np.all(np.isfinite(P_pred)) or np.linalg.eigvalsh(P_pred).min() <= 0:
            raise np.linalg.LinAlgError("non-positive DARE solution")
    except (np.linalg.LinAlgError, ValueError):
        return steady_state_iterate(system, mask)
    P_post = information_update(P_pred, system.J, mask)
    return P_pred, P_post, masked_gain(P_post, system, mask)


def steady_state_iterate(
    system: LinearSystem,
    mask: np.ndarray | None = None,
    *,
    P0: np.ndarray | None = None,
    tol: float = 1e-13,
    max_iter: int = 100_000,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Fixed point of the covariance recursion, batched over (..., M) masks.

    Iterates ``P[k|k] = ((F P F' + Q)⁻¹ + Σ_used J_i)⁻¹`` until the relative change is below
    ``tol`` in every batch member.

    Returns:
        Predicted (..., n, n), filtered (..., n, n) covariances and the gain (..., n, nz).
    """
    mask_arr = None if mask is None else np.asarray(mask, dtype=bool)
    batch = () if mask_arr is None else mask_arr.shape[:-1]
    P = np.broadcast_to(system.P0 if P0 is None else P0, (*batch, system.n, system.n)).copy()
    for _ in range(max_iter):
        P_pred = predict_cov(P, system.F, system.Q)
        P_new = information_update(P_pred, system.J, mask_arr)
        scale = np.maximum(np.abs(P_new).max(axis=(-2, -1)), 1e-300)
        done = np.abs(P_new - P).max(axis=(-2, -1)) <= tol * scale
        P = P_new
        if np.all(done):
            break
    P_pred = predict_cov(P, system.F, system.Q)
    return P_pred, P, masked_gain(P, system, mask_arr)
