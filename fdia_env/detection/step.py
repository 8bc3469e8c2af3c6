"""One filter step with a detector on the innovation (the detection game, docs/math.md §3).

One step for a batch of B filters, written against the engine's array backend (numpy or torch):
the engine (:mod:`fdia_env.envs.engine`) runs it for the native vector env's batch and for the
single env's batch of one. Sampled dynamics draw through a :data:`Draw` callable, which keeps
each caller's draw order (one generator per member on numpy, the single env's own generator, or
the torch device generator). Expected dynamics: the exact error covariance (numerical
integration, on the host in numpy) is computed once per distinct member state
``(P[k|k−1], Σ, p, τ)``; with a fresh prior and one policy every member shares it. On torch the
inputs of that integration are copied to the host and its results back to the device.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from fdia_env.backend import Backend
from fdia_env.defenses.base import BatchDetection
from fdia_env.detection.expected import (
    case_covariance,
    expected_squared_error,
)
from fdia_env.detection.statistics import STATISTICS
from fdia_env.kalman import predict_cov, psd_sqrt, spd_inv_sum, sym
from fdia_env.kalman.linalg import mT
from fdia_env.systems import LinearSystem

Draw = Callable[[Any], tuple[Any, Any]]
"""``draw(probability) -> (attacked, noise)`` for sampled dynamics: (B,) booleans (H1 with each
member's probability, one uniform each) and (B, n + 2 nz) standard normals (process noise,
measurement noise, and under H1 the bias), drawn in that order per member."""


@dataclass(frozen=True)
class SystemArrays:
    """The system's matrices on a backend, as the detection step reads them.

    Attributes:
        F, Q, H, R: The model's matrices.
        Gu: (n,) the known input.
        x0, P0: The prior (a fresh prior restarts from it).
        P0_root_T: ``psd_sqrt(P0)'``, the prior's draw factor.
        Q_factor_T, R_factor_T: ``psd_sqrt(Q)'`` and ``psd_sqrt(R)'``, the noises' factors.
    """

    F: Any
    Q: Any
    H: Any
    R: Any
    Gu: Any
    x0: Any
    P0: Any
    P0_root_T: Any
    Q_factor_T: Any
    R_factor_T: Any

    @classmethod
    def of(
        cls, system: LinearSystem, xp: Backend, Q_factor: np.ndarray, R_factor: np.ndarray
    ) -> SystemArrays:
        """``system``'s arrays on ``xp`` (the noise factors as the caller computed them)."""
        c = xp.asarray
        return cls(
            F=c(system.F),
            Q=c(system.Q),
            H=c(system.H),
            R=c(system.R),
            Gu=c(system.Gu),
            x0=c(system.x0),
            P0=c(system.P0),
            P0_root_T=c(psd_sqrt(system.P0).T),
            Q_factor_T=c(Q_factor.T),
            R_factor_T=c(R_factor.T),
        )


@dataclass
class DetectionStep:
    """What one step produced, per member (arrays of the backend).

    Attributes:
        P: (B, n, n) the filters' own covariances after the decision (expected dynamics: after D0).
        error_cov: (B, n, n) the exact expected error covariances (expected dynamics), else None.
        x, x_hat: (B, n) true states and estimates (sampled dynamics), else None.
        info: Decision details for ``infos``, (B,) arrays.
        value: Sampled ``"bayes_cost"`` criterion: (B,) fixed costs of the realised cases, else
            None.
    """

    P: Any
    error_cov: Any
    x: Any
    x_hat: Any
    info: dict[str, Any]
    value: Any = None


def batched_detection_step(
    xp: Backend,
    system: LinearSystem,
    arrays: SystemArrays,
    rule: BatchDetection,
    sigma: Any,
    probability: Any,
    P_prev: Any,
    *,
    draw: Draw | None = None,
    prior: Any = None,
    x: Any = None,
    x_hat: Any = None,
) -> DetectionStep:
    """Predict, test the innovation, and estimate with the decision's gain, for B filters.

    D0 uses the clean gain ``K0 = Pxz Pzz0⁻¹``; D1 discards (gain 0) or incorporates with the
    defender's attack model (``K1 = Pxz (Pzz0 + Σ_assumed)⁻¹``). Expected dynamics (``draw``
    None) return the exact error covariances; sampled dynamics draw H1 and the noises by
    ``draw``.

    Args:
        xp: The backend of every array.
        system: The model (its sizes; the exact integration reads its H and R on the host).
        arrays: ``system``'s matrices on ``xp``.
        rule: The detector (one threshold per member).
        sigma: (B, nz, nz) the attacker's bias covariances.
        probability: (B,) attack probabilities.
        P_prev: (B, n, n) the filters' covariances (ignored with a fresh prior).
        draw: Sampled dynamics: the draws of H1 and the noises (see :data:`Draw`).
        prior: Sampled dynamics with a fresh prior: (B, n) standard normals of the state draw,
            drawn by the caller before ``draw`` is called.
        x: Sampled dynamics: (B, n) true states (ignored with a fresh prior).
        x_hat: Sampled dynamics: (B, n) estimates (ignored with a fresh prior).

    Returns:
        The step's :class:`DetectionStep`.
    """
    n, nz = system.n, system.nz
    B = probability.shape[0]
    H, R = arrays.H, arrays.R
    thresholds = xp.asarray(rule.thresholds)
    if rule.fresh_prior:
        P_prev = xp.broadcast_to(arrays.P0, (B, n, n))
        if draw is not None:
            x_hat = xp.broadcast_to(arrays.x0, (B, n))
            x = x_hat + xp.rows_times(prior, arrays.P0_root_T)
    P_pred = predict_cov(P_prev, arrays.F, arrays.Q)  # the prior of this step's measurement
    Pxz = P_pred @ mT(H)
    Pzz0 = sym(H @ Pxz + R)
    Pzz0_inv = xp.inv(Pzz0)
    Pzz1_inv, _ = spd_inv_sum(Pzz0, xp.asarray(rule.assumed_sigma))  # never forms Pzz0 + Σ
    K0, K1 = Pxz @ Pzz0_inv, Pxz @ Pzz1_inv
    A = STATISTICS[rule.statistic].matrix(Pzz0_inv, Pzz1_inv)
    incorporate = rule.on_detect == "incorporate"
    gain_d1 = K1 if incorporate else xp.zeros(tuple(K0.shape))
    P_d0 = sym(P_pred - K0 @ Pzz0 @ mT(K0))
    P_d1 = sym(P_pred - K1 @ mT(Pxz)) if incorporate else P_pred  # K1 Pzz1 K1' = K1 Pxz'
    if draw is None:
        cov, p_fa, p_d = _exact_on_host(
            xp, system, rule, P_pred, sigma, probability, A, K0, gain_d1
        )
        info = {"p_false_alarm": p_fa, "p_detection": p_d, "threshold": thresholds}
        return DetectionStep(P_d0, cov, None, None, info)
    attacked, noise = draw(probability)
    rows = xp.rows_times  # member by member: each equals its batch of one (the single env)
    x_next = rows(x, mT(arrays.F)) + arrays.Gu + rows(noise[:, :n], arrays.Q_factor_T)
    z = rows(x_next, mT(H)) + rows(noise[:, n : n + nz], arrays.R_factor_T)
    bias = xp.einsum("bij,bj->bi", psd_sqrt(sigma), noise[:, n + nz :])
    z = z + bias * attacked[:, None]
    x_pred = rows(x_hat, mT(arrays.F)) + arrays.Gu
    y = z - rows(x_pred, mT(H))
    # y' A y as two products (a three-operand einsum's order of a member depends on B)
    statistic = xp.einsum("bi,bi->b", y, xp.einsum("bij,bj->bi", A, y))
    detected = statistic > thresholds
    info = {
        "attacked_now": attacked,
        "detected": detected,
        "statistic": statistic,
        "threshold": thresholds,
    }
    K = xp.where(detected[:, None, None], gain_d1, K0)
    x_hat_new = x_pred + xp.einsum("bij,bj->bi", K, y)
    P = xp.where(detected[:, None, None], P_d1, P_d0)
    value = None
    if rule.criterion == "bayes_cost":  # the fixed cost of the case each member met
        C = Pzz0 + sigma * attacked[:, None, None]
        value = xp.trace(case_covariance(P_pred, Pxz, C, K))
    return DetectionStep(P, None, x_next, x_hat_new, info, value)


def _exact_on_host(
    xp: Backend, system: LinearSystem, rule: BatchDetection, P_pred, sigma, probability, A, K0, D1
) -> tuple:
    """Expected dynamics: the exact error covariance and P_fa, P_d of every member.

    Computed in numpy once per distinct ``(P[k|k−1], Σ, p, τ)``; returns backend arrays.
    """
    B = P_pred.shape[0]
    host = [xp.to_numpy(a) for a in (P_pred, sigma, probability, A, K0, D1)]
    P_pred, sigma, probability, A, K0, gain_d1 = host
    thresholds = np.asarray(xp.to_numpy(xp.asarray(rule.thresholds)), dtype=np.float64)
    model = np.asarray(rule.assumed_sigma) if rule.on_detect == "incorporate" else None
    cov = np.empty((B, system.n, system.n))
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
            cache[key] = expected_squared_error(
                P_pred[i],
                system.H,
                system.R,
                sigma[i],
                float(probability[i]),
                A[i],
                float(thresholds[i]),
                K0[i],
                gain_d1[i],
                assumed_sigma=model,  # K1 rebuilt in the attack's basis (any power)
                criterion=rule.criterion,
            )
        out = cache[key]
        cov[i], p_fa[i], p_d[i] = out.error_cov, out.p_false_alarm, out.p_detection
    return xp.asarray(cov), xp.asarray(p_fa), xp.asarray(p_d)
