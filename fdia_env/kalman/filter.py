"""Kalman filter steps as pure functions with leading batch dimensions (docs/math.md §1).

Shapes: ``P`` (..., n, n), ``x`` (..., n), ``F``/``Q`` (n, n), ``H`` (nz, n), ``R`` (nz, nz),
sensor masks (..., M) booleans (True = the filter uses that sensor's measurement).
"""

from __future__ import annotations

import numpy as np

from fdia_env.backend import namespace
from fdia_env.kalman.linalg import mT, spd_inv, sym
from fdia_env.systems import LinearSystem


def predict_cov(P: np.ndarray, F: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """``P[k+1|k] = F P[k|k] F' + Q`` (numpy or torch, all of one backend)."""
    return sym(F @ P @ mT(F) + Q)


def predict(
    x: np.ndarray, P: np.ndarray, F: np.ndarray, Q: np.ndarray, Gu: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Predict the mean ``x[k+1|k] = F x + G u`` and covariance ``F P F' + Q``."""
    x_pred = x @ F.T
    if Gu is not None:
        x_pred = x_pred + Gu
    return x_pred, predict_cov(P, F, Q)


def covariance_update(
    P_pred: np.ndarray, H: np.ndarray, R: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Covariance-form update with every row of ``H`` used.

    ``S = H P H' + R``, ``W = P H' S⁻¹``, ``P[k|k] = P − W S W'``.

    Returns:
        ``(P_post, W, S)`` with shapes (..., n, n), (..., n, nz), (..., nz, nz).
    """
    S = sym(H @ P_pred @ H.T + R)
    W = mT(np.linalg.solve(S, H @ P_pred))  # W = P H' S⁻¹, solved rather than inverted
    P_post = sym(P_pred - W @ S @ mT(W))
    return P_post, W, S


def information_update(
    P_pred: np.ndarray, J: np.ndarray, mask: np.ndarray | None = None
) -> np.ndarray:
    """Information-form update for a sensor subset.

    ``P[k|k]⁻¹ = P[k|k−1]⁻¹ + Σ_{i used} H_i' R_i⁻¹ H_i``.

    Args:
        P_pred: (..., n, n) predicted covariance.
        J: (M, n, n) per-sensor information matrices (``LinearSystem.J``).
        mask: (..., M) sensors used; ``None`` uses all.
    """
    if mask is None:
        info_gain = J.sum(axis=0)
    else:
        info_gain = np.einsum("...m,mij->...ij", np.asarray(mask, dtype=float), J)
    return spd_inv(spd_inv(P_pred) + info_gain)


def masked_gain(
    P_post: np.ndarray, system: LinearSystem, mask: np.ndarray | None = None
) -> np.ndarray:
    """Gain over the stacked measurement with zero columns for unused sensors.

    ``W = P[k|k] H' R⁻¹`` restricted to the used rows; equal to the covariance-form gain of
    the used subset because R is block diagonal.

    Returns:
        (..., n, nz) gain.
    """
    if mask is None:
        return P_post @ system.HtRinv
    rows = system.row_mask(np.asarray(mask, dtype=float))
    return P_post @ (system.HtRinv * rows[..., None, :])


def subset_update(
    P_pred: np.ndarray, system: LinearSystem, mask: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Update for a (batched) sensor subset: ``(P_post, W)``, W of shape (..., n, nz)."""
    P_post = information_update(P_pred, system.J, mask)
    return P_post, masked_gain(P_post, system, mask)


def update_mean(x_pred: np.ndarray, W: np.ndarray, z: np.ndarray, H: np.ndarray) -> np.ndarray:
    """``x[k|k] = x[k|k−1] + W (z − H x[k|k−1])`` for batched vectors."""
    innovation = z - x_pred @ H.T
    return x_pred + np.einsum("...ij,...j->...i", W, innovation)


def joseph_update(
    M_pred: np.ndarray, W: np.ndarray, H: np.ndarray, noise_cov: np.ndarray
) -> np.ndarray:
    """Error covariance after an update with an arbitrary gain (Joseph form).

    ``M = (I − W H) M[k|k−1] (I − W H)' + W N W'`` where ``N`` is the covariance of the noise
    actually present in the measurement (``R + Σ`` under attack). Valid for any gain, which is
    why it is used for the actual error of a filter whose nominal gain ignores the attack.
    """
    A = namespace(M_pred).eye(M_pred.shape[-1]) - W @ H
    return sym(A @ M_pred @ mT(A) + W @ noise_cov @ mT(W))
