"""The attacker's bias covariance that maximises the missed-attack cost c2 (docs/math.md §3).

With ``K0 = Pxz Pzz0⁻¹`` the clean-model gain, the MSE of the unaware estimate under attack is

    c2(Pbb) = tr[Pxx − Pxz Pzz0⁻¹ (I − Pbb Pzz0⁻¹) Pxz']
            = tr[Pxx − Pxz Pzz0⁻¹ Pxz'] + tr[Pbb · K0' K0],

linear in Pbb. Over ``{Pbb ⪰ 0, tr Pbb = a²}`` a linear function ``tr(Pbb G)`` (G = K0' K0 =
Pzz0⁻¹ Pxz' Pxz Pzz0⁻¹ ⪰ 0) is maximised at ``a² λ_max(G)``, attained by the rank-one
``Pbb = a² u u'`` with u the top eigenvector of G: ``tr(Pbb G) = Σ_i μ_i u_i' G u_i`` for
``Pbb = Σ μ_i u_i u_i'`` with ``Σ μ_i = a²``, and each ``u_i' G u_i <= λ_max``. This is the same
eigenvector rule as the trace-optimal attack on the unaware filter (docs/math.md §2.2) with the gain
``K0`` in place of ``W``. A power weight Ω (``tr(Ω Pbb) = a²``) is handled by the substitution
``Pbb = Ω^{-1/2} P̃ Ω^{-1/2}``.
"""

from __future__ import annotations

import numpy as np

from fdia_env._validation import as_matrix, check_power, check_psd


def c2_gain_matrix(Pxx: np.ndarray, H: np.ndarray, Pww: np.ndarray) -> np.ndarray:
    """``G = K0' K0 = Pzz0⁻¹ Pxz' Pxz Pzz0⁻¹`` (nz, nz): ``c2 = c4 + tr(Pbb G)``."""
    Pxz = Pxx @ H.T
    Pzz0 = H @ Pxz + Pww
    K0 = np.linalg.solve(Pzz0, Pxz.T).T  # Pxz Pzz0⁻¹ (Pzz0 symmetric)
    G = K0.T @ K0
    return 0.5 * (G + G.T)


def c2_optimal_pbb(
    Pxx: np.ndarray,
    H: np.ndarray,
    Pww: np.ndarray,
    power: float,
    weight: np.ndarray | None = None,
) -> np.ndarray:
    """The bias covariance of power a² that maximises c2: ``a² u u'`` along G's top eigenvector.

    Args:
        Pxx: (n, n) prior covariance.
        H: (nz, n) measurement matrix.
        Pww: (nz, nz) measurement-noise covariance.
        power: a² ``>= 0``.
        weight: (nz, nz) symmetric positive definite power weight Ω (default identity).

    Returns:
        (nz, nz) rank-one (zero when a² = 0) PSD matrix with ``tr(Ω Pbb) = a²``. The eigenvector's
        sign is fixed (largest-magnitude entry positive); the matrix does not depend on it.

    Raises:
        ValueError: Naming the parameter: a matrix that is not numeric and finite or has the
            wrong shape, ``Pxx`` not symmetric PSD, ``Pww`` not symmetric positive definite,
            ``power`` not a number in ``[0, MAX_POWER]``, a weight not positive definite.

    Example:
        >>> import numpy as np
        >>> c2_optimal_pbb(100 * np.eye(2), np.eye(2), np.diag([3.0, 4.0]), 50.0).round(9).tolist()
        [[50.0, 0.0], [0.0, 0.0]]
    """
    Pxx = as_matrix("Pxx", Pxx)
    n = Pxx.shape[0]
    if Pxx.shape != (n, n):
        raise ValueError(f"Pxx must be a square (n, n) matrix, got shape {Pxx.shape}")
    check_psd("Pxx", Pxx)
    H = as_matrix("H", H, shape=(None, n))
    nz = H.shape[0]
    Pww = as_matrix("Pww", Pww, shape=(nz, nz))
    check_psd("Pww", Pww, strict=True)
    power = check_power("power", power, allow_zero=True)
    G = c2_gain_matrix(Pxx, H, Pww)
    if weight is None:
        inv_half = np.eye(nz)
    else:
        omega = as_matrix("weight", weight, shape=(nz, nz))
        check_psd("weight", omega, strict=True)
        w, v = np.linalg.eigh(omega)
        inv_half = (v / np.sqrt(w)) @ v.T
    G_tilde = inv_half @ G @ inv_half
    _, vectors = np.linalg.eigh(0.5 * (G_tilde + G_tilde.T))
    u = vectors[:, -1]
    u = u * np.sign(u[np.argmax(np.abs(u))])
    Pbb = float(power) * (inv_half @ np.outer(u, u) @ inv_half)
    return 0.5 * Pbb + 0.5 * Pbb.T  # halves first: no overflow at the largest powers
