"""What every single-injection covariance solver returns."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from baselines._inputs import resolve_system
from baselines.covariance.problem import check_weight
from fdia_env._validation import as_matrix, check_choice, check_psd
from fdia_env.kalman import psd_sqrt, spd_inv_sum, steady_state
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem, power_weight

if TYPE_CHECKING:
    from baselines.covariance.policy import CovariancePolicy
    from baselines.covariance.problem import CovarianceProblem

OBJECTIVES = ("trace", "logdet")


@dataclass(frozen=True, eq=False)
class CovarianceResult:
    """A bias covariance and the filter's actual error covariance under it.

    Attributes:
        sigma: (nz, nz) bias covariance Σ over the stacked measurement, symmetric PSD.
        objective: What ``value`` measures: ``"trace"`` or ``"logdet"`` of ``covariance``.
        method: The rule that produced Σ (e.g. ``"eigenvector"``, ``"water-filling"``).
        P: (n, n) the filter's ``P[K|K]`` before the attack.
        W: (n, nz) the filter's nominal gain.
        weight: (nz, nz) power weighting Ω.
        budget: The power a² the solver was given.
        info: Rule-specific quantities (chosen sensor, angles, water level, ...).

    Derived (computed in ``__post_init__``):
        covariance: (n, n) actual error covariance ``P + W Σ W'``.
        value: ``tr`` or ``log det`` of ``covariance``, per ``objective``.
        power: Power used, ``tr(Ω Σ)`` (equal to ``budget`` for every solver here).
    """

    sigma: np.ndarray
    objective: str
    method: str
    P: np.ndarray = field(repr=False)
    W: np.ndarray = field(repr=False)
    weight: np.ndarray = field(repr=False)
    budget: float = 0.0
    info: dict[str, Any] = field(default_factory=dict)
    covariance: np.ndarray = field(init=False, repr=False)
    value: float = field(init=False)
    power: float = field(init=False)

    def __post_init__(self) -> None:
        if self.objective not in OBJECTIVES:
            raise ValueError(f"objective must be one of {list(OBJECTIVES)}, got {self.objective!r}")
        sigma = np.array(self.sigma, dtype=np.float64)
        sigma = 0.5 * (sigma + sigma.T)
        cov = self.P + self.W @ sigma @ self.W.T  # M[K] = P[K|K] + W Σ W'
        cov = 0.5 * (cov + cov.T)
        sigma.setflags(write=False)
        cov.setflags(write=False)
        value = np.trace(cov) if self.objective == "trace" else _logdet(self.P, self.W, sigma)
        object.__setattr__(self, "sigma", sigma)
        object.__setattr__(self, "covariance", cov)
        object.__setattr__(self, "value", float(value))
        object.__setattr__(self, "power", float(np.trace(self.weight @ sigma)))

    @classmethod
    def of(
        cls, problem: CovarianceProblem, sigma: np.ndarray, objective: str, method: str, **info: Any
    ) -> CovarianceResult:
        """The result of playing ``sigma`` in ``problem``."""
        return cls(
            sigma, objective, method, problem.P, problem.W, problem.weight, problem.power, info
        )

    def policy(self, source: Any) -> CovariancePolicy:
        """The policy that injects ``sigma`` in ``source``'s env (see :class:`CovariancePolicy`)."""
        from baselines.covariance.policy import CovariancePolicy

        return CovariancePolicy(source, self.sigma)

    @property
    def trace(self) -> float:
        """``tr(P + W Σ W')``."""
        return float(np.trace(self.covariance))

    @property
    def logdet(self) -> float:
        """``log det(P + W Σ W')``.

        Computed from ``P`` and ``W Σ W'``: their sum is singular in float64 when a huge power
        goes into few directions.
        """
        added = self.W @ self.sigma @ self.W.T
        return float(spd_inv_sum(self.P, 0.5 * (added + added.T))[1])

    @property
    def det(self) -> float:
        """``det(P + W Σ W')``."""
        return float(np.exp(self.logdet))

    @property
    def extra(self) -> float:
        """The attack's extra MSE ``tr(W Σ W')``."""
        return float(np.trace(self.covariance) - np.trace(self.P))

    @property
    def variances(self) -> np.ndarray:
        """(nz,) bias variances ``diag(Σ)`` (per stacked measurement row)."""
        return np.diag(self.sigma).copy()

    @property
    def correlation(self) -> np.ndarray:
        """(nz, nz) bias correlation matrix; rows and columns of zero-variance biases are 0."""
        std = np.sqrt(np.clip(np.diag(self.sigma), 0.0, None))
        scale = np.outer(std, std)
        out = np.divide(self.sigma, scale, out=np.zeros_like(self.sigma), where=scale > 0)
        return np.clip(out, -1.0, 1.0)


def evaluate(
    system_or_scenario: str | Scenario | LinearSystem,
    sigma: np.ndarray,
    objective: str = "trace",
    weight: np.ndarray | None = None,
) -> CovarianceResult:
    """Score any bias covariance (e.g. an equal split, or no attack: zeros) like the solvers do.

    Args:
        system_or_scenario: Preset name, :class:`Scenario` or :class:`LinearSystem`.
        sigma: (nz, nz) symmetric PSD bias covariance.
        objective: ``"trace"`` or ``"logdet"``.
        weight: (nz, nz) power weighting Ω (default :func:`~fdia_env.systems.power_weight`);
            only ``power`` depends on it.

    Raises:
        ValueError: Naming the parameter, for a sigma of the wrong shape or not PSD, an unknown
            objective or a bad weight.

    Example:
        >>> round(evaluate("ch2-position", np.diag([1500.0, 1500.0])).value, 1)
        305.7
        >>> round(evaluate("ch2-position", np.zeros((2, 2))).value, 3)
        1.455
    """
    check_choice("objective", objective, OBJECTIVES)
    system = resolve_system(system_or_scenario).system
    sigma = as_matrix("sigma", sigma, shape=(system.nz, system.nz))
    check_psd("sigma", sigma)
    omega = power_weight(system) if weight is None else check_weight(weight, system.nz)
    _, P, W = steady_state(system)
    budget = float(np.trace(omega @ sigma))
    return CovarianceResult(sigma, objective, "given", P, W, omega, budget)


def _logdet(P: np.ndarray, W: np.ndarray, sigma: np.ndarray) -> float:
    """``log det(P + W Σ W')`` by the determinant lemma, finite for any power.

    ``log det P + Σ_i log(1 + λ_i)``, λ the eigenvalues of the PSD ``S' W' P⁻¹ W S`` (Σ = S S').
    Forming ``P + W Σ W'`` first loses P's small eigenvalues to round-off once Σ is ~1e17
    times larger (log det = −inf at a² = 1e18 on ch2-position); this form keeps them.
    """
    try:
        L = np.linalg.cholesky(P)
    except np.linalg.LinAlgError:  # a singular P: the direct form (its log det is −inf anyway)
        return float(np.linalg.slogdet(P + W @ sigma @ W.T)[1])
    S = psd_sqrt(sigma)
    X = np.linalg.solve(L, W @ S)  # L⁻¹ W S: X'X = S' W' P⁻¹ W S
    # λ = squared singular values of X; those below size · eps of the largest are rounding of
    # the large ones (a rank-two Σ of 1e300: eigvalsh(X'X) gave "eigenvalues" near 1e284,
    # each adding ~650 to the log-determinant)
    sv = np.linalg.svd(X, compute_uv=False)
    sv = np.where(sv > max(X.shape) * np.finfo(np.float64).eps * sv.max(initial=0.0), sv, 0.0)
    big = sv > 1.0
    safe = np.where(big, sv, 1.0)
    log1p_lam = np.where(big, 2.0 * np.log(safe) + np.log1p(safe**-2.0), np.log1p(sv * sv))
    return float(2.0 * np.log(np.diag(L)).sum() + log1p_lam.sum())
