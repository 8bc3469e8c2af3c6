"""The detection game's step for a batch (see :mod:`fdia_env.detection.step` for one filter).

Sampled dynamics: each member draws from its own generator in the single env's order, then
the test, the estimate and the filter update run as one batched computation. Expected dynamics:
the exact error covariance (numerical integration) is computed once per distinct member state,
``(P[k|k−1], Σ, p, τ)``; with a fresh prior and one policy every member shares it.
"""

from __future__ import annotations

import numpy as np

from fdia_env.defenses.base import BatchDetection
from fdia_env.detection.expected import (
    bayes_cost_covariance,
    case_covariance,
    expected_squared_error,
)
from fdia_env.kalman import predict_cov, psd_sqrt, sym
from fdia_env.kalman.linalg import mT


def batched_detection_step(
    sim, rule: BatchDetection, sigma: np.ndarray, probability: np.ndarray, active: np.ndarray | None
) -> None:
    """Advance every member of ``sim`` (a :class:`BatchedSimulation`) by one detection step."""
    sys, B = sim.system, sim.B
    n, nz = sys.n, sys.nz
    members = np.arange(B) if active is None else np.flatnonzero(active)
    if rule.fresh_prior:
        P_prev = np.broadcast_to(sys.P0, (B, n, n))
        if sim.sampled:
            sim.x_hat = np.broadcast_to(sys.x0, (B, n)).copy()
            root = psd_sqrt(sys.P0)
            for i in members:
                sim.x[i] = sim.x_hat[i] + root @ sim.rngs[i].standard_normal(n)
    else:
        P_prev = sim.P
    P_pred = predict_cov(P_prev, sys.F, sys.Q)
    Pxz = P_pred @ sys.H.T
    Pzz0 = sym(sys.H @ Pxz + sys.R)
    Pzz0_inv = np.linalg.inv(Pzz0)
    Pzz1 = sym(Pzz0 + rule.assumed_sigma)
    Pzz1_inv = np.linalg.inv(Pzz1)
    K0, K1 = Pxz @ Pzz0_inv, Pxz @ Pzz1_inv
    A = Pzz0_inv if rule.statistic == "chi2" else sym(Pzz0_inv - Pzz1_inv)
    incorporate = rule.on_detect == "incorporate"
    gain_d1 = K1 if incorporate else np.zeros_like(K0)
    P_d0 = sym(P_pred - K0 @ Pzz0 @ mT(K0))
    P_d1 = sym(P_pred - K1 @ Pzz1 @ mT(K1)) if incorporate else P_pred
    if not sim.sampled:
        exact = expected_squared_error if rule.criterion == "mse" else bayes_cost_covariance
        cov = np.empty((B, n, n))
        p_fa, p_d = np.zeros(B), np.zeros(B)
        cache: dict[bytes, object] = {}
        for i in range(B):  # once per distinct (P[k|k−1], Σ, p, τ)
            key = b"".join(
                (
                    P_pred[i].tobytes(),
                    sigma[i].tobytes(),
                    np.float64(probability[i]).tobytes(),
                    np.float64(rule.thresholds[i]).tobytes(),
                )
            )
            if key not in cache:
                cache[key] = exact(
                    P_pred[i],
                    sys.H,
                    sys.R,
                    sigma[i],
                    float(probability[i]),
                    A[i],
                    float(rule.thresholds[i]),
                    K0[i],
                    gain_d1[i],
                )
            out = cache[key]
            cov[i], p_fa[i], p_d[i] = out.error_cov, out.p_false_alarm, out.p_detection
        sim.detection_info = {
            "p_false_alarm": p_fa,
            "p_detection": p_d,
            "threshold": np.array(rule.thresholds, dtype=np.float64),
        }
        sim._set_P(np.array(P_d0))
        sim._M = cov
        sim._set_consistent(np.zeros(B, dtype=bool))
        return
    # sampled: uniform for H1, then process noise, measurement noise, and the bias under H1
    attacked = np.zeros(B, dtype=bool)
    noise = np.zeros((B, n + 2 * nz))
    for i in members:
        rng = sim.rngs[i]
        attacked[i] = rng.random() < probability[i]
        noise[i, : n + nz + (nz if attacked[i] else 0)] = rng.standard_normal(
            n + nz + (nz if attacked[i] else 0)
        )
    x_next = sim.x @ sys.F.T + sys.Gu + noise[:, :n] @ sim.single._Q_factor.T
    z = x_next @ sys.H.T + noise[:, n : n + nz] @ sim.single._R_factor.T
    bias = np.einsum("bij,bj->bi", psd_sqrt(sigma), noise[:, n + nz :])
    z = z + bias * attacked[:, None]
    x_pred = sim.x_hat @ sys.F.T + sys.Gu
    y = z - x_pred @ sys.H.T
    statistic = np.einsum("bi,bij,bj->b", y, A, y)
    detected = statistic > rule.thresholds
    sim.detection_info = {
        "attacked_now": attacked,
        "detected": detected,
        "statistic": statistic,
        "threshold": np.array(rule.thresholds, dtype=np.float64),
    }
    K = np.where(detected[:, None, None], gain_d1, K0)
    sim.x_hat = x_pred + np.einsum("bij,bj->bi", K, y)
    sim.x = x_next
    sim._set_P(np.where(detected[:, None, None], P_d1, P_d0))
    sim._set_consistent(np.ones(B, dtype=bool))
    sim.value_override = None
    if rule.criterion == "bayes_cost":  # the fixed cost of the case each member met
        C = Pzz0 + sigma * attacked[:, None, None]
        sim.value_override = np.trace(case_covariance(P_pred, Pxz, C, K), axis1=-2, axis2=-1)
