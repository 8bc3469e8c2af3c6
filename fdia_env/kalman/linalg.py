"""Small batched linear-algebra helpers; every function accepts leading batch dimensions."""

from __future__ import annotations

import numpy as np


def mT(a: np.ndarray) -> np.ndarray:
    """Transpose the last two axes."""
    return np.swapaxes(a, -1, -2)


def sym(a: np.ndarray) -> np.ndarray:
    """Symmetric part ``(A + A') / 2``, used to keep covariances symmetric after each update."""
    return 0.5 * (a + mT(a))


def spd_inv(a: np.ndarray) -> np.ndarray:
    """Inverse of symmetric positive definite matrices, symmetrised; (..., n, n) -> (..., n, n)."""
    if a.shape[-1] == 2:
        return inv2(a)
    return sym(np.linalg.inv(a))


_COFACTOR_SIGNS = np.array([[1.0, -1.0], [-1.0, 1.0]])


def inv2(a: np.ndarray) -> np.ndarray:
    """Closed-form inverse of (..., 2, 2) matrices: ``[[d, −b], [−c, a]] / (ad − bc)``.

    ``a[..., ::-1, ::-1]`` transposed is ``[[d, b], [c, a]]``; the sign pattern and the
    determinant finish the adjugate formula. On component views this is many times faster than
    ``np.linalg.inv``'s per-matrix LAPACK call, and exact to rounding.
    """
    with np.errstate(over="ignore", invalid="ignore"):
        det = a[..., 0, 0] * a[..., 1, 1] - a[..., 0, 1] * a[..., 1, 0]
    if not np.all(np.isfinite(det)):  # entries beyond ~1e154: invert a / max|a| instead
        scale = np.abs(a).max(axis=(-2, -1), keepdims=True)
        if not np.all(np.isfinite(scale)) or np.any(scale == 0.0):
            # NaN/inf entries (a diverged iterate): no rescaling helps; LAPACK gives NaN/inf
            # instead of recursing without end
            return np.linalg.inv(a)
        return inv2(a / scale) / scale
    return np.swapaxes(a[..., ::-1, ::-1], -1, -2) * (_COFACTOR_SIGNS / det[..., None, None])


def trace(a: np.ndarray) -> np.ndarray:
    """Trace over the last two axes."""
    return np.trace(a, axis1=-2, axis2=-1)


def logdet(a: np.ndarray) -> np.ndarray:
    """Log-determinant of symmetric positive definite matrices (batched)."""
    sign, value = np.linalg.slogdet(a)
    return np.where(sign > 0, value, -np.inf)


def psd_sqrt(a: np.ndarray) -> np.ndarray:
    """A factor ``L`` with ``L L' = A`` for symmetric PSD ``A`` (possibly singular), batched.

    Uses the eigen-decomposition, so rank-deficient bias covariances (the optimal attacks are
    rank one) are handled without a Cholesky failure.
    """
    w, v = np.linalg.eigh(sym(a))
    return v * np.sqrt(np.clip(w, 0.0, None))[..., None, :]


def objective(P: np.ndarray, kind: str) -> np.ndarray:
    """Φ(P): ``"trace"`` or ``"logdet"``."""
    return trace(P) if kind == "trace" else logdet(P)
