"""Actual error of a filter that is unaware of injected biases (docs/math.md §2.1)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from fdia_env.kalman.filter import joseph_update, predict_cov
from fdia_env.kalman.linalg import mT


def actual_covariance_step(
    M_prev: np.ndarray,
    F: np.ndarray,
    Q: np.ndarray,
    H: np.ndarray,
    R: np.ndarray,
    W: np.ndarray,
    Sigma: np.ndarray | None = None,
) -> np.ndarray:
    """``M[k] = (I − W H)(F M[k−1] F' + Q)(I − W H)' + W (R + Σ[k]) W'`` (Joseph form).

    Args:
        M_prev: (..., n, n) actual error covariance at k−1.
        F: (n, n) transition.
        Q: (n, n) process noise covariance.
        H: (nz, n) stacked measurement matrix.
        R: (nz, nz) block-diagonal measurement noise covariance.
        W: (..., n, nz) the filter's nominal gain at k (zero columns for unused rows).
        Sigma: (..., nz, nz) bias covariance injected at k (None = no attack).
    """
    noise = R if Sigma is None else R + Sigma
    return joseph_update(predict_cov(M_prev, F, Q), W, H, noise)


def transition_matrices(F: np.ndarray, H: np.ndarray, W: np.ndarray) -> np.ndarray:
    """``B[k] = (I − W[k] H) F`` for a (..., N+1, n, nz) sequence of gains."""
    return (np.eye(F.shape[0]) - W @ H) @ F


def extra_mse(
    F: np.ndarray,
    H: np.ndarray,
    gains: Sequence[np.ndarray] | np.ndarray,
    sigmas: Sequence[np.ndarray] | np.ndarray,
) -> np.ndarray:
    """Extra MSE ``A[K+N] = Σ_{m=0..N} D_m Σ[K+N−m] D_m'`` caused by biases from K on.

    ``D_0 = W[K+N]``, ``D_m = B[K+N] B[K+N−1] ··· B[K+N−m+1] W[K+N−m]``, ``B[k] = (I − W[k] H) F``.

    Args:
        F: (n, n) transition.
        H: (nz, n) stacked measurement matrix.
        gains: W[K], ..., W[K+N], each (n, nz).
        sigmas: Σ[K], ..., Σ[K+N], each (nz, nz).

    Returns:
        (n, n) extra MSE at K+N.
    """
    gains = np.asarray(gains, dtype=float)
    sigmas = np.asarray(sigmas, dtype=float)
    if gains.shape[0] != sigmas.shape[0]:
        raise ValueError(
            "gains and sigmas must cover the same steps, "
            f"got {gains.shape[0]} and {sigmas.shape[0]}"
        )
    B = transition_matrices(F, H, gains)
    N = gains.shape[0] - 1
    n = F.shape[0]
    prod = np.eye(n)  # B[K+N] ··· B[K+N−m+1]
    A = np.zeros((n, n))
    for m in range(N + 1):
        D = prod @ gains[N - m]
        A += D @ sigmas[N - m] @ mT(D)
        prod = prod @ B[N - m]
    return 0.5 * (A + A.T)
