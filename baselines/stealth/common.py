"""Input checks and small linear-algebra helpers shared by the stealthy-attack baselines."""

from __future__ import annotations

from typing import Any

import numpy as np

from fdia_env.stealth import StaticEstimation, static_estimation

ZERO_RTOL = 1e-9
"""A measurement of an attack counts as untouched when ``|a_i| <= ZERO_RTOL · max |a|``."""


def as_estimation(source: Any, param: str = "estimation") -> StaticEstimation:
    """A :class:`StaticEstimation`, or one built by :func:`static_estimation` from ``source``."""
    if isinstance(source, StaticEstimation):
        return source
    try:
        return static_estimation(source)
    except ValueError as exc:
        raise ValueError(f"{param}: {exc}") from exc


def meter_indices(est: StaticEstimation, meters: Any, param: str = "protected") -> np.ndarray:
    """Sorted unique meter positions from positions or names (``ValueError`` naming ``param``)."""
    return est.meter_positions(meters, param)


def state_index(est: StaticEstimation, state: Any, param: str = "state") -> int:
    """A state position 0..n−1 (``ValueError`` naming ``param`` otherwise)."""
    if isinstance(state, bool) or not isinstance(state, (int, np.integer)):
        raise ValueError(f"{param} must be a state position 0..{est.n - 1}, got {state!r}")
    if not 0 <= int(state) < est.n:
        raise ValueError(f"{param} must be a state position 0..{est.n - 1}, got {state}")
    return int(state)


def support(a: np.ndarray) -> np.ndarray:
    """Positions of the non-zero entries of an attack (relative tolerance :data:`ZERO_RTOL`)."""
    scale = float(np.max(np.abs(a))) if a.size else 0.0
    if scale == 0.0:
        return np.zeros(0, dtype=np.int64)
    return np.flatnonzero(np.abs(a) > ZERO_RTOL * scale)


def null_space(A: np.ndarray, n: int) -> np.ndarray:
    """(n, d) orthonormal basis of ``{c : A c = 0}`` for an (r, n) matrix (r may be 0)."""
    if A.shape[0] == 0:
        return np.eye(n)
    _, s, vt = np.linalg.svd(A, full_matrices=True)
    tol = max(A.shape) * np.finfo(float).eps * (s[0] if s.size else 0.0)
    rank = int(np.sum(s > tol))
    return vt[rank:].T


def attack_on_state(
    est: StaticEstimation, state: int, zero: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """``(c, a = H c)`` with ``c_state = 1`` and ``a`` zero on the meters ``zero``, or ``None``.

    Among the attacks with those zeros, the one of smallest ``|c|`` (a null-space vector of
    ``H[zero]``), so its support is the smallest the zeros allow when they make the null space
    one-dimensional.
    """
    N = null_space(est.H[zero], est.n)
    row = N[state]
    if N.shape[1] == 0 or np.linalg.norm(row) <= 1e-10:
        return None
    c = N @ row / float(row @ row)
    a = est.H @ c
    a[zero] = 0.0
    return c, a
