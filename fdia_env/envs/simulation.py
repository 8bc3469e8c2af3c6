"""The simulation engine shared by every environment: one filter, expected or sampled.

It keeps the filter's own covariance ``P`` (what the filter believes), the actual error
covariance ``M`` (what the attack makes it), and in sampled mode the true state and the
estimate. The environments put a PettingZoo / Gymnasium face on it.
"""

from __future__ import annotations

import numpy as np

from fdia_env.defenses.base import FilterInput
from fdia_env.episode import EpisodeSpec
from fdia_env.kalman import (
    information_update,
    joseph_update,
    masked_gain,
    objective,
    predict_cov,
    psd_sqrt,
    sampled_step,
    steady_state,
)
from fdia_env.systems import LinearSystem


class Simulation:
    """A Kalman filter under attack, stepped one window step at a time.

    Attributes:
        P: (n, n) the filter's covariance P[k|k] (nominal, computed from R).
        M: (n, n) the actual error covariance (equals P while no bias reaches the filter).
        x, x_hat: (n,) true state and estimate (sampled dynamics only).
        k: Window steps taken.
        phi: Φ after each window step (index 0 = window start).
    """

    def __init__(self, system: LinearSystem, spec: EpisodeSpec) -> None:
        self.system = system
        self.spec = spec
        self._all = np.ones(system.M, dtype=bool)
        self._J_flat = system.J.reshape(system.M, -1)
        self._Q_factor = psd_sqrt(system.Q)
        self._R_factor = psd_sqrt(system.R)
        self.P_start = self._start_covariance()
        self._P_scale = np.sqrt(np.diag(self.P_start))
        self.sampled = spec.dynamics == "sampled"
        self.k = 0

    def _start_covariance(self) -> np.ndarray:
        """P at the window start: steady state, or the prior after ``warmup`` clean steps."""
        if self.spec.warmup == "steady":
            return steady_state(self.system)[1]
        P = np.array(self.system.P0)
        for _ in range(int(self.spec.warmup)):
            P = information_update(predict_cov(P, self.system.F, self.system.Q), self.system.J)
        return P

    def reset(self, rng: np.random.Generator) -> None:
        """Put the filter at the window start; draw the true state in sampled mode."""
        self.P = self.P_start.copy()
        self.M = self.P  # shared until a bias leaks in (then M is recomputed separately)
        self.consistent = True
        self.k = 0
        self.nis = 0.0
        if self.sampled:
            self._reset_sampled(rng)
        self.phi = [self.measure()]

    def _reset_sampled(self, rng: np.random.Generator) -> None:
        sys = self.system
        if self.spec.warmup == "steady":
            self.x_hat = np.array(sys.x0)
            self.x = self.x_hat + psd_sqrt(self.P_start) @ rng.standard_normal(sys.n)
            return
        self.x_hat = np.array(sys.x0)
        self.x = self.x_hat + psd_sqrt(sys.P0) @ rng.standard_normal(sys.n)
        P = np.array(sys.P0)
        for _ in range(int(self.spec.warmup)):
            P = information_update(predict_cov(P, sys.F, sys.Q), sys.J)
            W = masked_gain(P, sys)
            self.x, self.x_hat, _, _ = sampled_step(
                rng, sys, self.x, self.x_hat, W, Q_factor=self._Q_factor, R_factor=self._R_factor
            )

    def step(self, filter_input: FilterInput, rng: np.random.Generator | None = None) -> float:
        """Advance one step with the sensors and leaked bias the defense model decided.

        Returns:
            Φ after the step (expected: of the actual error covariance; sampled: the squared
            estimation error).
        """
        sys = self.system
        used, leak = filter_input.used, filter_input.leaked_sigma
        P_pred = predict_cov(self.P, sys.F, sys.Q)
        info = _inverse(P_pred) + (used.astype(float) @ self._J_flat).reshape(sys.n, sys.n)
        P_new = _inverse(info)  # P[k|k]⁻¹ = P[k|k−1]⁻¹ + Σ_used H_i' R_i⁻¹ H_i
        W = None
        if leak is not None or not self.consistent or self.sampled:
            W = masked_gain(P_new, sys, used)
        if leak is None and self.consistent:
            self.M = P_new
        else:  # the nominal gain is not optimal for R + Σ: Joseph form for the actual error
            noise = sys.R if leak is None else sys.R + leak
            self.M = joseph_update(predict_cov(self.M, sys.F, sys.Q), W, sys.H, noise)
            self.consistent = False
        self.P = P_new
        if self.sampled:
            bias = None if leak is None else psd_sqrt(leak)
            self.x, self.x_hat, _, innovation = sampled_step(
                rng, sys, self.x, self.x_hat, W,
                Q_factor=self._Q_factor, R_factor=self._R_factor, bias_factor=bias,
            )
            rows = sys.row_mask(used)
            S = sys.H[rows] @ P_pred @ sys.H[rows].T + sys.R[np.ix_(rows, rows)]
            nu = innovation[rows]
            self.nis = float(nu @ np.linalg.solve(S, nu)) / max(int(rows.sum()), 1) if rows.any() else 0.0
        self.k += 1
        value = self.measure()
        self.phi.append(value)
        return value

    def measure(self) -> float:
        """Φ now: of the actual covariance (expected) or the squared error (sampled)."""
        if self.sampled:
            e = self.x - self.x_hat
            return float(e @ e)
        return float(objective(self.M, self.spec.objective))

    def features(self) -> np.ndarray:
        """Common observation features, order one.

        ``[steps_left / horizon, log(M_ii / P_start_ii) for each i, correlations of M (i < j)]``,
        plus the last normalised innovation squared (NIS per measurement) in sampled mode.
        """
        n = self.system.n
        d = np.sqrt(np.diag(self.M))
        logvar = np.clip(2.0 * np.log(d / self._P_scale), -30.0, 30.0)
        iu = np.triu_indices(n, 1)
        corr = np.clip(self.M[iu] / (d[iu[0]] * d[iu[1]]), -1.0, 1.0)
        base = [np.array([(self.spec.horizon - self.k) / self.spec.horizon]), logvar, corr]
        if self.sampled:
            base.append(np.array([min(self.nis, 1e3)]))
        return np.concatenate(base)

    def feature_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of :meth:`features`."""
        n = self.system.n
        n_corr = n * (n - 1) // 2
        low = [0.0] + [-30.0] * n + [-1.0] * n_corr + ([0.0] if self.sampled else [])
        high = [1.0] + [30.0] * n + [1.0] * n_corr + ([1e3] if self.sampled else [])
        return np.array(low), np.array(high)


def _inverse(a: np.ndarray) -> np.ndarray:
    """Inverse of one small SPD matrix; closed form for 2×2 (the tracking model)."""
    if a.shape == (2, 2):
        p, q, s = a[0, 0], a[0, 1], a[1, 1]
        det = p * s - q * q
        return np.array([[s / det, -q / det], [-q / det, p / det]])
    return np.linalg.inv(a)
