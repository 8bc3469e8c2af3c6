"""The minimum mean squared error estimator of docs/math.md §3 (no hard decision).

Given z the posterior is a two-component Gaussian mixture, so

    E[x | z] = Σ_{h=0,1} π_h(z) [x̄ + Pxz Pzzh⁻¹ (z − z̄)],   π_h(z) = p_h N(z; z̄, Pzzh) / p(z).

π_1 is computed as a logistic function of the log-likelihood ratio, so it neither overflows nor
loses precision far in the tails.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.special

from baselines.detection.problem import DetectionProblem, check_problem


@dataclass(frozen=True)
class MMSEResult:
    """The MMSE estimator applied to a batch of measurements.

    Attributes:
        estimate: (..., n) posterior means E[x | z].
        posterior: (...,) posterior probability of H1, π_1(z).
    """

    estimate: np.ndarray
    posterior: np.ndarray


@dataclass(frozen=True, eq=False)
class MMSEEstimator:
    """``E[x | z]`` under the two-hypothesis prior of ``problem``.

    Attributes:
        problem: The model (x̄, Pxx, H, Pww, Pbb, p1).
        name: Label.
    """

    problem: DetectionProblem
    name: str = "MMSE"

    def __post_init__(self) -> None:
        check_problem("problem", self.problem)

    def __call__(self, z: np.ndarray, x_bar: np.ndarray | None = None) -> MMSEResult:
        """Posterior means for (..., nz) measurements (``x_bar`` (..., n) as in the detectors)."""
        p = self.problem
        z = np.asarray(z, dtype=np.float64)
        if z.shape[-1:] != (p.nz,):
            raise ValueError(f"z must have shape (..., {p.nz}), got {z.shape}")
        y = z - (p.z_bar if x_bar is None else np.asarray(x_bar) @ p.H.T)
        q0 = np.einsum("...i,ij,...j->...", y, p.Pzz0_inv, y)
        q1 = np.einsum("...i,ij,...j->...", y, p.Pzz1_inv, y)
        # log[p1 N1 / (p0 N0)] = log(p1/p0) − ½ (q1 − q0) − ½ (ln|Pzz1| − ln|Pzz0|)
        log_prior = _log_odds(p.p1)
        llr = log_prior - 0.5 * (q1 - q0) - 0.5 * (p.logdet1 - p.logdet0)
        pi1 = scipy.special.expit(llr)
        gain_y = (1.0 - pi1)[..., None] * (y @ p.K0.T) + pi1[..., None] * (y @ p.K1.T)
        prior = p.x_bar if x_bar is None else np.asarray(x_bar, dtype=np.float64)
        return MMSEResult(prior + gain_y, pi1)


def _log_odds(p1: float) -> float:
    if p1 == 0.0:
        return -math.inf
    if p1 == 1.0:
        return math.inf
    return math.log(p1 / (1.0 - p1))


def mmse(problem: DetectionProblem) -> MMSEEstimator:
    """The MMSE estimator of ``problem``.

    Example:
        >>> from baselines.detection import static_problem
        >>> est = mmse(static_problem("ch3-static", 100.0))
        >>> r = est([10.0, 5.0])  # z = z̄: the estimate is the prior mean
        >>> r.estimate.tolist(), round(float(r.posterior), 4)
        ([10.0, 5.0], 0.8014)
    """
    return MMSEEstimator(problem)
