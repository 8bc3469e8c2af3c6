"""The one simulation engine: B filters under attack, one array computation per step.

Every face runs it: the native vector env with its batch, the single env
(:class:`~fdia_env.envs.simulation.Simulation`) as a batch of one. The 2-state case without a
leaking bias keeps each member as a node of a :class:`~fdia_env.envs.history.HistoryTable` on
numpy in expected dynamics (members with the same attack history share one covariance, computed
once by the single env's own kernel) and otherwise runs that kernel on (3, B) component arrays
(:func:`update2`: the single env's :mod:`fdia_env.kalman.small` applied elementwise);
everything else runs the generic batched functions of :mod:`fdia_env.kalman`. Large systems
(n >= 40) that start at the steady state keep each expected covariance as the steady state plus
a low-rank term in the sensor rows dropped so far (numpy backend; see
:meth:`BatchedSimulation._init_low_rank`): an O(n² r) step instead of an n × n solve per member.

On numpy a member equals the single env (the batch of one) bit for bit: the 2-state kernels are
one sequence of IEEE operations with numpy's logarithm, and every product a member goes through
is computed member by member (``Backend.rows_times``, stacked products, two-operand einsums,
batched LAPACK calls), since one (B, w) @ (w, n) BLAS product rounds a row differently at
B = 1 (gemv) than at B > 1 (gemm). Two cases stay exact to round-off only: the low-rank form
(each member padded to the batch's widest rank; the batch leaves the form when its widest
member exceeds the cap, so a member's formula depends on the others) and information sums with
an (M, n²) matrix above :data:`MEMBER_PRODUCT_SIZE` (one BLAS product for the batch: a gemv per
member would read the matrix B times).

The engine is written once against an array backend (:mod:`fdia_env.backend`): numpy arrays on
the CPU, or torch tensors on one device (CPU or CUDA; float64 throughout). The only part that
differs by backend is where random draws come from: with numpy each member draws from its own
generator in the single environment's order (so seeds reproduce single-env episodes); with
torch every member draws from one ``torch.Generator`` on the device (so sampled dynamics are
equal in distribution, not draw for draw).

Sensor sets are (B,) bitmasks (bit i = sensor i) or (B, M) boolean masks; the torch models use
masks where bitmasks would not fit an int64 (more than 62 sensors).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fdia_env.attacks.base import bits_to_mask, mask_array_to_bits
from fdia_env.backend import NUMPY, Backend
from fdia_env.defenses.base import BatchDetection
from fdia_env.detection.step import SystemArrays, batched_detection_step
from fdia_env.envs.history import HistoryTable
from fdia_env.episode import EpisodeSpec
from fdia_env.kalman import (
    information_update,
    joseph_update,
    masked_gain,
    objective,
    predict_cov,
    psd_sqrt,
    small,
    spd_inv,
    spd_inv_sum,
    steady_state,
    sym,
)
from fdia_env.kalman.linalg import logdet_sum2, mT
from fdia_env.systems import LinearSystem

# the largest (M, n²) sensor-information matrix summed member by member (grid-ieee14: 34 × 169,
# grid-ieee30: 71 × 841); above it one BLAS product serves the batch
MEMBER_PRODUCT_SIZE = 2**18


def start_covariance(system: LinearSystem, spec: EpisodeSpec) -> np.ndarray:
    """P at the window start: steady state, or the prior after ``spec.warmup`` clean steps."""
    if spec.warmup == "steady":
        return steady_state(system)[1]
    P = np.array(system.P0)
    for _ in range(int(spec.warmup)):
        P = information_update(predict_cov(P, system.F, system.Q), system.J)
    return P


class BatchedSimulation:
    """B filters under attack, on numpy or on torch.

    Args:
        system: The model.
        spec: The episode (its window, warm-up, objective and dynamics).
        batch: B.
        backend: Where the arrays live (:data:`~fdia_env.backend.NUMPY` by default).

    Attributes:
        P, M: (B, n, n) the filters' and the actual error covariances (properties).
        k: (B,) window steps taken.
        phi: (B,) Φ after the last step.
        x, x_hat: (B, n) true states and estimates (sampled only).
        rngs: numpy backend, sampled dynamics: one ``np.random.Generator`` per member.
        generator: torch backend, sampled dynamics: the ``torch.Generator`` of every draw.
    """

    def __init__(
        self, system: LinearSystem, spec: EpisodeSpec, batch: int, backend: Backend = NUMPY
    ) -> None:
        self.system = system
        self.spec = spec
        self.P_start = P_start = start_covariance(system, spec)
        self.B = batch
        self.xp = xp = backend
        self.sampled = spec.dynamics == "sampled"
        self.fast = system.n == 2
        n, M = system.n, system.M
        c = xp.asarray  # the system's constants, once, on the backend's device
        self._F_identity = bool(np.array_equal(system.F, np.eye(n)))
        self._F, self._Q, self._H, self._R = c(system.F), c(system.Q), c(system.H), c(system.R)
        self._Gu, self._x0 = c(system.Gu), c(system.x0)
        self._HtRinv = c(system.HtRinv)
        self._row_sensor = c(np.asarray(system.row_sensor, dtype=np.int64))
        self._shifts = c(np.arange(M, dtype=np.int64)) if M <= 62 else np.arange(M)
        self._eye = xp.eye(n)
        horizon = spec.horizon  # the first feature for k = 0..horizon, as float32
        steps_left = (horizon - np.arange(horizon + 1)) / horizon
        self._steps_left = c(steps_left.astype(np.float32))
        self._eye_nz = xp.eye(system.nz)
        self._J_flat = c(system.J.reshape(M, -1))
        self._start = c(P_start)
        self._start_diag = c(np.diag(P_start))
        self._iu = tuple(c(np.asarray(i, dtype=np.int64)) for i in np.triu_indices(n, 1))
        self._iu_flat = np.ravel_multi_index(np.triu_indices(n, 1), (n, n))
        self._Q_factor_T = c(psd_sqrt(system.Q).T)  # the single engine's noise factors
        self._R_factor_T = c(psd_sqrt(system.R).T)
        if M <= 16:  # Σ_{i used} J_i for every subset, looked up by bitmask
            bits = (np.arange(2**M)[:, None] >> np.arange(M)) & 1
            jtab = (bits.astype(float) @ system.J.reshape(M, -1)).reshape(-1, n, n)
            self._jtab = c(jtab)
        else:
            jtab = self._jtab = None
        if self.fast:
            self._f2, self._q2 = small.to_mat2(system.F), small.to_sym2(system.Q)
            self._start2 = small.to_sym2(P_start)
            self._start_comp = c(np.array(self._start2)[:, None])
            if jtab is not None:
                self._jcomp = c(np.stack([jtab[:, 0, 0], jtab[:, 0, 1], jtab[:, 1, 1]]))
        # expected 2-state dynamics on the CPU: members share the covariance of a shared history
        # (the table lives on the host: torch CPU tensors are its arrays' views, no copies)
        self._c: Any = None  # (3, B) components of P when the history table is not used
        self._node: Any = None  # (B,) int32 node of each member in the history table, or None
        self._history: HistoryTable | None = None
        on_cpu = xp is NUMPY or getattr(xp.device, "type", None) == "cpu"
        self._share = self.fast and not self.sampled and on_cpu and jtab is not None and M <= 10
        self._host = xp.to_numpy  # a backend array as numpy (a view on the CPU)
        if self.sampled:  # the sampled reset's constants: start factor, or warm-up gains
            warmup = self.spec.warmup
            root = psd_sqrt(P_start if warmup == "steady" else system.P0)
            self._start_root_T = c(root.T)
            self._warm_gains_T = []
            if warmup != "steady":
                P = np.array(system.P0)
                for _ in range(int(warmup)):
                    P = information_update(predict_cov(P, system.F, system.Q), system.J)
                    self._warm_gains_T.append(c(masked_gain(P, system).T))
        self._init_low_rank(P_start)
        self.rngs: list[np.random.Generator] = []
        self.generator: Any = None
        self.value_override: Any = None
        self._detection_arrays: SystemArrays | None = None
        self.reset(None, draw=False)  # the env's reset draws the sampled states

    # --- state -------------------------------------------------------------------------------
    @property
    def shares_histories(self) -> bool:
        """Whether the members are nodes of the history table (see :mod:`fdia_env.envs.history`).

        True from a full reset of a 2-state model in expected dynamics (numpy) until a step the
        table does not cover: a leaking bias, a steady restart, the detection game's step, or
        more histories than the table holds.
        """
        return self._node is not None

    @property
    def _comp(self) -> Any:
        """(3, B) components of P (2-state models), or None; read or set, it leaves the table."""
        if self._node is not None:
            self._leave_history()
        return self._c

    @_comp.setter
    def _comp(self, value: Any) -> None:
        self._node = None
        self._c = value

    def _leave_history(self) -> None:
        """The members' components out of the history table, which the batch stops using."""
        self._c = self.xp.asarray(self._history.comps.take(self._node, axis=1))
        self._node = None

    @property
    def P(self) -> Any:
        """(B, n, n) filter covariances."""
        comp = self._c
        if self._node is not None:
            comp = self.xp.asarray(self._history.comps.take(self._node, axis=1))
        if comp is not None:
            a, b, d = comp
            P = self.xp.empty((self.B, 2, 2))
            P[:, 0, 0], P[:, 0, 1], P[:, 1, 0], P[:, 1, 1] = a, b, b, d
            return P
        return self._P

    @property
    def M(self) -> Any:
        """(B, n, n) actual error covariances (P where no bias leaked)."""
        if self._clean or self.all_consistent():  # no member has seen a bias: M is P
            return self.P
        return self.xp.where(self.consistent[:, None, None], self.P, self._M)

    def all_consistent(self) -> bool:
        """Whether no member's filter has seen a bias (then M is P).

        Kept as a Python flag while it is known to hold, so the common case costs no reduction
        (and, on a GPU, no synchronisation).
        """
        if not self._clean:
            self._clean = self.xp.all(self.consistent)
        return self._clean

    # --- low-rank form of the expected covariance (large systems, steady start) -------------
    def _init_low_rank(self, P_start: np.ndarray) -> None:
        """Constants of the low-rank update (numpy, n >= 40, warm-up "steady"; else off).

        From the steady state ``Ps`` of all sensors (the window start, a fixed point:
        ``Ps⁻¹ = (F Ps F' + Q)⁻¹ + Σ_all J_i``), every expected covariance reached by dropping
        sensors is ``P = Ps + W C W'`` with ``W`` (n, r), r the sensor rows dropped so far, and
        ``C⁻¹`` (r, r) kept per member: a step costs O(n² r) instead of an n × n solve (the
        information identities of docs/math.md §1 with the Woodbury identity). Above
        ``r = n / 4`` the engine falls back to the full update until the next full reset.
        """
        sys = self.system
        n = sys.n
        self._lr_max = (
            n // 4 if (self.xp is NUMPY and n >= 40 and self.spec.warmup == "steady") else 0
        )
        self._lr_on = False
        if not self._lr_max:
            return
        Ps = np.asarray(P_start, dtype=float)
        Hw = np.zeros((sys.nz + 1, n))  # whitened rows (U_i' U_i = J_i), then a zero row
        for i, sensor in enumerate(sys.sensors):
            rows = np.flatnonzero(sys.row_sensor == i)
            L = np.linalg.cholesky(np.atleast_2d(sensor.R))
            Hw[rows] = np.linalg.solve(L, np.atleast_2d(sensor.H))
        self._lr_Hw = Hw
        self._lr_HwPs = Hw @ Ps  # (nz + 1, n): rows U Ps
        self._lr_Ps = Ps
        self._lr_Ppi = sym(np.linalg.inv(sym(sys.F @ Ps @ sys.F.T + sys.Q)))

    def _low_rank_reset(self, where: Any) -> None:
        """Members ``where`` (None = all) back at ``Ps`` (W = 0, C⁻¹ = I)."""
        if not self._lr_max:
            return
        if where is None:
            self._lr_W = np.zeros((self.B, self.system.n, 0))
            self._lr_Cinv = np.zeros((self.B, 0, 0))
            self._lr_live = np.zeros((self.B, 0), dtype=bool)
            self._lr_on = True
        elif self._lr_on:
            r = self._lr_W.shape[2]
            self._lr_W[where] = 0.0
            self._lr_Cinv[where] = np.eye(r)
            self._lr_live[where] = False

    def _low_rank_step(self, mask: Any) -> Any:
        """P[k|k] of every member from its (W, C⁻¹), or None when the rank would exceed the cap.

        With ``U`` the whitened rows dropped this step, ``Pp = F Ps F' + Q`` and ``W̃ = F W``:
        ``P[k|k]⁻¹ = Ps⁻¹ − Z K Z' − U'U`` with ``Z = Pp⁻¹ W̃``, ``K⁻¹ = C⁻¹ + W̃' Z``; so with
        ``V = [Z, U']``: ``W ← Ps V``, ``C⁻¹ ← diag(K⁻¹, I) − V' Ps V``.
        """
        sys, B = self.system, self.B
        dropped = ~mask[:, sys.row_sensor]  # (B, nz) rows not used
        counts = dropped.sum(1)
        k = int(counts.max()) if B else 0
        W, Cinv = self._lr_W, self._lr_Cinv
        r = W.shape[2]
        if r + k > self._lr_max:
            self._lr_on = False
            return None
        if k:  # each member's dropped rows first; the padding points at the zero row
            order = np.argsort(~dropped, axis=1, kind="stable")[:, :k]
            idx = np.where(np.arange(k) < counts[:, None], order, sys.nz)
            U = self._lr_Hw[idx]  # (B, k, n)
            UPs = self._lr_HwPs[idx]  # (B, k, n)
            UPsU = UPs @ U.transpose(0, 2, 1)
        if r:
            Wt = W if self._F_identity else self._F @ W
            Z = self._lr_Ppi @ Wt  # (B, n, r)
            PsZ = self._lr_Ps @ Z
            Zt = Z.transpose(0, 2, 1)
            top = Cinv + Wt.transpose(0, 2, 1) @ Z - Zt @ PsZ
            if k:
                UPsZ = UPs @ Z  # (B, k, r)
                W_new = np.concatenate([PsZ, UPs.transpose(0, 2, 1)], axis=2)
                Cinv_new = np.empty((B, r + k, r + k))
                Cinv_new[:, :r, :r] = top
                Cinv_new[:, r:, :r] = -UPsZ
                Cinv_new[:, :r, r:] = -UPsZ.transpose(0, 2, 1)
                Cinv_new[:, r:, r:] = np.eye(k) - UPsU
            else:
                W_new, Cinv_new = PsZ, top
        elif k:
            W_new, Cinv_new = UPs.transpose(0, 2, 1), np.eye(k) - UPsU
        else:
            W_new, Cinv_new = W, Cinv
        live = self._lr_live
        if k:
            live = np.concatenate([live, np.arange(k) < counts[:, None]], axis=1)
        # a padding column (W's column 0, C⁻¹'s row and column a unit vector) adds nothing:
        # each member's live columns move first and the batch keeps the widest member's count
        width = int(live.sum(1).max()) if B else 0
        if width < live.shape[1]:
            order = np.argsort(~live, axis=1, kind="stable")[:, :width]
            W_new = np.take_along_axis(W_new, order[:, None, :], axis=2)
            Cinv_new = np.take_along_axis(Cinv_new, order[:, :, None], axis=1)
            Cinv_new = np.take_along_axis(Cinv_new, order[:, None, :], axis=2)
            live = np.take_along_axis(live, order, axis=1)
        Cinv_new = sym(Cinv_new)
        self._lr_W, self._lr_Cinv, self._lr_live = W_new, Cinv_new, live
        if not W_new.shape[2]:
            return np.broadcast_to(self._lr_Ps, (B, sys.n, sys.n)).copy()
        CWt = np.linalg.solve(Cinv_new, W_new.transpose(0, 2, 1))
        return sym(self._lr_Ps + W_new @ CWt)

    def _update2(self, comp: Any, j: Any) -> Any:
        """:func:`update2` with this system's F and Q."""
        return update2(comp, self._f2, self._q2, j, self.xp)

    def _set_P(self, P: Any) -> None:
        if self.fast:
            self._comp = self.xp.stack([P[:, 0, 0], 0.5 * (P[:, 0, 1] + P[:, 1, 0]), P[:, 1, 1]])
        else:
            self._comp = None
            self._P = P

    def _set_consistent(self, consistent: Any) -> None:
        """Replace the (B,) consistency flags (the detection game's step sets them)."""
        self.consistent = consistent
        self._clean = False

    def reset(self, where: Any = None, draw: bool = True) -> None:
        """Put the members ``where`` (a (B,) boolean mask; None = all) at the window start.

        Args:
            where: Members to reset.
            draw: Sampled dynamics: draw their true states and estimates (from :attr:`rngs`,
                numpy, or :attr:`generator`, torch).
        """
        xp = self.xp
        B, n = self.B, self.system.n
        full = where is None or xp.all(where)
        if full:
            if self.fast:
                self._comp = xp.broadcast_to(self._start_comp, (3, B))
                if self._share:  # every member at the table's root
                    if self._history is None:
                        j = [small.to_sym2(self._jtab[u]) for u in range(2**self.system.M)]
                        f, q = small.to_mat2(self.system.F), small.to_sym2(self.system.Q)
                        self._history = HistoryTable(self._start2, f, q, j, self.spec.objective)
                    self._node = np.zeros(B, dtype=np.int32)
            else:
                self._set_P(xp.broadcast_to(self._start, (B, n, n)))
            self._M = None  # only read where a member is inconsistent
            self._Mb = None  # M − P: the biases' part of M (None: zero, or not tracked)
            self._low_rank_reset(None)
            self.consistent = xp.ones(B, dtype=xp.bool)
            self._clean = True
            self.k = xp.zeros(B, dtype=xp.int64)
            self.nis = xp.zeros(B)
            if self.sampled:
                self.x = xp.zeros((B, n))
                self.x_hat = xp.zeros((B, n))
        else:
            if self._node is not None:
                self._node[self._host(where)] = 0
            elif self._c is not None:
                self._c[:, where] = self._start_comp
            else:
                self._P[where] = self._start
            if not self.all_consistent():
                self._M[where] = self._start
                if self._Mb is not None:
                    self._Mb[where] = 0.0
            self.consistent[where] = True
            self._low_rank_reset(where)
            self.k[where] = 0
            self.nis[where] = 0.0
        if self.sampled and draw:
            self._reset_sampled(None if full else where)
        override, self.value_override = self.value_override, None  # a fresh start: Φ of the state
        phi0 = self._measure_all()
        self.value_override = None if full else override
        self.phi = phi0 if full else xp.where(where, phi0, self.phi)

    def _reset_sampled(self, where: Any) -> None:
        """Draw the members' true states around the estimate, then run the warm-up steps."""
        xp, sys = self.xp, self.system
        x_hat = xp.broadcast_to(self._x0, (self.B, sys.n))
        x = x_hat + xp.rows_times(self._normal(sys.n, where), self._start_root_T)
        for W_T in self._warm_gains_T:  # warmup = int: clean steps with every sensor
            noise = self._normal(sys.n + sys.nz, where)
            x, x_hat, _ = self._propagate(x, x_hat, W_T, noise, None)
        if where is None:
            self.x, self.x_hat = x, x_hat
        else:
            self.x = xp.where(where[:, None], x, self.x)
            self.x_hat = xp.where(where[:, None], x_hat, self.x_hat)

    # --- random draws: the only backend-specific part ------------------------------------------
    def _normal(self, width: int, members: Any, counts: Any = None) -> Any:
        """(B, width) standard normal draws for the members of the (B,) mask (None = all).

        numpy: member ``i`` draws the first ``counts[i]`` (default ``width``) columns from its
        own generator, in the single environment's order; the other entries are 0. torch: every
        entry comes from :attr:`generator` (members outside ``members`` and columns beyond
        ``counts`` are drawn too and ignored by the caller).
        """
        xp = self.xp
        if xp is not NUMPY:
            return xp.normal(self.generator, (self.B, width))
        out = np.zeros((self.B, width))
        idx = range(self.B) if members is None else np.flatnonzero(members)
        for i in idx:
            count = width if counts is None else int(counts[i])
            out[i, :count] = self.rngs[i].standard_normal(count)
        return out

    # --- step --------------------------------------------------------------------------------
    def step(
        self,
        used: Any,
        leak: Any,
        present: Any,
        steady: bool,
        active: Any = None,
        detection: BatchDetection | None = None,
        probability: Any = None,
    ) -> Any:
        """Advance every member one step; ``active`` members draw noise (sampled mode).

        Args:
            used: (B,) bitmasks or (B, M) boolean masks of the sensors each filter uses.
            leak: (B, nz, nz) bias covariance reaching each filter, or None.
            present: (B,) members with a leak (their single-env twin gets a leaked_sigma).
            steady: Restart each member from the steady state of its ``used`` subset first.
            active: (B,) members whose step counts; the others are about to be reset, or are
                held and put back by the caller (the sequential formats), so their state after
                the step is unspecified (the general update leaves their covariance as it was).
            detection: The detection game's per-member detector (then ``leak`` is the attacker's
                Σ and ``probability`` its attack probabilities).
            probability: (B,) attack probabilities (detection game).

        Returns:
            (B,) Φ after the step.
        """
        if detection is not None:  # the detection game: the detector decides per measurement
            self._detection_step(detection, leak, probability, active)
            self.k += 1
            self.phi = self._measure_all()
            return self.phi
        if steady:
            self._restart_steady(used, active)
        if self._node is not None:
            if leak is None and used.ndim == 1 and (self._clean or self.all_consistent()):
                if self._history_step(self._host(used), active):
                    self.k += 1
                    self.phi = self._measure_all()
                    return self.phi
            self._leave_history()
        if (
            self.fast
            and leak is None
            and not self.sampled
            and (self._clean or self.all_consistent())
        ):
            # P[k|k] = ((F P F' + Q)⁻¹ + Σ_used J_i)⁻¹ on (3, B) components
            self._comp = self._update2(self._comp, self._used_components(used))
        else:
            self._generic_step(used, leak, present, active)
        self.k += 1
        self.phi = self._measure_all()
        return self.phi

    def _history_step(self, used: Any, active: Any) -> bool:
        """Each member to the child of its node under ``used``; False if the table is full.

        Members about to be reset (not ``active``) step from the root instead, so that the
        table does not grow with the histories past the window's end.
        """
        node = self._node
        if active is not None:
            active = self._host(active)
        if active is not None and not active.all():
            node = np.where(active, node, 0).astype(np.int32)
        child = self._history.step(node, used)
        if child is None:  # too many histories: the closed form on every member from now on
            self._share = False
            return False
        self._node = child
        return True

    def _detection_step(
        self, rule: BatchDetection, sigma: Any, probability: Any, active: Any
    ) -> None:
        """The detection game's step (:func:`~fdia_env.detection.step.batched_detection_step`).

        Sampled dynamics draw for the ``active`` members: on numpy each from its own generator
        in the single env's order (a fresh prior's state, H1, then the noises), on torch every
        member from the device generator.
        """
        xp, sys, B = self.xp, self.system, self.B
        n, nz = sys.n, sys.nz
        if self._detection_arrays is None:
            self._detection_arrays = SystemArrays(
                F=self._F,
                Q=self._Q,
                H=self._H,
                R=self._R,
                Gu=self._Gu,
                x0=self._x0,
                P0=xp.asarray(sys.P0),
                P0_root_T=xp.asarray(psd_sqrt(sys.P0).T),
                Q_factor_T=self._Q_factor_T,
                R_factor_T=self._R_factor_T,
            )
        arrays = self._detection_arrays
        draw = prior = None
        if self.sampled:
            if rule.fresh_prior:
                prior = self._normal(n, active)

            def draw(p: Any) -> tuple[Any, Any]:
                if xp is not NUMPY:  # the device generator, for every member at once
                    return xp.uniform(self.generator, B) < p, self._normal(n + 2 * nz, active)
                members = np.arange(B) if active is None else np.flatnonzero(active)
                attacked = np.zeros(B, dtype=bool)
                noise = np.zeros((B, n + 2 * nz))
                for i in members:  # each member's generator, in the single env's order
                    rng = self.rngs[i]
                    attacked[i] = rng.random() < p[i]
                    count = n + nz + (nz if attacked[i] else 0)
                    noise[i, :count] = rng.standard_normal(count)
                return attacked, noise

        out = batched_detection_step(
            xp,
            sys,
            arrays,
            rule,
            sigma,
            probability,
            None if rule.fresh_prior else self.P,
            draw=draw,
            prior=prior,
            x=self.x if self.sampled else None,
            x_hat=self.x_hat if self.sampled else None,
        )
        self.detection_info = out.info
        self._lr_on = False  # P is no longer Ps + W C W'
        if not self.sampled:
            self._set_P(xp.copy(out.P))
            self._M = out.error_cov
            self._Mb = None  # M is the detector's mixture, not P plus a bias part
            self._set_consistent(xp.zeros(B, dtype=xp.bool))
            return
        if active is None:
            self.x, self.x_hat = out.x, out.x_hat
        else:  # members about to be reset keep their state (a fresh prior redraws only theirs)
            keep = ~active[:, None]
            self.x = xp.where(keep, self.x, out.x)
            self.x_hat = xp.where(keep, self.x_hat, out.x_hat)
        self._set_P(out.P)
        self._set_consistent(xp.ones(B, dtype=xp.bool))
        self.value_override = out.value

    def _mask_of(self, used: Any) -> Any:
        """(B, M) boolean masks of (B,) bitmasks (masks pass through)."""
        if used.ndim == 2:
            return used
        xp = self.xp
        if used.dtype == object:  # Python-int bitmasks (M > 62): their bytes, unpacked
            M = self.system.M
            size = (M + 7) // 8
            raw = np.frombuffer(b"".join(int(u).to_bytes(size, "little") for u in used), np.uint8)
            bits = np.unpackbits(raw.reshape(len(used), size), axis=1, bitorder="little")
            return bits[:, :M].astype(bool)
        return xp.astype((used[:, None] >> self._shifts) & 1, xp.bool)

    def _used_components(self, used: Any) -> Any:
        """(3, B) components of ``Σ_{i used} J_i`` per member."""
        xp = self.xp
        if self._jtab is not None and used.ndim == 1:
            return xp.take(self._jcomp, used, axis=1)
        J = self._used_information(used)
        return xp.stack([J[:, 0, 0], J[:, 0, 1], J[:, 1, 1]])

    def _used_information(self, used: Any) -> Any:
        """(B, n, n) ``Σ_{i used} H_i' R_i⁻¹ H_i``.

        Looked up in the table of every subset (M <= 16), else one (M,) × (M, n²) product per
        member (a member's sum does not depend on B) while the (M, n²) matrix is small, else
        one (B, M) × (M, n²) product for the batch (BLAS: a member's rounding depends on B).
        """
        xp = self.xp
        if self._jtab is not None and used.ndim == 1:
            return xp.take(self._jtab, used, axis=0)
        mask = xp.astype(self._mask_of(used), xp.float64)
        if self._J_flat.shape[0] * self._J_flat.shape[1] <= MEMBER_PRODUCT_SIZE:
            flat = xp.rows_times(mask, self._J_flat)
        else:
            flat = mask @ self._J_flat
        return flat.reshape(-1, self.system.n, self.system.n)

    def _restart_steady(self, used: Any, active: Any) -> None:
        """P = M = the steady state of each member's subset (one cached DARE per subset)."""
        xp, sys = self.xp, self.system
        bits = xp.to_numpy(used)
        if bits.ndim == 2:
            bits = mask_array_to_bits(bits)
        P = np.empty((self.B, sys.n, sys.n))
        for u in np.unique(bits):  # the DARE runs on numpy, once per distinct subset
            P[bits == u] = steady_state(sys, bits_to_mask(u, sys.M))[1]
        P = xp.asarray(P)
        self._set_P(P)
        self._lr_on = False  # P is no longer Ps + W C W'
        self._M = xp.copy(P)
        self._Mb = None
        self.consistent = xp.ones(self.B, dtype=xp.bool)
        self._clean = True
        if self.sampled:  # a fresh error drawn from the steady-state covariance
            draws = self._normal(sys.n, active)
            x = self.x_hat + xp.einsum("bij,bj->bi", psd_sqrt(P), draws)
            self.x = x if active is None else xp.where(active[:, None], x, self.x)

    def _generic_step(self, used: Any, leak: Any, present: Any, active: Any) -> None:
        xp = self.xp
        mask = self._mask_of(used)
        P_prev, M_prev = self.P, self.M
        P_new = self._low_rank_step(mask) if self._lr_on else None
        # the general update (below) with some members not active updates the active ones
        # only, and in expected dynamics predicts them only too
        general = P_new is None and not self.fast
        partial = general and active is not None and not bool(xp.all(active))
        only_active = partial and not self.sampled
        P_pred = None  # read by the full update and the sampled step's NIS only
        if (P_new is None or self.sampled) and not only_active:
            P_pred = self._predict(P_prev)
        if P_new is None and self.fast:
            # 2 states, each member as its single env: the float kernel on components while no
            # bias has reached its filter nor reaches it now, else (P[k|k−1]⁻¹ + Σ J_i)⁻¹ by
            # two closed-form inverses (as the single env's engine step)
            kernel = self.consistent if present is None else self.consistent & ~present
            if (self._clean and present is None) or xp.all(kernel):
                self._comp = self._update2(self._comp, self._used_components(used))
                P_new = self.P
            else:
                P_new = spd_inv(spd_inv(P_pred) + self._used_information(used))
                if xp.any(kernel):
                    self._comp = self._update2(self._comp, self._used_components(used))
                    P_new = xp.where(kernel[:, None, None], self.P, P_new)
        elif P_new is None:
            # P[k|k] = (P[k|k−1]⁻¹ + Σ_used J_i)⁻¹ computed as (I + P[k|k−1] J)⁻¹ P[k|k−1]:
            # one LU solve instead of two inverses (I + P J is invertible: its eigenvalues are
            # those of I + P^½ J P^½, all >= 1)
            if not partial:
                used_info = self._used_information(used)
                P_new = sym(xp.solve(self._eye + P_pred @ used_info, P_pred))
            else:  # only the members whose step counts; the others keep P (reset or put back)
                P_new = xp.copy(P_prev)
                if bool(xp.any(active)):
                    sub = self._predict(P_prev[active]) if P_pred is None else P_pred[active]
                    info = self._used_information(used[active])
                    P_new[active] = sym(xp.solve(self._eye + sub @ info, sub))
        if present is None:
            leaking = None if self.all_consistent() else ~self.consistent
        else:
            leaking = present if self.all_consistent() else ~self.consistent | present
        any_leak = leaking is not None and xp.any(leaking)
        # the (B, n, nz) gain only where it is read (large for the power-grid systems)
        W = self._gain(P_new, mask) if any_leak or self.sampled else None
        if any_leak:  # Joseph form for the members whose filter is not optimal
            if self._Mb is None and not self._clean and not self.all_consistent():
                # M from the detection game's step: no separate bias part
                M_new = joseph_update(predict_cov(M_prev, self._F, self._Q), W, self._H, self._R)
                if leak is not None:
                    M_new = sym(M_new + W @ leak @ mT(W))
            else:
                # M = P + B: the nominal gain makes the Joseph form of P's own noise P itself,
                # so only the biases' part B is propagated, B ← A F B F' A' + W Σ W' with
                # A = I − W H; log det(P + B) then comes from the two terms (spd_inv_sum),
                # which their float64 sum loses under a huge rank-deficient Σ
                B_prev = self._Mb if self._Mb is not None else xp.zeros(P_new.shape)
                B_pred = B_prev if self._F_identity else self._F @ B_prev @ mT(self._F)
                A = self._eye - W @ self._H
                B_new = A @ B_pred @ mT(A)
                if leak is not None:
                    B_new = B_new + W @ leak @ mT(W)
                B_new = sym(B_new)
                M_new = sym(P_new + B_new)
                self._Mb = xp.where(leaking[:, None, None], B_new, 0.0)
            self._M = xp.where(leaking[:, None, None], M_new, P_new)
            self.consistent = self.consistent & ~leaking
            self._clean = False
        self._set_P(P_new)
        if self.sampled:
            self._sampled_step(mask, P_pred, W, leak, present, active)

    def _predict(self, P: Any) -> Any:
        """``P[k|k−1] = F P F' + Q``; a random walk (F = I, the grid presets) skips the products."""
        return P + self._Q if self._F_identity else predict_cov(P, self._F, self._Q)

    def _gain(self, P_post: Any, mask: Any) -> Any:
        """(B, n, nz) nominal gain ``P H' R⁻¹`` with zero columns for the unused sensors."""
        xp = self.xp
        rows = xp.astype(mask[:, self._row_sensor], xp.float64)
        return P_post @ (self._HtRinv * rows[:, None, :])

    def _propagate(self, x: Any, x_hat: Any, W: Any, noise: Any, bias: Any) -> tuple:
        """One step of the true system and of the filter (docs/math.md §1), batched.

        ``x[k+1] = F x + G u + v``, ``z = H x[k+1] + w (+ b)``,
        ``x̂ = x̂[k+1|k] + W (z − H x̂[k+1|k])``, with ``v, w`` from the first n + nz columns of
        ``noise``; ``W`` is (B, n, nz) per member or the (nz, n) transpose of a shared gain.

        Returns:
            ``(x_next, x_hat_next, innovation)``.
        """
        n, nz = self.system.n, self.system.nz
        rows = self.xp.rows_times  # member by member: each equals its batch of one
        x_next = rows(x, self._F.T) + self._Gu + rows(noise[:, :n], self._Q_factor_T)
        z = rows(x_next, self._H.T) + rows(noise[:, n : n + nz], self._R_factor_T)
        if bias is not None:
            z = z + bias
        x_pred = rows(x_hat, self._F.T) + self._Gu
        innovation = z - rows(x_pred, self._H.T)
        if W.ndim == 2:
            return x_next, x_pred + rows(innovation, W), innovation
        return x_next, x_pred + self.xp.einsum("bij,bj->bi", W, innovation), innovation

    def _sampled_step(self, mask, P_pred, W, leak, present, active) -> None:
        xp, sys = self.xp, self.system
        n, nz = sys.n, sys.nz
        has_bias = present is not None and xp.any(present)
        counts = None
        if xp is NUMPY:  # each member's draws in its single env's order: v, w, then the bias
            counts = np.full(self.B, n + nz) if present is None else n + nz + nz * present
        noise = self._normal(n + 2 * nz, active, counts)
        bias = None
        if has_bias:
            L = psd_sqrt(leak)
            bias = xp.einsum("bij,bj->bi", L, noise[:, n + nz :]) * present[:, None]
        self.x, self.x_hat, innovation = self._propagate(self.x, self.x_hat, W, noise, bias)
        rows = xp.astype(mask[:, self._row_sensor], xp.float64)  # NIS over the used rows
        S = self._H @ P_pred @ self._H.T + self._R
        S = S * rows[:, :, None] * rows[:, None, :] + self._eye_nz * (1.0 - rows)[:, None, :]
        nu = innovation * rows
        count = xp.sum(rows, 1)
        nis = xp.einsum("bi,bi->b", nu, xp.solve(S, nu[..., None])[..., 0])
        self.nis = xp.where(count > 0, nis / xp.maximum(count, 1.0), 0.0)

    # --- outputs -----------------------------------------------------------------------------
    def _measure_all(self) -> Any:
        xp = self.xp
        if self._node is not None:  # Φ of each member's node
            return xp.asarray(self._history.phi.take(self._node))
        if self.sampled:
            if self.value_override is not None:  # the detection game's fixed Bayes costs
                return self.value_override
            e = self.x - self.x_hat
            return xp.einsum("bi,bi->b", e, e)
        if self._c is None:
            return self._objective_of_M()
        # 2 states: small.trace2 / small.logdet2 of P's components where M is P (the single
        # env's float kernel), the generic objective of M where a bias reached the filter (the
        # single env's engine step): each member by its own state, as its single env
        a, b, d = self._c
        phi = a + d if self.spec.objective == "trace" else small.logdet2((a, b, d))
        if self._clean or self.all_consistent():
            return phi
        return xp.where(self.consistent, phi, self._objective_of_M())

    def _objective_of_M(self) -> Any:
        """(B,) Φ(M); a log det of ``P + B`` from its two terms where the bias part B is kept."""
        if self.spec.objective != "logdet" or self._Mb is None:
            return objective(self.M, self.spec.objective)
        if self.system.n == 2:  # the same on the components, in closed form
            value = logdet_sum2(self.P, self._Mb)
        else:
            value = spd_inv_sum(self.P, self._Mb)[1]
        return self.xp.where(self.consistent, objective(self.P, "logdet"), value)

    def _components_of_M(self) -> tuple[Any, Any, Any]:
        """(a, b, d) of each member's M, (B,) each (2-state models)."""
        if self._c is not None and (self._clean or self.all_consistent()):
            return self._c[0], self._c[1], self._c[2]
        M = self.M
        return M[:, 0, 0], M[:, 0, 1], M[:, 1, 1]

    def features(self, out: Any) -> int:
        """Write the common features into the rows ``out[:f]`` of a (d, B) buffer.

        The buffer is float32 (an observation's rows; logs computed in float32) or float64 (the
        single env's features).

        Same features as :meth:`Simulation.features`, one row per feature (rows are contiguous,
        so the batch is written without strided stores); returns f.
        """
        xp = self.xp
        n = self.system.n
        out[0] = xp.take(self._steps_left, self.k)  # (horizon − k) / horizon, looked up
        if self._node is not None:  # each member's node's features, gathered
            rows = self._host(out[1:4])  # contiguous rows: on torch (CPU) a view of them
            if rows.dtype == np.float32:
                np.take(self._history.feats, self._node, axis=1, out=rows, mode="clip")
            else:
                rows[...] = self._history.feats64.take(self._node, axis=1)
            col = 4
        elif self.fast:  # small.shape_features2 of M's components, in float64, then stored
            a, b, d = self._components_of_M()
            a0, _, d0 = self._start2
            out[1] = xp.clip(xp.log(a / a0), -30.0, 30.0)
            out[2] = xp.clip(xp.log(d / d0), -30.0, 30.0)
            out[3] = xp.clip(small.corr2(a, b, d), -1.0, 1.0)
            col = 4
        else:
            M = self.M
            var = xp.diagonal(M)
            out[1 : 1 + n] = xp.clip(xp.log(var / self._start_diag), -30.0, 30.0).T
            i, j = self._iu
            if xp is NUMPY and M.flags.c_contiguous:  # one gather from the flat rows
                upper = M.reshape(len(M), -1)[:, self._iu_flat]
            else:
                upper = M[:, i, j]
            corr = small.corr2(var[:, i], upper, var[:, j])
            out[1 + n : 1 + n + len(i)] = xp.clip(corr, -1.0, 1.0).T
            col = 1 + n + len(i)
        if self.sampled:
            out[col] = xp.where(xp.isfinite(self.nis), xp.minimum(self.nis, 1e3), 1e3)
            col += 1
        return col


def update2(comp: Any, f: small.Mat2, q: small.Sym2, j: Any, xp: Backend = NUMPY) -> Any:
    """``P[k|k] = ((F P F' + Q)⁻¹ + J)⁻¹`` for (3, B) components, by the single env's kernel.

    :func:`~fdia_env.kalman.small.predict2` and :func:`~fdia_env.kalman.small.info_update2`
    applied elementwise to the component arrays: the same IEEE operations in the same order as
    on one member's Python floats, so each member equals the single env's float kernel bit for
    bit, whatever B (the history table's nodes are computed the same way).

    Args:
        comp: (3, B) components of P[k−1|k−1] (numpy or torch).
        f: (f11, f12, f21, f22) of F.
        q: (a, b, d) components of Q.
        j: (3, B) components of each member's ``Σ_used J_i``.
        xp: The backend of the arrays.

    Returns:
        (3, B) components of P[k|k] (a new array).
    """
    pred = small.predict2((comp[0], comp[1], comp[2]), f, q)
    return xp.stack(small.info_update2(pred, (j[0], j[1], j[2])))
