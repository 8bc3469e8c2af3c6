"""The detection game's step for a batch (see :mod:`fdia_env.detection.step` for one filter).

Written against the engine's array backend (numpy or torch). Sampled dynamics: on numpy each
member draws from its own generator in the single env's order, on torch every member from the
device generator; the test, the estimate and the filter update run as one batched computation.
Expected dynamics: the exact error covariance (numerical integration, on the host in numpy) is
computed once per distinct member state, ``(P[k|k−1], Σ, p, τ)``; with a fresh prior and one
policy every member shares it. On torch the inputs of that integration are copied to the host
and its results back to the device (the one host round trip of the torch engine).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fdia_env.backend import NUMPY
from fdia_env.defenses.base import BatchDetection
from fdia_env.detection.expected import (
    bayes_cost_covariance,
    case_covariance,
    expected_squared_error,
)
from fdia_env.detection.statistics import STATISTICS
from fdia_env.kalman import predict_cov, psd_sqrt, spd_inv_sum, sym
from fdia_env.kalman.linalg import mT


def batched_detection_step(
    sim, rule: BatchDetection, sigma: Any, probability: Any, active: Any | None
) -> None:
    """Advance every member of ``sim`` (a :class:`BatchedSimulation`) by one detection step."""
    xp, sys, B = sim.xp, sim.system, sim.B
    n, nz = sys.n, sys.nz
    H, R = sim._H, sim._R
    thresholds = xp.asarray(rule.thresholds)
    if rule.fresh_prior:
        P0 = xp.asarray(sys.P0)
        P_prev = xp.broadcast_to(P0, (B, n, n))
        if sim.sampled:
            sim.x_hat = xp.broadcast_to(sim._x0, (B, n))
            x = sim.x_hat + sim._normal(n, active) @ xp.asarray(psd_sqrt(sys.P0).T)
            sim.x = x if active is None else xp.where(active[:, None], x, sim.x)
    else:
        P_prev = sim.P
    P_pred = predict_cov(P_prev, sim._F, sim._Q)
    Pxz = P_pred @ H.T
    Pzz0 = sym(H @ Pxz + R)
    Pzz0_inv = xp.inv(Pzz0)
    Pzz1_inv, _ = spd_inv_sum(Pzz0, xp.asarray(rule.assumed_sigma))  # any power
    K0, K1 = Pxz @ Pzz0_inv, Pxz @ Pzz1_inv
    A = STATISTICS[rule.statistic].matrix(Pzz0_inv, Pzz1_inv)
    incorporate = rule.on_detect == "incorporate"
    gain_d1 = K1 if incorporate else xp.zeros(tuple(K0.shape))
    P_d0 = sym(P_pred - K0 @ Pzz0 @ mT(K0))
    P_d1 = sym(P_pred - K1 @ mT(Pxz)) if incorporate else P_pred  # K1 Pzz1 K1' = K1 Pxz'
    if not sim.sampled:
        cov, p_fa, p_d = _exact_on_host(sim, rule, P_pred, sigma, probability, A, K0, gain_d1)
        sim.detection_info = {"p_false_alarm": p_fa, "p_detection": p_d, "threshold": thresholds}
        sim._set_P(xp.copy(P_d0))
        sim._M = cov
        sim._set_consistent(xp.zeros(B, dtype=xp.bool))
        return
    # sampled: uniform for H1, then process noise, measurement noise, and the bias under H1
    if xp is NUMPY:  # each member's generator, in the single env's order
        members = np.arange(B) if active is None else np.flatnonzero(active)
        attacked = np.zeros(B, dtype=bool)
        noise = np.zeros((B, n + 2 * nz))
        for i in members:
            rng = sim.rngs[i]
            attacked[i] = rng.random() < probability[i]
            count = n + nz + (nz if attacked[i] else 0)
            noise[i, :count] = rng.standard_normal(count)
    else:  # the device generator, for every member at once
        attacked = xp.uniform(sim.generator, B) < probability
        noise = sim._normal(n + 2 * nz, active)
    x_next = sim.x @ sim._F.T + sim._Gu + noise[:, :n] @ sim._Q_factor_T
    z = x_next @ H.T + noise[:, n : n + nz] @ sim._R_factor_T
    bias = xp.einsum("bij,bj->bi", psd_sqrt(sigma), noise[:, n + nz :])
    z = z + bias * attacked[:, None]
    x_pred = sim.x_hat @ sim._F.T + sim._Gu
    y = z - x_pred @ H.T
    statistic = xp.einsum("bi,bij,bj->b", y, A, y)
    detected = statistic > thresholds
    sim.detection_info = {
        "attacked_now": attacked,
        "detected": detected,
        "statistic": statistic,
        "threshold": thresholds,
    }
    K = xp.where(detected[:, None, None], gain_d1, K0)
    sim.x_hat = x_pred + xp.einsum("bij,bj->bi", K, y)
    sim.x = x_next
    sim._set_P(xp.where(detected[:, None, None], P_d1, P_d0))
    sim._set_consistent(xp.ones(B, dtype=xp.bool))
    sim.value_override = None
    if rule.criterion == "bayes_cost":  # the fixed cost of the case each member met
        C = Pzz0 + sigma * attacked[:, None, None]
        sim.value_override = xp.trace(case_covariance(P_pred, Pxz, C, K))


def _exact_on_host(sim, rule, P_pred, sigma, probability, A, K0, gain_d1) -> tuple:
    """Expected dynamics: the exact error covariance and P_fa, P_d of every member.

    Computed in numpy once per distinct ``(P[k|k−1], Σ, p, τ)``; returns backend arrays.
    """
    xp, sys, B = sim.xp, sim.system, sim.B
    host = [xp.to_numpy(a) for a in (P_pred, sigma, probability, A, K0, gain_d1)]
    P_pred, sigma, probability, A, K0, gain_d1 = host
    thresholds = np.asarray(xp.to_numpy(xp.asarray(rule.thresholds)), dtype=np.float64)
    exact = expected_squared_error if rule.criterion == "mse" else bayes_cost_covariance
    model = np.asarray(rule.assumed_sigma) if rule.on_detect == "incorporate" else None
    cov = np.empty((B, sys.n, sys.n))
    p_fa, p_d = np.zeros(B), np.zeros(B)
    cache: dict[bytes, object] = {}
    for i in range(B):  # once per distinct (P[k|k−1], Σ, p, τ)
        key = b"".join(
            (
                P_pred[i].tobytes(),
                sigma[i].tobytes(),
                np.float64(probability[i]).tobytes(),
                np.float64(thresholds[i]).tobytes(),
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
                float(thresholds[i]),
                K0[i],
                gain_d1[i],
                assumed_sigma=model,  # K1 rebuilt in the attack's basis (any power)
            )
        out = cache[key]
        cov[i], p_fa[i], p_d[i] = out.error_cov, out.p_false_alarm, out.p_detection
    return xp.asarray(cov), xp.asarray(p_fa), xp.asarray(p_d)
