"""The attacker's bias covariance that maximises the missed-detection cost c2 (MATH.md §3)."""

from __future__ import annotations

import numpy as np


def c2_optimal_sigma(Pxx: np.ndarray, H: np.ndarray, Pww: np.ndarray, power: float) -> np.ndarray:
    """``argmax tr Pbb = a²`` of ``c2 = tr[Pxx − Pxz Pzz0⁻¹ (I − Pbb Pzz0⁻¹) Pxz']``.

    ``c2 = const + tr(Pbb G)`` with ``G = Pzz0⁻¹ Pxz' Pxz Pzz0⁻¹`` is linear in Pbb, so the
    maximiser is rank one, ``a² v v'`` along the top eigenvector v of G.
    """
    Pxz = Pxx @ H.T
    Pzz0_inv = np.linalg.inv(H @ Pxz + Pww)
    G = Pzz0_inv @ Pxz.T @ Pxz @ Pzz0_inv
    _, V = np.linalg.eigh(0.5 * (G + G.T))
    v = V[:, -1]
    return power * np.outer(v, v)
