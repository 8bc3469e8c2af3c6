"""Exact expected squared error of a threshold detector followed by an estimator (docs/math.md §3).

Setting: prior ``x ~ N(x̄, Pxx)``, ``z = H x + w (+ b)``, ``w ~ N(0, Pww)``, ``b ~ N(0, Σ)`` with
probability ``p1``; the detector decides D1 when ``y' A y > τ`` for the innovation
``y = z − H x̄``; the estimate is ``x̄ + K_D y`` with ``K_D`` the gain of the decision (the clean
LMMSE gain on D0; on D1 zero to discard, or the attack-model gain to incorporate).

Given ``y`` under hypothesis h (``y ~ N(0, C_h)``, ``C_h = H Pxx H' + Pww + h Σ``) the error has
mean ``(K_h* − K_D) y`` (``K_h* = Pxz C_h⁻¹``) and covariance ``Σ_h = Pxx − Pxz C_h⁻¹ Pxz'``, so

    E ||x − x̂||² = Σ_h p_h [ tr Σ_h + E_h(y' G_{h,D0} y 1{y'Ay ≤ τ})
                                    + E_h(y' G_{h,D1} y 1{y'Ay > τ}) ]

with ``G = (K_h* − K_D)'(K_h* − K_D)``. Whitening ``y = L u`` (``L L' = C_h``) and rotating to the
eigenvectors V of ``L'AL`` (eigenvalues λ) gives independent ``v_i ~ N(0, 1)`` with
``y'Ay = Σ λ_i v_i²`` and

    E(y'Gy 1{y'Ay > τ}) = Σ_i g_ii E(v_i² 1{Σ_j λ_j v_j² > τ})
                        = Σ_i g_ii P(λ_i χ²₃ + Σ_{j≠i} λ_j χ²₁ > τ),

(``g = V'L'GLV``; off-diagonal terms vanish by symmetry, and ``E[v² f(v²)] = E[f(χ²₃)]`` for
``v ~ N(0, 1)``): generalized chi-square tail probabilities (:mod:`fdia_env.detection.gchisq`).

Numerical stability at any attack power. The second moment on D0 is *not* formed as
``C − E[y y' 1{D1}]``: under a strong attack (power a²) ``C_1 ~ a²`` and ``P(D1 | H1) → 1``, so
that difference cancels to nothing while it is multiplied by ``|K_1* − K_0|² ~ 1``: at a² = 1e12
the old form returned 4e11 for an error of 175, and at 1e100 a negative "squared error". Both
truncated moments are computed directly as sums of non-negative pieces,

    E[y y' 1{D_j}] = Σ_i m_{j,i} t_i t_i',   t_i = (L V)_{:,i},
    m_{0,i} = P(λ_i χ²₃ + Σ_{l≠i} λ_l χ²₁ <= τ),   m_{1,i} = P(... > τ),

with *each* tail probability accurate relative to its own size (a miss probability of 1e-18
multiplies a second moment of 1e12), and the error covariance is assembled as
``Σ_h + W_0 W_0' + W_1 W_1'`` with ``W_j = (K_h* − K_Dj) T diag(√m_j)``: every term is PSD, so the
result is PSD and finite whenever the true value is (no piece exceeds it). The same holds for the
Bayes cost, which uses ``P(D0 | h)`` directly instead of ``1 − P(D1 | h)``.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from fdia_env.detection.gchisq import gchisq_tails
from fdia_env.kalman import psd_sqrt
from fdia_env.kalman.linalg import mT


@dataclass(frozen=True)
class DetectorOutcome:
    """Exact performance of a detector/estimator pair.

    Attributes:
        error_cov: (n, n) ``E[(x − x̂)(x − x̂)']``; its trace is the expected squared error.
        p_false_alarm: ``P(D1 | H0)``.
        p_detection: ``P(D1 | H1)``.
    """

    error_cov: np.ndarray
    p_false_alarm: float
    p_detection: float

    @property
    def mse(self) -> float:
        """``E ||x − x̂||²``."""
        return float(np.trace(self.error_cov))


def tails(weights: np.ndarray, tau: float, dof: np.ndarray | None = None) -> tuple[float, float]:
    """``(P(q <= τ), P(q > τ))`` for ``q = Σ w_i χ²_{k_i}``, weights >= 0; τ may be ±inf."""
    if np.isnan(tau):
        raise ValueError("tau must not be NaN")
    return gchisq_tails(tau, np.clip(weights, 0.0, None), dof)


def tail(weights: np.ndarray, tau: float) -> float:
    """``P(Σ w_i χ²₁ > τ)`` for weights >= 0; 1 for τ < 0, 0 for τ = ∞."""
    return tails(weights, tau)[1]


def truncated_moments(
    A: np.ndarray, C: np.ndarray, tau: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The pieces of ``E[y y' 1{y'Ay <= τ}]`` and ``E[y y' 1{y'Ay > τ}]`` for ``y ~ N(0, C)``.

    Returns:
        ``(p, T, m0, m1)``: ``p = (P(D0), P(D1))``; ``T = L V`` (nz, nz); ``m0``, ``m1`` (nz,)
        with ``E[y y' 1{D_j}] = T diag(m_j) T'``; every entry of p, m0, m1 in [0, 1] and
        accurate relative to its size (module docstring).
    """
    L = psd_sqrt(C)
    B = L.T @ A @ L
    lam, V = np.linalg.eigh(0.5 * (B + B.T))
    lam = np.clip(lam, 0.0, None)
    p = np.array(tails(lam, tau))
    m = np.empty((2, lam.size))
    dof = np.ones(lam.size)
    for i in range(lam.size):
        dof[i] = 3.0  # E[v_i² 1{...}] = P(λ_i χ²₃ + Σ_{j≠i} λ_j χ²₁ ...)
        m[:, i] = tails(lam, tau, dof)
        dof[i] = 1.0
    return p, L @ V, m[0], m[1]


def hypotheses(
    Pxx: np.ndarray, H: np.ndarray, Pww: np.ndarray, sigma: np.ndarray, p1: float
) -> Iterator[tuple[float, np.ndarray, np.ndarray]]:
    """``(p_h, Pxz, C_h)`` for H0 and H1, ``C_h = H Pxx H' + Pww + h Σ`` (innovation covariance)."""
    Pxz = Pxx @ H.T
    for h, prob in ((0, 1.0 - p1), (1, p1)):
        C = H @ Pxz + Pww + (sigma if h else 0.0)
        yield prob, Pxz, 0.5 * (C + C.T)


def expected_squared_error(
    Pxx: np.ndarray,
    H: np.ndarray,
    Pww: np.ndarray,
    sigma: np.ndarray,
    p1: float,
    A: np.ndarray,
    tau: float,
    gain_d0: np.ndarray,
    gain_d1: np.ndarray,
) -> DetectorOutcome:
    """Exact error covariance of the detector ``y'Ay > τ`` with gains ``gain_d0`` / ``gain_d1``.

    Args:
        Pxx: (n, n) prior covariance.
        H: (nz, n) measurement matrix.
        Pww: (nz, nz) measurement noise covariance.
        sigma: (nz, nz) the attacker's true bias covariance.
        p1: The attacker's true attack probability.
        A: (nz, nz) PSD statistic matrix.
        tau: Threshold (D1 when the statistic exceeds it); may be ``inf``.
        gain_d0: (n, nz) estimator gain after D0.
        gain_d1: (n, nz) estimator gain after D1 (zero to discard).
    """
    cov = np.zeros_like(Pxx, dtype=float)
    probs = []
    for prob, Pxz, C in hypotheses(Pxx, H, Pww, sigma, p1):
        K = np.linalg.solve(C, Pxz.T).T  # posterior-mean gain under hypothesis h (C symmetric)
        p, T, m0, m1 = truncated_moments(A, C, tau)
        W0 = ((K - gain_d0) @ T) * np.sqrt(m0)  # error = (K − K_D) y + posterior noise
        W1 = ((K - gain_d1) @ T) * np.sqrt(m1)
        posterior = Pxx - K @ Pxz.T
        cov_h = 0.5 * (posterior + posterior.T) + W0 @ W0.T + W1 @ W1.T
        if prob > 0.0:
            cov += prob * cov_h
        probs.append(float(p[1]))
    cov = 0.5 * (cov + cov.T)
    return DetectorOutcome(error_cov=cov, p_false_alarm=probs[0], p_detection=probs[1])


def case_covariance(Pxx: np.ndarray, Pxz: np.ndarray, C: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Error covariance of ``x̂ = x̄ + K y`` when ``y ~ N(0, C)``: ``Pxx − K Pxz' − Pxz K' + K C K'``.

    Its trace is one of the fixed costs c1..c4 of docs/math.md §3 (K and C of the case).
    """
    cov = Pxx - K @ mT(Pxz) - Pxz @ mT(K) + K @ C @ mT(K)  # leading batch dimensions allowed
    return 0.5 * (cov + mT(cov))


def bayes_cost_covariance(
    Pxx: np.ndarray,
    H: np.ndarray,
    Pww: np.ndarray,
    sigma: np.ndarray,
    p1: float,
    A: np.ndarray,
    tau: float,
    gain_d0: np.ndarray,
    gain_d1: np.ndarray,
) -> DetectorOutcome:
    """The Bayes-cost counterpart of :func:`expected_squared_error` (same arguments).

    ``Σ_h p_h [P(D1|h) C(K_D1, h) + P(D0|h) C(K_D0, h)]`` with the fixed case covariances of
    :func:`case_covariance`; its trace is
    ``p1 [P_d c1 + (1 − P_d) c2] + p0 [P_fa c3 + (1 − P_fa) c4]``.
    """
    cov = np.zeros_like(Pxx, dtype=float)
    probs = []
    for prob, Pxz, C in hypotheses(Pxx, H, Pww, sigma, p1):
        L = psd_sqrt(C)
        B = L.T @ A @ L
        p_d0, p_d1 = tails(np.linalg.eigvalsh(0.5 * (B + B.T)), tau)  # each accurate, no 1 − p
        if prob > 0.0:
            cov += prob * (
                p_d1 * case_covariance(Pxx, Pxz, C, gain_d1)
                + p_d0 * case_covariance(Pxx, Pxz, C, gain_d0)
            )
        probs.append(p_d1)
    return DetectorOutcome(error_cov=cov, p_false_alarm=probs[0], p_detection=probs[1])
