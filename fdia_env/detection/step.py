"""One filter step with a detector on the innovation (the detection game, docs/math.md §3)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from fdia_env.defenses.base import Detection
from fdia_env.detection.expected import (
    bayes_cost_covariance,
    case_covariance,
    expected_squared_error,
)
from fdia_env.detection.statistics import STATISTICS
from fdia_env.kalman import predict_cov, psd_sqrt, spd_inv_sum, sym
from fdia_env.systems import LinearSystem


@dataclass
class DetectionStep:
    """What one step produced.

    Attributes:
        P: (n, n) the filter's own covariance after the decision (expected dynamics: after D0).
        error_cov: (n, n) the exact expected error covariance (expected dynamics), else None.
        x, x_hat: (n,) true state and estimate (sampled dynamics), else None.
        info: Decision details for ``infos``.
        value: Sampled ``"bayes_cost"`` criterion: the fixed cost of the realised case, else None.
    """

    P: np.ndarray
    error_cov: np.ndarray | None
    x: np.ndarray | None
    x_hat: np.ndarray | None
    info: dict[str, Any]
    value: float | None = None


def detection_step(
    system: LinearSystem,
    rule: Detection,
    sigma: np.ndarray | None,
    probability: float,
    P_prev: np.ndarray,
    *,
    rng: np.random.Generator | None = None,
    x: np.ndarray | None = None,
    x_hat: np.ndarray | None = None,
    factors: tuple[np.ndarray, np.ndarray] | None = None,
) -> DetectionStep:
    """Predict, test the innovation, and estimate with the decision's gain.

    D0 uses the clean gain ``K0 = Pxz Pzz0⁻¹``; D1 discards (gain 0) or incorporates with the
    defender's attack model (``K1 = Pxz (Pzz0 + Σ_assumed)⁻¹``). Sampled dynamics (``rng`` given)
    draw, in this order: H1 with probability ``probability`` (one uniform), the process noise
    (n), the measurement noise (nz), and under H1 the bias (nz); a fresh prior draws the state
    (n) before all of them. Expected dynamics return the exact error covariance instead.
    """
    sys = system
    n, nz = sys.n, sys.nz
    sampled = rng is not None
    if rule.fresh_prior:
        P_prev, x_hat = np.array(sys.P0), np.array(sys.x0)
        if sampled:
            x = x_hat + psd_sqrt(sys.P0) @ rng.standard_normal(n)
    P_pred = predict_cov(P_prev, sys.F, sys.Q)  # the prior of this step's measurement
    Pxz = P_pred @ sys.H.T
    Pzz0 = sym(sys.H @ Pxz + sys.R)
    Pzz0_inv = np.linalg.inv(Pzz0)
    Pzz1_inv, _ = spd_inv_sum(Pzz0, rule.assumed_sigma)  # never forms Pzz0 + Σ (any power)
    K0, K1 = Pxz @ Pzz0_inv, Pxz @ Pzz1_inv
    A = STATISTICS[rule.statistic].matrix(Pzz0_inv, Pzz1_inv)
    incorporate = rule.on_detect == "incorporate"
    gain_d1 = K1 if incorporate else np.zeros_like(K0)
    P_d0 = sym(P_pred - K0 @ Pzz0 @ K0.T)
    P_d1 = sym(P_pred - K1 @ Pxz.T) if incorporate else P_pred  # K1 Pzz1 K1' = K1 Pxz'
    true_sigma = np.zeros((nz, nz)) if sigma is None else sigma
    if not sampled:
        exact = expected_squared_error if rule.criterion == "mse" else bayes_cost_covariance
        model = rule.assumed_sigma if incorporate else None  # K1 rebuilt in the attack's basis
        out = exact(
            P_pred,
            sys.H,
            sys.R,
            true_sigma,
            probability,
            A,
            rule.threshold,
            K0,
            gain_d1,
            assumed_sigma=model,
        )
        info = {
            "p_false_alarm": out.p_false_alarm,
            "p_detection": out.p_detection,
            "threshold": rule.threshold,
        }
        return DetectionStep(P_d0, out.error_cov, None, None, info)
    attacked = bool(rng.random() < probability)
    Q_factor, R_factor = factors
    x_next = sys.F @ x + sys.Gu + Q_factor @ rng.standard_normal(n)
    z = sys.H @ x_next + R_factor @ rng.standard_normal(nz)
    if attacked:
        z = z + psd_sqrt(true_sigma) @ rng.standard_normal(nz)
    x_pred = sys.F @ x_hat + sys.Gu
    y = z - sys.H @ x_pred
    statistic = float(y @ A @ y)
    detected = statistic > rule.threshold
    x_hat_new = x_pred + (gain_d1 if detected else K0) @ y
    info = {
        "attacked_now": attacked,
        "detected": detected,
        "statistic": statistic,
        "threshold": rule.threshold,
    }
    value = None
    if rule.criterion == "bayes_cost":  # the fixed cost of the case that happened
        C = Pzz0 + (true_sigma if attacked else 0.0)
        value = float(np.trace(case_covariance(P_pred, Pxz, C, gain_d1 if detected else K0)))
    return DetectionStep(P_d1 if detected else P_d0, None, x_next, x_hat_new, info, value)
