"""The simulation engine for a batch of B environments, one numpy computation per step.

Member ``i`` of the batch follows exactly the recursion of
:class:`~fdia_env.envs.simulation.Simulation`: the 2-state case without a leaking bias runs the
same closed-form kernels (:mod:`fdia_env.kalman.small`) on component arrays, everything else the
generic batched functions of :mod:`fdia_env.kalman`. In sampled dynamics each member draws from
its own generator, in the single environment's order, so seeds reproduce single-env episodes.
"""

from __future__ import annotations

import numpy as np

from fdia_env.attacks.base import bits_to_mask
from fdia_env.defenses.base import BatchDetection
from fdia_env.envs.simulation import Simulation
from fdia_env.episode import EpisodeSpec
from fdia_env.kalman import (
    joseph_update,
    masked_gain,
    objective,
    predict_cov,
    psd_sqrt,
    small,
    steady_state,
    sym,
)
from fdia_env.kalman.linalg import spd_inv
from fdia_env.vector.detection import batched_detection_step


class BatchedSimulation:
    """B filters under attack.

    Attributes:
        P, M: (B, n, n) the filters' and the actual error covariances (properties).
        k: (B,) window steps taken.
        phi: (B,) Φ after the last step.
        x, x_hat: (B, n) true states and estimates (sampled only).
    """

    def __init__(self, single: Simulation, batch: int) -> None:
        self.single = single
        self.system = system = single.system
        self.spec: EpisodeSpec = single.spec
        self.B = batch
        self.sampled = single.sampled
        self.fast = system.n == 2
        self._F_identity = bool(np.array_equal(system.F, np.eye(system.n)))
        self._eye = np.eye(system.n)
        self._J_flat = system.J.reshape(system.M, -1)
        self._start = single.P_start
        self._start_diag = np.diag(self._start)
        self._iu = np.triu_indices(system.n, 1)
        if system.M <= 16:  # Σ_{i used} J_i for every subset, looked up by bitmask
            bits = (np.arange(2**system.M)[:, None] >> np.arange(system.M)) & 1
            self._jtab = (bits.astype(float) @ self._J_flat).reshape(-1, system.n, system.n)
        else:
            self._jtab = None
        if self.fast:
            self._C = small.predict_matrix2(small.to_mat2(system.F))
            self._q = np.array(small.to_sym2(system.Q))
            self._start2 = small.to_sym2(self._start)
            self._start_comp = np.array(self._start2)[:, None]
            if self._jtab is not None:
                self._jcomp = np.stack(
                    [self._jtab[:, 0, 0], self._jtab[:, 0, 1], self._jtab[:, 1, 1]]
                )
        self.rngs: list[np.random.Generator] = []
        self.value_override: np.ndarray | None = None
        self.reset(None, None)  # the env's reset draws the sampled states

    # --- state -------------------------------------------------------------------------------
    @property
    def P(self) -> np.ndarray:
        """(B, n, n) filter covariances."""
        if self._comp is not None:
            a, b, d = self._comp
            P = np.empty((self.B, 2, 2))
            P[:, 0, 0], P[:, 0, 1], P[:, 1, 0], P[:, 1, 1] = a, b, b, d
            return P
        return self._P

    @property
    def M(self) -> np.ndarray:
        """(B, n, n) actual error covariances (P where no bias leaked)."""
        if self.consistent.all():  # no member's filter has seen a bias: M is P
            return self.P
        return np.where(self.consistent[:, None, None], self.P, self._M)

    def _set_P(self, P: np.ndarray) -> None:
        if self.fast:
            self._comp = np.stack([P[:, 0, 0], 0.5 * (P[:, 0, 1] + P[:, 1, 0]), P[:, 1, 1]])
        else:
            self._comp = None
            self._P = P

    def reset(self, where: np.ndarray | None, rngs: list[np.random.Generator] | None) -> None:
        """Put the members ``where`` (a (B,) boolean mask; None = all) at the window start.

        Args:
            where: Members to reset.
            rngs: Their generators, in member order (sampled dynamics), or None.
        """
        B, n = self.B, self.system.n
        if where is None or where.all():
            if self.fast:
                self._comp = np.repeat(self._start_comp, B, axis=1)
            else:
                self._set_P(np.broadcast_to(self._start, (B, n, n)).copy())
            self._M = None  # only read where a member is inconsistent
            self.consistent = np.ones(B, dtype=bool)
            self.k = np.zeros(B, dtype=np.int64)
            self.nis = np.zeros(B)
            if self.sampled:
                self.x = np.zeros((B, n))
                self.x_hat = np.zeros((B, n))
            members = np.arange(B)
        else:
            if self._comp is not None:
                self._comp[:, where] = self._start_comp
            else:
                self._P[where] = self._start
            if not self.consistent.all():
                self._M[where] = self._start
            self.consistent[where] = True
            self.k[where] = 0
            self.nis[where] = 0.0
            members = np.flatnonzero(where)
        if self.sampled and rngs is not None:
            for i, rng in zip(members, rngs, strict=True):  # one generator per member
                self.single._reset_sampled(rng)
                self.x[i], self.x_hat[i] = self.single.x, self.single.x_hat
        override, self.value_override = self.value_override, None  # a fresh start: Φ of the state
        phi0 = self._measure_all()
        self.value_override = None if where is None or where.all() else override
        self.phi = phi0 if where is None or where.all() else np.where(where, phi0, self.phi)

    # --- step --------------------------------------------------------------------------------
    def step(
        self,
        used: np.ndarray,
        leak: np.ndarray | None,
        present: np.ndarray | None,
        steady: bool,
        active: np.ndarray | None = None,
        detection: BatchDetection | None = None,
        probability: np.ndarray | None = None,
    ) -> np.ndarray:
        """Advance every member one step; ``active`` members draw noise (sampled mode).

        Args:
            used: (B,) bitmasks of the sensors each filter uses.
            leak: (B, nz, nz) bias covariance reaching each filter, or None.
            present: (B,) members with a leak (their single-env twin gets a leaked_sigma).
            steady: Restart each member from the steady state of its ``used`` subset first.
            active: (B,) members whose step counts (the others are about to be reset).
            detection: The detection game's per-member detector (then ``leak`` is the attacker's
                Σ and ``probability`` its attack probabilities).
            probability: (B,) attack probabilities (detection game).

        Returns:
            (B,) Φ after the step.
        """
        if detection is not None:  # the detection game: the detector decides per measurement
            batched_detection_step(self, detection, leak, probability, active)
            self.k += 1
            self.phi = self._measure_all()
            return self.phi
        if steady:
            self._restart_steady(used, active)
        if self.fast and leak is None and not self.sampled and self.consistent.all():
            # P[k|k] = ((F P F' + Q)⁻¹ + Σ_used J_i)⁻¹ on (3, B) components
            info = small.inv2_stacked(small.predict2_stacked(self._comp, self._C, self._q))
            info += self._used_components(used)
            self._comp = small.inv2_stacked(info)
        else:
            self._generic_step(used, leak, present, active)
        self.k += 1
        self.phi = self._measure_all()
        return self.phi

    def _used_components(self, used: np.ndarray) -> np.ndarray:
        """(3, B) components of ``Σ_{i used} J_i`` per member."""
        if self._jtab is not None:
            return np.take(self._jcomp, used, axis=1)
        J = self._used_information(used)
        return np.stack([J[:, 0, 0], J[:, 0, 1], J[:, 1, 1]])

    def _used_information(self, used: np.ndarray) -> np.ndarray:
        """(B, n, n) ``Σ_{i used} H_i' R_i⁻¹ H_i``."""
        if self._jtab is not None:
            return np.take(self._jtab, used, axis=0)
        bits = (used[:, None] >> np.arange(self.system.M)) & 1
        return (bits.astype(float) @ self._J_flat).reshape(-1, self.system.n, self.system.n)

    def _restart_steady(self, used: np.ndarray, active: np.ndarray | None) -> None:
        M_ = self.system.M
        P = np.empty((self.B, self.system.n, self.system.n))
        for u in np.unique(used):  # one cached DARE per distinct subset, not per member
            P[used == u] = steady_state(self.system, bits_to_mask(u, M_))[1]
        self._set_P(P)
        self._M = P.copy()
        self.consistent[:] = True
        if self.sampled:
            for i in range(self.B) if active is None else np.flatnonzero(active):
                draw = self.rngs[i].standard_normal(self.system.n)
                self.x[i] = self.x_hat[i] + psd_sqrt(P[i]) @ draw

    def _generic_step(self, used, leak, present, active) -> None:
        sys = self.system
        mask = ((used[:, None] >> np.arange(sys.M)) & 1).astype(bool)
        P_prev, M_prev = self.P, self.M
        # P[k|k−1] = F P F' + Q; a random walk (F = I, the grid presets) skips the products
        P_pred = P_prev + sys.Q if self._F_identity else predict_cov(P_prev, sys.F, sys.Q)
        # P[k|k] = (P[k|k−1]⁻¹ + Σ_used J_i)⁻¹, the sum as one (B, M) × (M, n²) product,
        # computed as (I + P[k|k−1] J)⁻¹ P[k|k−1]: one LU solve instead of two inverses
        # (I + P J is invertible: its eigenvalues are those of I + P^½ J P^½, all >= 1)
        used_info = (mask.astype(float) @ self._J_flat).reshape(-1, sys.n, sys.n)
        if sys.n > 2:
            P_new = sym(np.linalg.solve(self._eye + P_pred @ used_info, P_pred))
        else:
            P_new = spd_inv(spd_inv(P_pred) + used_info)
        leaking = ~self.consistent if present is None else ~self.consistent | present
        # the (B, n, nz) gain only where it is read (large for the power-grid systems)
        W = masked_gain(P_new, sys, mask) if leaking.any() or self.sampled else None
        if leaking.any():  # Joseph form for the members whose filter is not optimal
            noise = sys.R if leak is None else sys.R + leak
            M_new = joseph_update(predict_cov(M_prev, sys.F, sys.Q), W, sys.H, noise)
            self._M = np.where(leaking[:, None, None], M_new, P_new)
            self.consistent = self.consistent & ~leaking
        self._set_P(P_new)
        if self.sampled:
            self._sampled_step(mask, P_pred, W, leak, present, active)

    def _sampled_step(self, mask, P_pred, W, leak, present, active) -> None:
        sys = self.system
        n, nz, B = sys.n, sys.nz, self.B
        noise = np.zeros((B, n + 2 * nz))
        has_bias = np.zeros(B, dtype=bool) if present is None else present
        members = range(B) if active is None else np.flatnonzero(active)
        for i in members:  # each member's own generator, in the single env's draw order
            noise[i, : n + nz + (nz if has_bias[i] else 0)] = self.rngs[i].standard_normal(
                n + nz + (nz if has_bias[i] else 0)
            )
        v = noise[:, :n] @ self.single._Q_factor.T
        w = noise[:, n : n + nz] @ self.single._R_factor.T
        x_next = self.x @ sys.F.T + sys.Gu + v
        z = x_next @ sys.H.T + w
        if has_bias.any():
            L = psd_sqrt(leak)
            z = z + np.einsum("bij,bj->bi", L, noise[:, n + nz :]) * has_bias[:, None]
        x_pred = self.x_hat @ sys.F.T + sys.Gu
        innovation = z - x_pred @ sys.H.T
        self.x_hat = x_pred + np.einsum("bij,bj->bi", W, innovation)
        self.x = x_next
        rows = sys.row_mask(mask).astype(float)  # NIS over the used rows
        S = sys.H @ P_pred @ sys.H.T + sys.R
        S = S * rows[:, :, None] * rows[:, None, :] + np.eye(nz) * (1.0 - rows)[:, None, :]
        nu = innovation * rows
        count = rows.sum(axis=1)
        nis = np.einsum("bi,bi->b", nu, np.linalg.solve(S, nu[..., None])[..., 0])
        self.nis = np.where(count > 0, nis / np.maximum(count, 1.0), 0.0)

    # --- outputs -----------------------------------------------------------------------------
    def _measure_all(self) -> np.ndarray:
        if self.sampled:
            if self.value_override is not None:  # the detection game's fixed Bayes costs
                return self.value_override
            e = self.x - self.x_hat
            return np.einsum("bi,bi->b", e, e)
        if self._comp is not None and self.consistent.all():
            a, b, d = self._comp
            if self.spec.objective == "trace":
                return a + d
            det = a * d - b * b
            with np.errstate(divide="ignore", invalid="ignore"):
                return np.where(det > 0, np.log(det), -np.inf)
        return objective(self.M, self.spec.objective)

    def features(self, out: np.ndarray) -> int:
        """Write the common features into the rows ``out[:f]`` of a (d, B) float32 buffer.

        Same features as :meth:`Simulation.features`, one row per feature (rows are contiguous,
        so the batch is written without strided stores); returns f.
        """
        n = self.system.n
        out[0] = (self.spec.horizon - self.k) / self.spec.horizon
        if self._comp is not None and self.consistent.all():
            a, b, d = self._comp
            a0, _, d0 = self._start2
            f32 = np.float32  # the observation is float32: compute its transcendental parts so
            np.log(a * (1.0 / a0), dtype=f32, out=out[1])
            np.log(d * (1.0 / d0), dtype=f32, out=out[2])
            _clip(out[1:3], 30.0)
            np.divide(b, np.sqrt(a * d), out=out[3], casting="same_kind")
            _clip(out[3], 1.0)
            col = 4
        else:
            M = self.M
            var = np.diagonal(M, axis1=-2, axis2=-1)
            out[1 : 1 + n] = np.clip(np.log(var / self._start_diag), -30.0, 30.0).T
            i, j = self._iu
            corr = M[:, i, j] / np.sqrt(var[:, i] * var[:, j])
            out[1 + n : 1 + n + len(i)] = np.clip(corr, -1.0, 1.0).T
            col = 1 + n + len(i)
        if self.sampled:
            out[col] = np.where(np.isfinite(self.nis), np.minimum(self.nis, 1e3), 1e3)
            col += 1
        return col


def _clip(x: np.ndarray, bound: float) -> np.ndarray:
    """``x`` clipped to [−bound, bound] in place (np.clip's wrapper costs more here)."""
    np.minimum(x, bound, out=x)
    np.maximum(x, -bound, out=x)
    return x
