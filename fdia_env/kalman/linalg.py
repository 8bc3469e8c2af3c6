"""Small batched linear-algebra helpers; every function accepts leading batch dimensions.

Each function works on numpy arrays and on torch tensors alike (:mod:`fdia_env.backend`), so
the batched simulation engine runs the same code on either.
"""

from __future__ import annotations

import numpy as np

from fdia_env.backend import NUMPY, Backend, namespace


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


def logdet_sum2(P: np.ndarray, S: np.ndarray) -> np.ndarray:
    """``log det(P + S)`` of (..., 2, 2) SPD ``P`` and PSD ``S``: :func:`spd_inv_sum`'s log det.

    The same computation on the components: S's eigenvalues ``(a + d) / 2 ± r``,
    ``r = sqrt(((a − d) / 2)² + b²)`` (the small one as ``det S / w_max``, zero below
    ``2 eps w_max``), the top eigenvector from the cancellation-free one of ``((a − d) / 2 + r,
    b)`` and ``(b, r − (a − d) / 2)``; ``log det X`` of the unit-diagonal X is ``log(1 − x²)``.
    """
    xp = namespace(P)
    a, b, d = S[..., 0, 0], 0.5 * (S[..., 0, 1] + S[..., 1, 0]), S[..., 1, 1]
    half = 0.5 * (a - d)
    big = xp.maximum(xp.maximum(abs(half), abs(b)), _TINY)  # scaled: no overflow at 1e300
    hs, bs = half / big, b / big
    root = big * xp.sqrt(hs * hs + bs * bs)
    w_max = 0.5 * (a + d) + root
    top = xp.where(w_max > 0.0, w_max, 1.0)
    w_min = xp.where(w_max > 0.0, (a / top) * d - (b / top) * b, 0.0)
    w_min = xp.where(w_min > 2.0 * _EPS * w_max, w_min, 0.0)
    v0 = xp.where(half >= 0.0, half + root, b)
    v1 = xp.where(half >= 0.0, b, root - half)
    size = xp.maximum(xp.maximum(abs(v0), abs(v1)), _TINY)
    v0, v1 = v0 / size, v1 / size
    norm = xp.sqrt(v0 * v0 + v1 * v1)
    none = norm == 0.0  # S = s I: any basis
    c = xp.where(none, 1.0, v0 / xp.where(none, 1.0, norm))
    s = xp.where(none, 0.0, v1 / xp.where(none, 1.0, norm))
    p00, p01, p11 = P[..., 0, 0], 0.5 * (P[..., 0, 1] + P[..., 1, 0]), P[..., 1, 1]
    # U'PU with U = [[c, −s], [s, c]] (columns: the eigenvectors of w_max, w_min)
    q00 = c * c * p00 + 2.0 * c * s * p01 + s * s * p11
    q11 = s * s * p00 - 2.0 * c * s * p01 + c * c * p11
    q01 = (c * c - s * s) * p01 + c * s * (p11 - p00)
    d0, d1 = q00 + w_max, q11 + w_min
    x = q01 / (xp.sqrt(d0) * xp.sqrt(d1))
    return xp.log(1.0 - x * x) + xp.log(d0) + xp.log(d1)


_COFACTOR_SIGNS = np.array([[1.0, -1.0], [-1.0, 1.0]])
_TINY = float(np.finfo(np.float64).tiny)
_HUGE = float(np.finfo(np.float64).max)


def inv2(a: np.ndarray) -> np.ndarray:
    """Closed-form inverse of (..., 2, 2) matrices: ``[[d, −b], [−c, a]] / (ad − bc)``.

    ``a[..., ::-1, ::-1]`` transposed is ``[[d, b], [c, a]]``; the sign pattern and the
    determinant finish the adjugate formula. On component views this is many times faster than
    ``np.linalg.inv``'s per-matrix LAPACK call, and exact to rounding.

    Entries beyond ~1e154 overflow the determinant, entries below ~1e-154 underflow it (a
    covariance of 1e-300): where any determinant is not a normal float, every matrix is scaled
    by the power of two ``s`` that puts its largest entry in [0.5, 1) and the inverse is ``s``
    times the scaled one's. Scaling by a power of two is exact, so a matrix inside the range
    gets the same bits either way (a member's inverse does not depend on the rest of its batch).
    """
    xp = namespace(a)
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):
        det = a[..., 0, 0] * a[..., 1, 1] - a[..., 0, 1] * a[..., 1, 0]
    if not xp.all((det >= _TINY) & (det <= _HUGE)):
        # NaN/inf entries (a diverged iterate) stay NaN/inf; a singular matrix gives inf/NaN
        big = abs(a).amax(dim=(-2, -1)) if xp is not NUMPY else np.abs(a).max(axis=(-2, -1))
        s = xp.unit_scale(big)[0][..., None, None]
        a = a * s
        det = a[..., 0, 0] * a[..., 1, 1] - a[..., 0, 1] * a[..., 1, 0]
        with np.errstate(divide="ignore", invalid="ignore"):
            return _adjugate(a, xp) * (xp.asarray(_COFACTOR_SIGNS) / det[..., None, None]) * s
    return _adjugate(a, xp) * (xp.asarray(_COFACTOR_SIGNS) / det[..., None, None])


def _adjugate(a: np.ndarray, xp: Backend) -> np.ndarray:
    """``[[d, b], [c, a]]`` of (..., 2, 2) ``[[a, b], [c, d]]`` (the adjugate before its signs)."""
    return mT(xp.flip_last2(a))


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
