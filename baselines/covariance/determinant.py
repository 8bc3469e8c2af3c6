"""Determinant-optimal bias covariance for a single injection: water-filling (docs/math.md §2.3).

Maximise ``det(P + W Σ W')`` over ``Σ ⪰ 0`` with ``tr(Ω Σ) = a²``. Substituting
``Σ̃ = Ω^{1/2} Σ Ω^{1/2}``, ``W̃ = W Ω^{-1/2}`` (power ``tr Σ̃``):

    det(P + W̃ Σ̃ W̃') = det(P) det(I + Σ̃ Ξ),   Ξ = W̃' P⁻¹ W̃ = V diag(ξ_i) V'.

By Hadamard's inequality the optimum is diagonal in V's basis, ``Σ̃* = V diag(s_i) V'``, and
maximises ``Σ_i log(1 + s_i ξ_i)`` subject to ``Σ_i s_i = a²``, ``s_i ≥ 0``: water-filling,

    s_i = (1/λ − 1/ξ_i)⁺,   the level 1/λ chosen so that Σ_i s_i = a².

:func:`kkt_residuals` checks the answer against the KKT conditions of the matrix problem itself
(not only of the scalar one), so it also catches a wrong basis.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from baselines.covariance.problem import make_problem, weight_roots
from baselines.covariance.result import CovarianceResult
from fdia_env._validation import as_float_array, check_positive
from fdia_env.kalman import spd_inv_sum
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem

# Eigenvalues of Ξ below this fraction of the largest are zero: Ξ has rank ≤ n < nz whenever
# there are more measurement rows than states, and those eigenvalues come out as ±1e-17.
_RANK_TOL = 1e-12


def water_filling(xi: np.ndarray, power: float) -> tuple[np.ndarray, float]:
    """Powers ``s_i = (1/λ − 1/ξ_i)⁺`` with ``Σ s_i = power`` that maximise ``Σ log(1 + s_i ξ_i)``.

    With ``ξ`` sorted in decreasing order, ``k`` directions are active when the level
    ``(a² + Σ_{i≤k} 1/ξ_i) / k`` exceeds ``1/ξ_k``; the condition is monotone in ``k``, so the
    active set is the largest such ``k``.

    Args:
        xi: (d,) non-negative gains (eigenvalues of Ξ); values below ``1e-12 · max(ξ)`` count
            as zero and get no power.
        power: a² > 0.

    Returns:
        ``(s, level)``: (d,) powers in the order of ``xi`` and the water level ``1/λ``.

    Raises:
        ValueError: For a power that is not a finite number > 0, a negative gain, or when no
            gain is positive (then no allocation changes the determinant).

    Example:
        >>> s, level = water_filling(np.array([1.0, 0.25]), 2.0)
        >>> s.tolist(), level
        ([2.0, 0.0], 3.0)
        >>> water_filling(np.array([1.0, 0.25]), 6.0)[0].tolist()
        [4.5, 1.5]
    """
    power = check_positive("power", power)
    xi = as_float_array("xi", xi, "a non-empty finite 1-D array of numbers")
    if xi.ndim != 1 or xi.size == 0 or not np.all(np.isfinite(xi)):
        raise ValueError(f"xi must be a non-empty finite 1-D array, got {xi!r}")
    if np.any(xi < 0.0):
        raise ValueError(
            f"xi must be non-negative (gains are eigenvalues of a PSD matrix), got {xi}"
        )
    top = float(xi.max(initial=0.0))
    if top <= 0.0:
        raise ValueError(f"xi must have a positive entry (no power changes the objective): {xi}")
    positive = xi > _RANK_TOL * top
    order = np.argsort(-np.where(positive, xi, 0.0), kind="stable")[: int(positive.sum())]
    inv = 1.0 / xi[order]  # 1/ξ in decreasing ξ order (increasing inv)
    # Direction k is active iff a² > Σ_{i≤k} (1/ξ_k − 1/ξ_i); the sum telescopes into
    # Σ_{j<k} j (1/ξ_{j+1} − 1/ξ_j), which has no cancellation when a² ≪ 1/ξ (a level
    # ``a² + 1/ξ_1`` would round to 1/ξ_1 and leave no direction active).
    gaps = np.concatenate(([0.0], np.cumsum(np.arange(1, inv.size) * np.diff(inv))))
    active = int(np.count_nonzero(gaps < power))  # ≥ 1: the first gap is 0 < a²
    level = float((power + inv[:active].sum()) / active)
    # s_i = level − 1/ξ_i = (a² − Σ_{j≤k} (1/ξ_i − 1/ξ_j)) / k, again free of cancellation
    spread = (inv[:active, None] - inv[None, :active]).sum(axis=1)
    s = np.zeros_like(xi)
    s[order[:active]] = np.maximum((power - spread) / active, 0.0)
    return s, level


def det_optimal(
    system_or_scenario: str | Scenario | LinearSystem,
    power: float | None = None,
    weight: np.ndarray | None = None,
) -> CovarianceResult:
    """The bias covariance that maximises ``det(P[K|K] + W Σ W')`` under ``tr(Ω Σ) = a²``.

    Args: as :func:`~baselines.covariance.make_problem` (the system, a² and Ω).

    Returns:
        ``value = log det(P + W Σ W')`` (``result.det`` is the determinant). ``info`` holds the
        water ``level`` (1/λ), the gains ``xi`` and powers ``s`` per eigen-direction of Ξ.

    Raises:
        ValueError: Naming the parameter, for a power that is not a finite number > 0 or a bad
            weight.

    Example:
        >>> result = det_optimal("ch2-pv-1")
        >>> round(result.value, 4), round(float(result.correlation[0, 1]), 4)
        (7.9246, 0.0093)
    """
    problem = make_problem(system_or_scenario, power, weight)
    Wt = problem.W_tilde
    Xi = Wt.T @ np.linalg.solve(problem.P, Wt)  # Ξ = W̃' P⁻¹ W̃
    xi, V = np.linalg.eigh(0.5 * (Xi + Xi.T))
    s, level = water_filling(np.clip(xi, 0.0, None), problem.power)
    sigma = problem.from_tilde((V * s) @ V.T)  # Σ = Ω^{-1/2} V diag(s) V' Ω^{-1/2}
    return CovarianceResult.of(problem, sigma, "logdet", "water-filling", level=level, xi=xi, s=s)


@dataclass(frozen=True)
class KKTResiduals:
    """Relative KKT residuals of ``max log det(P + W̃ Σ̃ W̃')`` s.t. ``tr Σ̃ = a²``, ``Σ̃ ⪰ 0``.

    With ``G = W̃' (P + W̃ Σ̃ W̃')⁻¹ W̃`` (the gradient) the conditions are ``G − λ I + Z = 0``,
    ``Z ⪰ 0``, ``Z Σ̃ = 0``, ``λ > 0``; the multiplier is estimated as ``λ = tr(G Σ̃) / a²``.

    Attributes:
        power: ``|tr Σ̃ − a²| / a²`` (primal feasibility).
        psd: ``max(0, −λ_min(Σ̃)) / a²`` (primal feasibility).
        stationarity: ``‖G Σ̃ − λ Σ̃‖_F / (λ a²)`` (``Z Σ̃ = 0`` on the support).
        dual: ``max(0, λ_max(G) − λ) / λ`` (``Z = λ I − G ⪰ 0``).
        multiplier: λ.
    """

    power: float
    psd: float
    stationarity: float
    dual: float
    multiplier: float

    @property
    def worst(self) -> float:
        """The largest residual."""
        return max(self.power, self.psd, self.stationarity, self.dual)


def kkt_residuals(result: CovarianceResult, power: float | None = None) -> KKTResiduals:
    """KKT residuals of ``result.sigma`` for the determinant problem it claims to solve.

    Args:
        result: A result for some system (its ``P``, ``W`` and ``weight`` define the problem).
        power: a² (default ``result.budget``, the power the solver was asked for).
    """
    a2 = check_positive("power", result.budget if power is None else power)
    half, inv_half = weight_roots(result.weight)
    sigma_t = half @ result.sigma @ half  # Σ̃ = Ω^{1/2} Σ Ω^{1/2}
    Wt = result.W @ inv_half
    added = result.W @ result.sigma @ result.W.T
    inverse, _ = spd_inv_sum(result.P, 0.5 * (added + added.T))  # not inv(P + W Σ W'): singular
    G = Wt.T @ inverse @ Wt  # ∂ log det / ∂Σ̃
    G = 0.5 * (G + G.T)
    lam = float(np.trace(G @ sigma_t)) / a2
    return KKTResiduals(
        power=abs(float(np.trace(sigma_t)) - a2) / a2,
        psd=max(0.0, -float(np.linalg.eigvalsh(sigma_t).min())) / a2,
        stationarity=float(np.linalg.norm(G @ sigma_t - lam * sigma_t)) / (lam * a2),
        dual=max(0.0, float(np.linalg.eigvalsh(G).max()) - lam) / lam,
        multiplier=lam,
    )
