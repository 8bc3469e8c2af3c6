"""The optimal linear attack on remote estimation under a KL stealthiness budget (Guo et al. 2017).

A sensor runs the steady-state Kalman filter of ``x[k+1] = A x + w``, ``y = C x + v`` and sends
its innovations ``z[k] ~ N(0, Σ)`` (``Σ = C P C' + R``, P the predicted steady state) to a remote
estimator ``x̂[k] = A x̂[k−1] + K z̃[k]``. The attacker replaces them by ``z̃ = T z + b``,
``b ~ N(0, Σ_b)`` independent over time, and must keep the detector's view stealthy:
``KL(N(0, Σ̃) ‖ N(0, Σ)) ≤ δ`` with ``Σ̃ = T Σ T' + Σ_b``. The remote error is the local error
plus ``d[k] = A d[k−1] + K ((I − T) z − b)``, orthogonal to it, so (A stable) the remote error
covariance has trace

    J(T, Σ_b) = tr P_f + tr(W M),   M = (I − T) Σ (I − T)' + Σ_b,   W = K' X K,  X = A' X A + I

(P_f the local filtered covariance). Whitening with ``Σ = L L'`` (``T̂ = L⁻¹ T L``,
``Ŵ = L' W L``, ``S = L⁻¹ Σ̃ L⁻ᵀ``): ``tr(W M) = tr Ŵ − 2 tr(Ŵ T̂) + tr(Ŵ S)`` with
``T̂ T̂' ⪯ S``. For a fixed S the best T̂ is ``−S^{1/2}`` aligned with Ŵ (``Σ_b = 0``), and by von
Neumann's trace inequalities S shares Ŵ's eigenvectors, so with ``Ŵ = U diag(w) U'`` the problem
is ``max Σ_i w_i (1 + √s_i)²`` s.t. ``½ Σ_i (s_i − 1 − ln s_i) ≤ δ``: concave over a convex set,
solved by its Lagrange condition ``w_i (1 + 1/√s_i) = (μ/2)(1 − 1/s_i)`` per direction and one
scalar μ. With a single direction (one sensor) or equal w_i it is the closed form
``s = −W₋₁(−e^{−1−2δ/m'})`` (Lambert W, m' directions sharing the budget). The attack is
``T = −L U diag(√s) U' L⁻¹``, ``b = 0``; at δ = 0 it is ``T = −I``: the innovation's sign
reversed, undetectable since ``z̃`` has the distribution of z.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy import linalg, special

from baselines.stealth.dynamic import KalmanModel, kalman_model


@dataclass(frozen=True, eq=False)
class LinearAttack:
    """The KL-optimal linear attack ``z̃ = T z + b`` and what it achieves.

    Attributes:
        T: (m, m) the linear map.
        Sigma_b: (m, m) covariance of b (zero at the optimum).
        value: J, the trace of the remote estimator's steady-state error covariance.
        clean: ``tr P_f``, its value without attack.
        kl: The attack's KL divergence (≤ delta).
        delta: The budget.
    """

    T: np.ndarray
    Sigma_b: np.ndarray
    value: float
    clean: float
    kl: float
    delta: float


def _weights(model: KalmanModel) -> tuple[np.ndarray, np.ndarray, float]:
    rho = float(np.max(np.abs(np.linalg.eigvals(model.A))))
    if rho >= 1.0:
        raise ValueError(
            f"A must be stable (spectral radius {rho:.6g} >= 1): the remote error under a "
            "linear attack then grows without bound; see mo_sinopoli"
        )
    X = linalg.solve_discrete_lyapunov(model.A.T, np.eye(model.n))
    W = model.K.T @ X @ model.K
    L = np.linalg.cholesky(model.Pz)
    Pf = model.P - model.K @ model.Pz @ model.K.T
    return (W + W.T) / 2.0, L, float(np.trace(Pf))


def attack_value(model: KalmanModel, T: np.ndarray, Sigma_b: np.ndarray) -> tuple[float, float]:
    """``(J, KL)`` of the linear attack ``(T, Σ_b)`` on ``model`` (A stable)."""
    W, _, clean = _weights(model)
    Sigma = model.Pz
    eye = np.eye(model.m)
    M = (eye - T) @ Sigma @ (eye - T).T + Sigma_b
    St = T @ Sigma @ T.T + Sigma_b
    G = np.linalg.solve(Sigma, St)
    sign, logdet = np.linalg.slogdet(G)
    kl = 0.5 * (np.trace(G) - model.m - logdet) if sign > 0 else np.inf
    return clean + float(np.trace(W @ M)), float(kl)


def _s_of_mu(w: np.ndarray, mu: float) -> np.ndarray:
    """Per direction, the root s ≥ 1 of ``w (1 + 1/√s) = (μ/2)(1 − 1/s)`` (1 where w = 0)."""
    s = np.ones_like(w)
    for i, wi in enumerate(w):
        if wi <= 0.0:
            continue
        lo, hi = 1.0, 2.0
        f = lambda x, wi=wi: wi * (1 + 1 / np.sqrt(x)) - mu / 2 * (1 - 1 / x)  # noqa: E731
        while f(hi) > 0:
            hi *= 2.0
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if f(mid) > 0 else (lo, mid)
        s[i] = 0.5 * (lo + hi)
    return s


def optimal_linear_attack(A: Any, C: Any, Q: Any, R: Any, delta: float) -> LinearAttack:
    """The linear attack ``z̃ = T z + b`` maximising the remote error under ``KL ≤ delta``.

    Args:
        A: (n, n) dynamics, stable (spectral radius < 1).
        C: (m, n) measurement matrix.
        Q: (n, n) process noise covariance.
        R: (m, m) measurement noise covariance (positive definite).
        delta: KL budget, ≥ 0 (0: strict stealth).

    Returns:
        The :class:`LinearAttack`.

    Raises:
        ValueError: Naming the parameter: a bad system, an unstable A, a negative or
            non-finite delta.

    Example:
        >>> attack = optimal_linear_attack([[0.9]], [[1.0]], [[1.0]], [[1.0]], 0.0)
        >>> attack.T.round(12).tolist(), round(attack.value / attack.clean, 4)
        ([[-1.0]], 32.24)
    """
    if isinstance(delta, bool) or not isinstance(delta, (int, float, np.integer, np.floating)):
        raise ValueError(f"delta must be a KL budget >= 0, got {delta!r}")
    delta = float(delta)
    if not (np.isfinite(delta) and delta >= 0.0):
        raise ValueError(f"delta must be a finite KL budget >= 0, got {delta}")
    model = kalman_model(A, C, Q, R)
    W, L, clean = _weights(model)
    What = L.T @ W @ L
    w, U = np.linalg.eigh((What + What.T) / 2.0)
    w = np.clip(w, 0.0, None)
    active = w > 1e-14 * max(float(w.max()), 1e-300)
    if delta == 0.0 or not active.any():
        s = np.ones_like(w)
    elif np.allclose(w[active], w[active][0], rtol=1e-12):
        # equal weights: the budget splits evenly; s − ln s = 1 + 2δ/m' (Lambert W, branch −1)
        share = 2.0 * delta / int(active.sum())
        s = np.ones_like(w)
        s[active] = -np.real(special.lambertw(-np.exp(-1.0 - share), k=-1))
    else:
        kl = lambda s: 0.5 * np.sum(s - 1.0 - np.log(s))  # noqa: E731
        lo, hi = 2.0 * float(w.max()) * (1 + 1e-12), 4.0 * float(w.max()) + 1.0
        while kl(_s_of_mu(w, hi)) > delta:
            hi *= 2.0
        for _ in range(200):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if kl(_s_of_mu(w, mid)) > delta else (lo, mid)
        s = _s_of_mu(w, hi)
    That = -(U * np.sqrt(s)) @ U.T
    T = L @ That @ np.linalg.inv(L)
    Sigma_b = np.zeros((model.m, model.m))
    value, kl_value = attack_value(model, T, Sigma_b)
    return LinearAttack(T=T, Sigma_b=Sigma_b, value=value, clean=clean, kl=kl_value, delta=delta)
