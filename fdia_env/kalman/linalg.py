"""Small batched linear-algebra helpers; every function accepts leading batch dimensions.

Each function works on numpy arrays and on torch tensors alike (:mod:`fdia_env.backend`), so
the batched simulation engine runs the same code on either.
"""

from __future__ import annotations

import numpy as np

from fdia_env.backend import NUMPY, namespace


def mT(a: np.ndarray) -> np.ndarray:
    """Transpose the last two axes."""
    return a.swapaxes(-1, -2)


def sym(a: np.ndarray) -> np.ndarray:
    """Symmetric part ``(A + A') / 2``, used to keep covariances symmetric after each update."""
    return 0.5 * (a + mT(a))


def spd_inv(a: np.ndarray) -> np.ndarray:
    """Inverse of symmetric positive definite matrices, symmetrised; (..., n, n) -> (..., n, n)."""
    if a.shape[-1] == 2:
        return inv2(a)
    return sym(namespace(a).inv(a))


# Eigenvalues of a PSD matrix below ``size · eps`` of its largest carry no information in
# float64 (they are rounding of the large ones): they are zero.
_EPS = float(np.finfo(np.float64).eps)


def spd_inv_sum(P: np.ndarray, S: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(P + S)⁻¹`` and ``log det(P + S)`` for SPD ``P`` and PSD ``S`` of any relative scale.

    Forming ``P + S`` loses ``P`` wherever ``S`` is rank deficient and ``‖S‖ ≫ ‖P‖`` (a rank-one
    bias covariance of power 1e40 makes the sum exactly singular in float64). Instead, in the
    eigenbasis ``S = U diag(w) U'`` (eigenvalues below ``size · eps · max w`` set to zero, as
    they are rounding), ``U'(P + S)U = U'PU + diag(w)`` is scaled by its diagonal
    ``d = diag(U'PU) + w`` to ``X = D^{-1/2} (U'PU + diag(w)) D^{-1/2}`` with unit diagonal,
    which is as well conditioned as ``P`` whatever ``w`` is; then
    ``(P + S)⁻¹ = U D^{-1/2} X⁻¹ D^{-1/2} U'`` and ``log det(P + S) = log det X + Σ log d``.

    Args:
        P: (..., m, m) symmetric positive definite.
        S: (m, m) or (..., m, m) symmetric PSD (broadcast against ``P``).

    Returns:
        ``(inverse, logdet)``: (..., m, m) symmetric and (...,).
    """
    xp = namespace(P)
    m = P.shape[-1]
    w, U = xp.eigh(sym(xp.asarray(S)))
    w = xp.where(w > m * _EPS * w[..., -1:], w, 0.0)  # ascending: the last is the largest
    Pb = sym(mT(U) @ P @ U)
    d = xp.diagonal(Pb) + w
    r = 1.0 / xp.sqrt(d)
    outer = r[..., :, None] * r[..., None, :]
    X = sym((Pb + w[..., :, None] * xp.eye(m)) * outer)
    inverse = sym(U @ (spd_inv(X) * outer) @ mT(U))
    return inverse, logdet(X) + xp.sum(xp.log(d), -1)


_COFACTOR_SIGNS = np.array([[1.0, -1.0], [-1.0, 1.0]])
_TINY = float(np.finfo(np.float64).tiny)


def inv2(a: np.ndarray) -> np.ndarray:
    """Closed-form inverse of (..., 2, 2) matrices: ``[[d, −b], [−c, a]] / (ad − bc)``.

    ``a[..., ::-1, ::-1]`` transposed is ``[[d, b], [c, a]]``; the sign pattern and the
    determinant finish the adjugate formula. On component views this is many times faster than
    ``np.linalg.inv``'s per-matrix LAPACK call, and exact to rounding.
    """
    xp = namespace(a)
    if xp is not NUMPY:
        det = a[..., 0, 0] * a[..., 1, 1] - a[..., 0, 1] * a[..., 1, 0]
        if not xp.all(xp.isfinite(det)):  # huge entries: as below, rescale (or give up: NaN)
            scale = a.abs().amax(dim=(-2, -1), keepdim=True)
            if not xp.all(xp.isfinite(scale)) or xp.any(scale == 0.0):
                return xp.inv(a)
            return inv2(a / scale) / scale
        signs = xp.asarray(_COFACTOR_SIGNS)
        return mT(xp.flip_last2(a)) * (signs / det[..., None, None])
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        det = a[..., 0, 0] * a[..., 1, 1] - a[..., 0, 1] * a[..., 1, 0]
    if not np.all(np.isfinite(det)) or np.any(np.abs(det) < _TINY):
        # entries beyond ~1e154 overflow the determinant, entries below ~1e-154 underflow it
        # (a covariance of 1e-300): invert a / max|a| instead
        scale = np.abs(a).max(axis=(-2, -1), keepdims=True)
        if not np.all(np.isfinite(scale)) or np.any(scale == 0.0):
            # NaN/inf entries (a diverged iterate) or a zero matrix: no rescaling helps;
            # LAPACK gives NaN/inf or its error
            return np.linalg.inv(a)
        a = a / scale
        det = (a[..., 0, 0] * a[..., 1, 1] - a[..., 0, 1] * a[..., 1, 0])[..., None, None]
        return np.swapaxes(a[..., ::-1, ::-1], -1, -2) * (_COFACTOR_SIGNS / (det * scale))
    return np.swapaxes(a[..., ::-1, ::-1], -1, -2) * (_COFACTOR_SIGNS / det[..., None, None])


def trace(a: np.ndarray) -> np.ndarray:
    """Trace over the last two axes."""
    return namespace(a).trace(a)


def logdet(a: np.ndarray) -> np.ndarray:
    """Log-determinant of symmetric positive definite matrices (batched)."""
    xp = namespace(a)
    sign, value = xp.slogdet(a)
    return xp.where(sign > 0, value, -np.inf)


def psd_sqrt(a: np.ndarray) -> np.ndarray:
    """A factor ``L`` with ``L L' = A`` for symmetric PSD ``A`` (possibly singular), batched.

    Uses the eigen-decomposition, so rank-deficient bias covariances (the optimal attacks are
    rank one) are handled without a Cholesky failure.
    """
    xp = namespace(a)
    w, v = xp.eigh(sym(a))
    return v * xp.sqrt(xp.maximum(w, 0.0))[..., None, :]


def objective(P: np.ndarray, kind: str) -> np.ndarray:
    """Φ(P): ``"trace"`` or ``"logdet"``."""
    return trace(P) if kind == "trace" else logdet(P)
