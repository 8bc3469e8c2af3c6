"""Input checks and small linear-algebra helpers shared by the stealthy-attack baselines."""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import functools
import os
import sys
from collections.abc import Iterator
from typing import Any

import numpy as np

from fdia_env.stealth import StaticEstimation, static_estimation

ZERO_RTOL = 1e-9
"""A measurement of an attack counts as untouched when ``|a_i| <= ZERO_RTOL · max |a|``."""


@functools.cache
def _libc() -> Any:
    name = ctypes.util.find_library("c")
    try:
        return ctypes.CDLL(name) if name else None
    except OSError:  # pragma: no cover - no C library to flush (the redirect still works)
        return None


def _flush_c_stdout() -> None:
    libc = _libc()
    if libc is not None:
        libc.fflush(None)


@contextlib.contextmanager
def quiet_solver() -> Iterator[None]:
    """Send file descriptor 1 to the null device while a HiGHS MILP runs.

    HiGHS' MIP solver prints debugging lines (``HighsMipSolverData::
    transformNewIntegerFeasibleSolution tmpSolver.run();``) from C++ straight to the process's
    standard output, and scipy's ``milp`` has no option that silences them; so the descriptor
    itself is redirected for the solve and restored after it (C's buffer is flushed both
    times, so nothing written before or after is lost or misplaced). Output that another thread
    writes to descriptor 1 during the solve is dropped too.
    """
    sys.stdout.flush()
    _flush_c_stdout()
    try:
        saved = os.dup(1)
    except OSError:  # no descriptor 1 (a detached process): nothing to silence
        yield
        return
    null = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        yield
    finally:
        _flush_c_stdout()
        os.dup2(saved, 1)
        os.close(saved)
        os.close(null)


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


def on_support(a: np.ndarray) -> np.ndarray:
    """``a`` with the entries off its :func:`support` set to 0 (rounding residue of ``H c``)."""
    out = np.zeros_like(a, dtype=np.float64)
    keep = support(a)
    out[keep] = a[keep]
    return out


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


def milp(*args: Any, **kwargs: Any) -> Any:
    """``scipy.optimize.milp`` with HiGHS' debugging lines silenced (:func:`quiet_solver`)."""
    from scipy import optimize

    with quiet_solver():
        return optimize.milp(*args, **kwargs)
