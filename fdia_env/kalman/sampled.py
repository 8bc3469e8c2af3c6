"""Sampled simulation: true states, noises and biases drawn from a numpy Generator."""

from __future__ import annotations

import numpy as np

from fdia_env.kalman.filter import update_mean
from fdia_env.systems import LinearSystem


def draw(rng: np.random.Generator, factor: np.ndarray, batch: tuple[int, ...]) -> np.ndarray:
    """Draw ``(*batch, d)`` Gaussian vectors with covariance ``factor @ factor'``."""
    noise = rng.standard_normal((*batch, factor.shape[-1]))
    return np.einsum("...ij,...j->...i", factor, noise)  # einsum broadcasts the batch axes


def sampled_step(
    rng: np.random.Generator,
    system: LinearSystem,
    x: np.ndarray,
    x_hat: np.ndarray,
    W: np.ndarray,
    *,
    Q_factor: np.ndarray,
    R_factor: np.ndarray,
    bias_factor: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One step of the true system and of the filter on (possibly corrupted) measurements.

    ``x[k+1] = F x + G u + v``, ``z = H x[k+1] + w + b``, ``x̂ = x̂[k+1|k] + W (z − H x̂[k+1|k])``.

    Args:
        rng: Source of every random draw.
        system: The system.
        x: (..., n) true states at k.
        x_hat: (..., n) filter estimates at k.
        W: (..., n, nz) gain at k+1 (zero columns for measurements the filter drops).
        Q_factor: (n, n) with ``Q_factor Q_factor' = Q``.
        R_factor: (nz, nz) with ``R_factor R_factor' = R``.
        bias_factor: (..., nz, nz) factor of the bias covariance Σ (None = no bias).

    Returns:
        ``(x_next, x_hat_next, z, innovation)``.
    """
    batch = x.shape[:-1]
    x_next = x @ system.F.T + system.Gu + draw(rng, Q_factor, batch)
    z = x_next @ system.H.T + draw(rng, R_factor, batch)
    if bias_factor is not None:
        z = z + draw(rng, bias_factor, batch)
    x_pred = x_hat @ system.F.T + system.Gu
    innovation = z - x_pred @ system.H.T
    return x_next, update_mean(x_pred, W, z, system.H), z, innovation
