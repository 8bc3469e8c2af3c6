"""The simulation engine shared by every environment: one filter, expected or sampled.

It keeps the filter's own covariance ``P`` (what the filter believes), the actual error
covariance ``M`` (what the attack makes it), and in sampled mode the true state and the
estimate. The environments put a PettingZoo / Gymnasium face on it.

Two paths compute the same recursion: a generic numpy path for any state size, and for the
2-state tracking model, while no bias reaches the filter, the closed-form kernels of
:mod:`fdia_env.kalman.small` (tested against the generic path).
"""

from __future__ import annotations

import math

import numpy as np

from fdia_env.attacks.base import bits_to_mask
from fdia_env.backend import NUMPY
from fdia_env.defenses.base import FilterInput
from fdia_env.detection.step import SystemArrays, detection_step
from fdia_env.episode import EpisodeSpec
from fdia_env.kalman import (
    information_update,
    joseph_update,
    masked_gain,
    objective,
    predict_cov,
    psd_sqrt,
    sampled_step,
    small,
    steady_state,
)
from fdia_env.systems import LinearSystem


def start_covariance(system: LinearSystem, spec: EpisodeSpec) -> np.ndarray:
    """P at the window start: steady state, or the prior after ``spec.warmup`` clean steps.

    The one definition of the start for the single and the batched engine.
    """
    if spec.warmup == "steady":
        return steady_state(system)[1]
    P = np.array(system.P0)
    for _ in range(int(spec.warmup)):
        P = information_update(predict_cov(P, system.F, system.Q), system.J)
    return P


class Simulation:
    """A Kalman filter under attack, stepped one window step at a time.

    Attributes:
        P: (n, n) the filter's covariance P[k|k] (nominal, computed from R).
        M: (n, n) the actual error covariance (equals P while no bias reaches the filter).
        x, x_hat: (n,) true state and estimate (sampled dynamics only).
        k: Window steps taken.
        phi: Φ after each window step (index 0 = window start).
        nis: Normalised innovation squared per used measurement, last step (sampled only).
    """

    def __init__(self, system: LinearSystem, spec: EpisodeSpec, *, fast: bool = True) -> None:
        self.system = system
        self.spec = spec
        self.sampled = spec.dynamics == "sampled"
        self._full = (1 << system.M) - 1
        self._Q_factor = psd_sqrt(system.Q)
        self._R_factor = psd_sqrt(system.R)
        self.P_start = start_covariance(system, spec)
        self._iu = np.triu_indices(system.n, 1)
        self._detection_arrays: SystemArrays | None = None
        self._fast = fast and system.n == 2
        if self._fast:
            self._f2 = small.to_mat2(system.F)
            self._q2 = small.to_sym2(system.Q)
            self._start2 = small.to_sym2(self.P_start)
            self._j2: dict[int, small.Sym2] = {}
        self.k = 0

    # --- state -------------------------------------------------------------------------------
    @property
    def P(self) -> np.ndarray:
        """The filter's covariance P[k|k]."""
        return small.from_sym2(self._p2) if self._p2 is not None else self._P

    @property
    def M(self) -> np.ndarray:
        """The actual error covariance."""
        if self.consistent:
            return self.P
        return self._M

    def reset(self, rng: np.random.Generator) -> None:
        """Put the filter at the window start; draw the true state in sampled mode."""
        self._P = self.P_start.copy()
        self._p2 = self._start2 if self._fast else None
        self._M = self._P
        self.consistent = True
        self.k = 0
        self.nis = 0.0
        self.last_detection: dict = {}
        self._value_override: float | None = None
        if self.sampled:
            self._reset_sampled(rng)
        self.phi = [self.measure()]

    def _reset_sampled(self, rng: np.random.Generator) -> None:
        sys = self.system
        self.x_hat = np.array(sys.x0)
        if self.spec.warmup == "steady":
            self.x = self.x_hat + psd_sqrt(self.P_start) @ rng.standard_normal(sys.n)
            return
        self.x = self.x_hat + psd_sqrt(sys.P0) @ rng.standard_normal(sys.n)
        P = np.array(sys.P0)
        for _ in range(int(self.spec.warmup)):
            P = information_update(predict_cov(P, sys.F, sys.Q), sys.J)
            W = masked_gain(P, sys)
            self.x, self.x_hat, _, _ = sampled_step(
                rng, sys, self.x, self.x_hat, W, Q_factor=self._Q_factor, R_factor=self._R_factor
            )

    # --- step --------------------------------------------------------------------------------
    def step(self, filter_input: FilterInput, rng: np.random.Generator | None = None) -> float:
        """Advance one step with the sensors and leaked bias the defense model decided.

        Returns:
            Φ after the step (expected: of the actual error covariance; sampled: the squared
            estimation error).
        """
        used, leak = filter_input.used, filter_input.leaked_sigma
        if filter_input.detection is not None:
            self._detection_step(filter_input, rng)
            self.k += 1
            value = self.measure()
            self.phi.append(value)
            return value
        if filter_input.steady:
            self._restart_steady(used, rng)
        if self._fast and leak is None and self.consistent and not self.sampled:
            self._p2 = small.info_update2(
                small.predict2(self._p2, self._f2, self._q2), self._j2_of(used)
            )
        else:
            self._generic_step(used, leak, rng)
        self.k += 1
        value = self.measure()
        self.phi.append(value)
        return value

    def _detection_step(self, fi: FilterInput, rng: np.random.Generator | None) -> None:
        """A step of the detection game (see :mod:`fdia_env.detection.step`)."""
        if self._detection_arrays is None:  # the system's arrays, built once
            self._detection_arrays = SystemArrays.of(
                self.system, NUMPY, self._Q_factor, self._R_factor
            )
        out = detection_step(
            self.system,
            fi.detection,
            fi.leaked_sigma,
            fi.attack_probability,
            self.P,
            rng=rng if self.sampled else None,
            x=getattr(self, "x", None),
            x_hat=getattr(self, "x_hat", None),
            arrays=self._detection_arrays,
        )
        self._P = out.P
        self._p2 = small.to_sym2(out.P) if self._fast else None
        if out.error_cov is not None:
            self._M = out.error_cov
            self.consistent = False
        else:
            self._M, self.consistent = out.P, True
            self.x, self.x_hat = out.x, out.x_hat
        self.last_detection = out.info
        self._value_override = out.value

    def _restart_steady(self, used: int, rng: np.random.Generator | None) -> None:
        """The filter has been running on ``used`` long enough: P = M = its steady state."""
        P = np.array(steady_state(self.system, bits_to_mask(used, self.system.M))[1])
        self._P = self._M = P
        self._p2 = small.to_sym2(P) if self._fast else None
        self.consistent = True
        if self.sampled:  # a fresh error drawn from the steady-state covariance
            self.x = self.x_hat + psd_sqrt(P) @ rng.standard_normal(self.system.n)

    def _j2_of(self, used: int) -> small.Sym2:
        j = self._j2.get(used)
        if j is None:
            J = self.system.J[bits_to_mask(used, self.system.M)].sum(axis=0)
            j = self._j2[used] = small.to_sym2(J)
        return j

    def _generic_step(
        self, used: int, leak: np.ndarray | None, rng: np.random.Generator | None
    ) -> None:
        sys = self.system
        mask = bits_to_mask(used, sys.M)
        P_prev, M_prev = self.P, self.M
        P_pred = predict_cov(P_prev, sys.F, sys.Q)
        P_new = information_update(P_pred, sys.J, mask)  # P[k|k]⁻¹ = P[k|k−1]⁻¹ + Σ_used J_i
        needs_gain = leak is not None or not self.consistent or self.sampled
        # nominal gain (zero columns for dropped sensors), only where it is read
        W = masked_gain(P_new, sys, mask) if needs_gain else None
        if leak is not None or not self.consistent:
            # the nominal gain is not optimal for R + Σ: Joseph form for the actual error
            noise = sys.R if leak is None else sys.R + leak
            self._M = joseph_update(predict_cov(M_prev, sys.F, sys.Q), W, sys.H, noise)
            self.consistent = False
        self._P = P_new
        self._p2 = None
        if self._fast:
            self._p2 = small.to_sym2(P_new)
        if self.sampled:
            self._sampled_step(rng, mask, P_pred, W, leak)

    def _sampled_step(self, rng, mask, P_pred, W, leak) -> None:
        sys = self.system
        bias = None if leak is None else psd_sqrt(leak)
        self.x, self.x_hat, _, innovation = sampled_step(
            rng,
            sys,
            self.x,
            self.x_hat,
            W,
            Q_factor=self._Q_factor,
            R_factor=self._R_factor,
            bias_factor=bias,
        )
        rows = sys.row_mask(mask)
        if not rows.any():
            self.nis = 0.0
            return
        H = sys.H[rows]
        S = H @ P_pred @ H.T + sys.R[np.ix_(rows, rows)]
        nu = innovation[rows]
        self.nis = float(nu @ np.linalg.solve(S, nu)) / int(rows.sum())

    # --- outputs -----------------------------------------------------------------------------
    def info(self) -> dict:
        """Per-step details of the engine (the detector's decision or probabilities)."""
        return dict(self.last_detection) if self.last_detection else {}

    def measure(self) -> float:
        """Φ now: of the actual covariance (expected) or the squared error (sampled)."""
        if self.sampled:
            if self._value_override is not None:  # a detection step's fixed Bayes cost
                return self._value_override
            e = self.x - self.x_hat
            return float(e @ e)
        if self._p2 is not None and self.consistent:
            if self.spec.objective == "trace":
                return small.trace2(self._p2)
            return small.logdet2(self._p2)
        return float(objective(self.M, self.spec.objective))

    def features(self) -> list[float]:
        """Common observation features, order one.

        ``[steps_left / horizon, log(M_ii / P_start_ii) for each i, correlations of M (i < j)]``,
        plus the last normalised innovation squared (NIS per measurement) in sampled mode.
        """
        out = [(self.spec.horizon - self.k) / self.spec.horizon]
        if self._p2 is not None and self.consistent:
            out += small.shape_features2(self._p2, self._start2)
        else:
            M = self.M
            var = np.diag(M)
            out += np.clip(np.log(var / np.diag(self.P_start)), -30.0, 30.0).tolist()
            i, j = self._iu
            out += np.clip(M[i, j] / np.sqrt(var[i] * var[j]), -1.0, 1.0).tolist()
        if self.sampled:
            out.append(min(self.nis, 1e3) if math.isfinite(self.nis) else 1e3)
        return out

    def feature_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of :meth:`features`."""
        n = self.system.n
        n_corr = n * (n - 1) // 2
        low = [0.0] + [-30.0] * n + [-1.0] * n_corr + ([0.0] if self.sampled else [])
        high = [1.0] + [30.0] * n + [1.0] * n_corr + ([1e3] if self.sampled else [])
        return np.array(low), np.array(high)
