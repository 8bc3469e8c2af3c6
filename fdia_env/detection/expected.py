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
import scipy.linalg

from fdia_env._validation import check_choice
from fdia_env.detection.gchisq import gchisq_tails
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


_EPS = float(np.finfo(np.float64).eps)
_GRADED = 1e8  # above this spread of the innovation's scales, weights come from graded_eigh


@dataclass(frozen=True)
class Innovation:
    """A factor ``L = L0 U diag(g)`` of ``C = C0 + Σ`` that keeps every scale of Σ apart.

    ``C0 = L0 L0'`` (Cholesky, well conditioned: measurement noise included) and the whitened
    attack ``L0⁻¹ Σ L0⁻ᵀ = U diag(s) U'``, eigenvalues below ``size · eps · max s`` set to zero
    (they are rounding of the large ones, e.g. of a rank-one Σ), ``g = √(1 + s)``. ``C`` is never
    formed: at a power of 1e40 ``C0 + Σ`` is singular in float64, and quantities such as
    ``Pxz C⁻¹ L = Pxz L0⁻ᵀ U diag(1/g)`` are exact here however large g is.
    """

    L0: np.ndarray
    U: np.ndarray
    g: np.ndarray

    @classmethod
    def of(
        cls, C0: np.ndarray, sigma: np.ndarray | None, L0: np.ndarray | None = None
    ) -> Innovation:
        """The factor of ``C0 + sigma`` (``sigma`` None or zero: H0); ``L0``: C0's, if known."""
        L0 = np.linalg.cholesky(0.5 * (C0 + C0.T)) if L0 is None else L0
        m = C0.shape[0]
        if sigma is None or not np.any(sigma):
            return cls(L0, np.eye(m), np.ones(m))
        W = scipy.linalg.solve_triangular(L0, np.asarray(sigma, dtype=float), lower=True)
        S = scipy.linalg.solve_triangular(L0, W.T, lower=True)  # L0⁻¹ Σ L0⁻ᵀ
        s, U = np.linalg.eigh(0.5 * (S + S.T))
        s = np.where(s > m * _EPS * s[-1], s, 0.0)
        return cls(L0, U, np.sqrt(1.0 + s))

    def whiten(self, M: np.ndarray) -> np.ndarray:
        """``U' L0' M L0 U``: a matrix on the innovation in the factor's coordinates."""
        T = self.L0 @ self.U
        return T.T @ M @ T

    def gain_times_factor(self, K: np.ndarray) -> np.ndarray:
        """``K L`` for a gain ``K`` that does not depend on Σ (``K L0 U diag(g)``)."""
        return (K @ self.L0 @ self.U) * self.g

    def optimal_gain_times_factor(self, Pxz: np.ndarray) -> np.ndarray:
        """``K* L`` with ``K* = Pxz C⁻¹`` (the posterior-mean gain): ``Pxz L0⁻ᵀ U diag(1/g)``."""
        W = scipy.linalg.solve_triangular(self.L0, Pxz.T, lower=True)  # L0⁻¹ Pxz'
        return (W.T @ self.U) / self.g


def graded_eigh(M: np.ndarray, g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Eigenvalues and eigenvectors of ``diag(g) M diag(g)`` for PSD ``M`` of moderate scale.

    With g spanning many orders of magnitude (``g ~ 1e20`` along a strong attack) a symmetric
    eigensolver's absolute error ``eps · max λ`` swamps the small eigenvalues. Here
    ``M = R'R`` and the one-sided Jacobi method orthogonalises the columns of ``R diag(g)``:
    each eigenvalue (a squared column norm) is accurate relative to its own size.
    """
    mu, Q = np.linalg.eigh(0.5 * (M + M.T))
    X = (np.sqrt(np.clip(mu, 0.0, None))[:, None] * Q.T) * g[None, :]
    m = X.shape[1]
    V = np.eye(m)
    for _ in range(60):
        rotated = False
        for p in range(m - 1):
            for q in range(p + 1, m):
                a, b = np.linalg.norm(X[:, p]), np.linalg.norm(X[:, q])
                c = float(X[:, p] @ X[:, q])
                if a == 0.0 or b == 0.0 or abs(c) <= _EPS * a * b:
                    continue
                rotated = True
                zeta = (b - a) * ((b + a) / (2.0 * c))
                t = np.copysign(1.0, zeta) / (abs(zeta) + np.hypot(1.0, zeta))
                cs = 1.0 / np.hypot(1.0, t)
                sn = cs * t
                for Y in (X, V):
                    yp, yq = Y[:, p].copy(), Y[:, q]
                    Y[:, p] = cs * yp - sn * yq
                    Y[:, q] = sn * yp + cs * yq
        if not rotated:
            break
    lam = np.sum(X * X, axis=0)
    order = np.argsort(lam)
    return lam[order], V[:, order]


def _weights(factor: Innovation, A: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weights λ and rotation V of ``y'Ay = Σ λ_i v_i²`` for ``y = L V v``, ``v ~ N(0, I)``."""
    Aw = factor.whiten(A)
    if factor.g[-1] ** 2 > _GRADED:
        return graded_eigh(Aw, factor.g)
    B = (factor.g[:, None] * Aw) * factor.g[None, :]
    lam, V = np.linalg.eigh(0.5 * (B + B.T))
    return np.clip(lam, 0.0, None), V


def statistic_weights(A: np.ndarray, C0: np.ndarray, sigma: np.ndarray | None) -> np.ndarray:
    """Weights λ of ``y'Ay = Σ λ_i χ²₁`` for ``y ~ N(0, C0 + sigma)``, accurate at any power.

    Each weight is accurate relative to its own size, also when ``sigma`` is a strong rank-one
    attack (a weight of order a² next to weights of order one); ``C0 + sigma`` is never formed.
    """
    return _weights(Innovation.of(C0, sigma), A)[0]


def _moments(lam: np.ndarray, tau: float) -> tuple[np.ndarray, np.ndarray]:
    """``p = (P(D0), P(D1))`` and ``m`` (2, nz): ``E[v_i² 1{D_j}]`` for the weights ``lam``."""
    p = np.array(tails(lam, tau))
    m = np.empty((2, lam.size))
    dof = np.ones(lam.size)
    for i in range(lam.size):
        dof[i] = 3.0  # E[v_i² 1{...}] = P(λ_i χ²₃ + Σ_{j≠i} λ_j χ²₁ ...)
        m[:, i] = tails(lam, tau, dof)
        dof[i] = 1.0
    return p, m


def hypotheses(
    Pxx: np.ndarray, H: np.ndarray, Pww: np.ndarray, sigma: np.ndarray, p1: float
) -> Iterator[tuple[float, np.ndarray, Innovation, np.ndarray | None]]:
    """``(p_h, Pxz, factor of C_h, Σ or None)`` for H0 and H1, ``C_h = H Pxx H' + Pww + h Σ``."""
    Pxz = Pxx @ H.T
    C0 = H @ Pxz + Pww
    for h, prob in ((0, 1.0 - p1), (1, p1)):
        yield prob, Pxz, Innovation.of(C0, sigma if h else None), sigma if h else None


def _error_factors(
    factor: Innovation,
    Pxx: np.ndarray,
    Pxz: np.ndarray,
    gains: tuple[np.ndarray, np.ndarray],
    sigma: np.ndarray | None,
    assumed_sigma: np.ndarray | None,
) -> tuple[np.ndarray, list[np.ndarray]]:
    """The posterior covariance ``Pxx − K* Pxz'`` and ``(K* − K_D) L`` for each gain ``K_D``.

    With ``assumed_sigma`` the second gain is the H1-model gain ``Pxz (C0 + Σa)⁻¹``, built here
    in the factor's coordinates (given as a matrix it would carry an error ``eps`` along a
    strong attack, which ``L`` multiplies by ``√a²``); equal to Σ it is the posterior-mean
    gain itself and its error term vanishes.
    """
    KL = factor.optimal_gain_times_factor(Pxz)
    posterior = Pxx - KL @ KL.T  # K* Pxz' = K* C K*' = (K* L)(K* L)'
    E = [KL - factor.gain_times_factor(gains[0])]
    if assumed_sigma is None:
        E.append(KL - factor.gain_times_factor(gains[1]))
    elif sigma is not None and np.array_equal(assumed_sigma, sigma):
        E.append(np.zeros_like(KL))
    else:
        model = Innovation.of(factor.L0 @ factor.L0.T, assumed_sigma, factor.L0)
        W = scipy.linalg.solve_triangular(factor.L0, Pxz.T, lower=True).T  # Pxz L0⁻ᵀ
        E.append(KL - ((W @ model.U) / model.g**2 @ (model.U.T @ factor.U)) * factor.g)
    return 0.5 * (posterior + posterior.T), E


CRITERIA = ("mse", "bayes_cost")


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
    *,
    assumed_sigma: np.ndarray | None = None,
    criterion: str = "mse",
) -> DetectorOutcome:
    """Exact error covariance of the detector ``y'Ay > τ`` with gains ``gain_d0`` / ``gain_d1``.

    ``criterion="mse"``: the expected squared error's covariance (module docstring).
    ``criterion="bayes_cost"``: its Bayes-cost counterpart
    ``Σ_h p_h [P(D1|h) C(K_D1, h) + P(D0|h) C(K_D0, h)]`` with the fixed case covariances of
    :func:`case_covariance`; its trace is
    ``p1 [P_d c1 + (1 − P_d) c2] + p0 [P_fa c3 + (1 − P_fa) c4]``.

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
        assumed_sigma: (nz, nz) the defender's model Σa when ``gain_d1`` is its H1-model gain
            ``Pxz (H Pxx H' + Pww + Σa)⁻¹`` (incorporate): that gain is then recomputed from
            Σa, exactly consistent with ``sigma`` at any power.
        criterion: ``"mse"`` or ``"bayes_cost"``.

    Raises:
        ValueError: For a criterion not in :data:`CRITERIA`.
    """
    check_choice("criterion", criterion, CRITERIA)
    cov = np.zeros_like(Pxx, dtype=float)
    probs = []
    for prob, Pxz, factor, sigma_h in hypotheses(Pxx, H, Pww, sigma, p1):
        lam, V = _weights(factor, A)
        gains = (gain_d0, gain_d1)
        posterior, (E0, E1) = _error_factors(factor, Pxx, Pxz, gains, sigma_h, assumed_sigma)
        if criterion == "mse":
            p, m = _moments(lam, tau)
            W0 = (E0 @ V) * np.sqrt(m[0])  # error = (K* − K_D) y + posterior noise
            W1 = (E1 @ V) * np.sqrt(m[1])
            term, p_d1 = posterior + W0 @ W0.T + W1 @ W1.T, float(p[1])
        else:  # the case covariance Pxx − K Pxz' − Pxz K' + K C K' = posterior + E C E'
            p_d0, p_d1 = tails(lam, tau)  # each accurate, no 1 − p
            term = p_d1 * (posterior + E1 @ E1.T) + p_d0 * (posterior + E0 @ E0.T)
        if prob > 0.0:
            cov += prob * term
        probs.append(p_d1)
    cov = 0.5 * (cov + cov.T)
    return DetectorOutcome(error_cov=cov, p_false_alarm=probs[0], p_detection=probs[1])


def case_covariance(Pxx: np.ndarray, Pxz: np.ndarray, C: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Error covariance of ``x̂ = x̄ + K y`` when ``y ~ N(0, C)``: ``Pxx − K Pxz' − Pxz K' + K C K'``.

    Its trace is one of the fixed costs c1..c4 of docs/math.md §3 (K and C of the case).
    """
    cov = Pxx - K @ mT(Pxz) - Pxz @ mT(K) + K @ C @ mT(K)  # leading batch dimensions allowed
    return 0.5 * (cov + mT(cov))
