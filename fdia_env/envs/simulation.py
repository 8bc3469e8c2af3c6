"""The single environment's filter: the one engine as a batch of one.

It keeps the filter's own covariance ``P`` (what the filter believes), the actual error
covariance ``M`` (what the attack makes it), and in sampled mode the true state and the
estimate, all in a :class:`~fdia_env.envs.engine.BatchedSimulation` of one member (the engine
of the native vector env, which draws from the env's generator in the same order). The
environments put a PettingZoo / Gymnasium face on it.

One kernel runs outside the batch arrays: for the 2-state model in expected dynamics while no
bias has reached the filter, the closed-form update of :mod:`fdia_env.kalman.small` on Python
floats (one member's arrays cost ~15x more per step). The engine's 2-state update
(:func:`~fdia_env.envs.engine.update2`) is the same sequence of IEEE operations on component
arrays, with the same (numpy's) logarithm, so the kernel equals the engine bit for bit; it hands
its state to the engine at the first step it does not cover (tests/properties checks both).
"""

from __future__ import annotations

import numpy as np

from fdia_env.attacks.base import bit_array
from fdia_env.defenses.base import BatchDetection, FilterInput
from fdia_env.envs.engine import BatchedSimulation, start_covariance
from fdia_env.episode import EpisodeSpec
from fdia_env.kalman import small
from fdia_env.systems import LinearSystem

__all__ = ["Simulation", "start_covariance"]

# the most covariances whose features and log det the float kernel keeps (a few MB)
MEMO_SIZE = 2**15


class Simulation:
    """A Kalman filter under attack, stepped one window step at a time (a batch of one).

    Attributes:
        engine: The :class:`~fdia_env.envs.engine.BatchedSimulation` of one member.
        P_start: (n, n) the filter's covariance at the window start.
        k: Window steps taken.
        phi: Φ after each window step (index 0 = window start).
    """

    def __init__(self, system: LinearSystem, spec: EpisodeSpec, *, fast: bool = True) -> None:
        self.system = system
        self.spec = spec
        self.sampled = spec.dynamics == "sampled"
        self.engine = BatchedSimulation(system, spec, 1)
        self.P_start = self.engine.P_start
        self._fast = fast and system.n == 2 and not self.sampled
        if self._fast:
            self._f2 = small.to_mat2(system.F)
            self._q2 = small.to_sym2(system.Q)
            self._start2 = small.to_sym2(self.P_start)
            self._j2: dict[int, small.Sym2] = {}
            self._memo: dict[small.Sym2, tuple[list[float], float]] = {}
        n = system.n
        rows = 1 + n + n * (n - 1) // 2 + (1 if self.sampled else 0)
        self._rows = np.empty((rows, 1))  # float64: the features before the observation's cast
        self._p2: small.Sym2 | None = None
        self._engine_stale = False
        self._features: list[float] | None = None  # of the current state (each player reads it)
        self.k = 0
        self.phi: list[float] = []
        self.last_detection: dict = {}

    # --- state -------------------------------------------------------------------------------
    @property
    def P(self) -> np.ndarray:
        """The filter's covariance P[k|k]."""
        return small.from_sym2(self._p2) if self._p2 is not None else self.engine.P[0]

    @property
    def M(self) -> np.ndarray:
        """The actual error covariance."""
        return small.from_sym2(self._p2) if self._p2 is not None else self.engine.M[0]

    @property
    def consistent(self) -> bool:
        """Whether no bias has reached the filter (then M is P)."""
        return self._p2 is not None or bool(self.engine.consistent[0])

    @property
    def x(self) -> np.ndarray:
        """The true state (sampled dynamics)."""
        return self.engine.x[0]

    @property
    def x_hat(self) -> np.ndarray:
        """The filter's estimate (sampled dynamics)."""
        return self.engine.x_hat[0]

    @property
    def nis(self) -> float:
        """Normalised innovation squared per used measurement, last step (sampled only)."""
        return float(self.engine.nis[0])

    def reset(self, rng: np.random.Generator) -> None:
        """Put the filter at the window start; draw the true state in sampled mode."""
        self.k = 0
        self.last_detection = {}
        self._features = None
        if self._fast:  # the kernel's state; the engine is reset when it takes over
            self._p2 = self._start2
            self._engine_stale = True
            self.phi = [self.measure()]
            return
        engine = self.engine
        engine.rngs = [rng]
        engine.value_override = None
        engine.reset(None, draw=True)
        self._p2 = None
        self.phi = [self.measure()]

    # --- step --------------------------------------------------------------------------------
    def step(self, filter_input: FilterInput, rng: np.random.Generator | None = None) -> float:
        """Advance one step with the sensors and leaked bias the defense model decided.

        Returns:
            Φ after the step (expected: of the actual error covariance; sampled: the squared
            estimation error).
        """
        fi = filter_input
        self._features = None
        if self._p2 is not None and fi.leaked_sigma is None and not fi.steady:
            if fi.detection is None:  # the closed-form kernel on floats
                self._p2 = small.info_update2(
                    small.predict2(self._p2, self._f2, self._q2), self._j2_of(fi.used)
                )
                self.k += 1
                value = self.measure()
                self.phi.append(value)
                return value
        self._engine_step(fi, rng)
        self.k += 1
        value = self.measure()
        self.phi.append(value)
        return value

    def _engine_step(self, fi: FilterInput, rng: np.random.Generator | None) -> None:
        """One step of the engine's batch of one (the kernel's state handed over first)."""
        engine, sys = self.engine, self.system
        if self._p2 is not None:
            if self._engine_stale:  # expected dynamics: nothing to draw
                engine.value_override = None
                engine.reset(None, draw=False)
                self._engine_stale = False
            engine._set_P(small.from_sym2(self._p2)[None])
            self._p2 = None
        if rng is not None:
            engine.rngs = [rng]
        engine.k[0] = self.k
        used = bit_array([fi.used], sys.M)
        leak = None if fi.leaked_sigma is None else np.asarray(fi.leaked_sigma)[None]
        if fi.detection is not None:  # the detection game
            rule = fi.detection
            detection = BatchDetection(
                rule.statistic,
                np.array([float(rule.threshold)]),
                rule.on_detect,
                rule.assumed_sigma,
                rule.fresh_prior,
                rule.criterion,
            )
            sigma = np.zeros((1, sys.nz, sys.nz)) if leak is None else leak
            probability = np.array([float(fi.attack_probability)])
            engine.step(used, sigma, None, False, detection=detection, probability=probability)
            self.last_detection = {
                key: (bool(v[0]) if v.dtype == bool else float(v[0]))
                for key, v in engine.detection_info.items()
            }
        else:
            present = None if leak is None else np.ones(1, dtype=bool)
            engine.step(used, leak, present, fi.steady)
        if self._fast and engine._comp is not None and engine.all_consistent():
            self._p2 = tuple(engine._comp[:, 0].tolist())  # back to the kernel

    def _j2_of(self, used: int) -> small.Sym2:
        j = self._j2.get(used)
        if j is None:
            mask = bit_array([used], self.system.M)
            J = self.engine._used_information(mask)[0]
            j = self._j2[used] = small.to_sym2(J)
        return j

    # --- outputs -----------------------------------------------------------------------------
    def info(self) -> dict:
        """Per-step details of the engine (the detector's decision or probabilities)."""
        return dict(self.last_detection)

    def measure(self) -> float:
        """Φ now: of the actual covariance (expected) or the squared error (sampled)."""
        if self._p2 is not None:
            if self.spec.objective == "trace":
                return small.trace2(self._p2)
            return self._shape(self._p2)[1]
        return float(self.engine.phi[0])

    def _shape(self, p2: small.Sym2) -> tuple[list[float], float]:
        """(:func:`~fdia_env.kalman.small.shape_features2`, log det) of ``p2``, memoised.

        Expected dynamics revisit the same covariances (a covariance is a function of the
        attack history), and each numpy logarithm of a float is a call through numpy's machinery,
        so each covariance's logarithms are taken once (up to ``MEMO_SIZE`` covariances).
        """
        out = self._memo.get(p2)
        if out is None:
            out = (small.shape_features2(p2, self._start2), small.logdet2(p2))
            if len(self._memo) < MEMO_SIZE:
                self._memo[p2] = out
        return out

    def features(self) -> list[float]:
        """Common observation features, order one (the same list until the state changes).

        ``[steps_left / horizon, log(M_ii / P_start_ii) for each i, correlations of M (i < j)]``,
        plus the last normalised innovation squared (NIS per measurement) in sampled mode.
        """
        if self._features is not None:  # computed for the other player already
            return self._features
        steps_left = (self.spec.horizon - self.k) / self.spec.horizon
        if self._p2 is not None:
            out = [steps_left, *self._shape(self._p2)[0]]
        else:
            self.engine.k[0] = self.k
            count = self.engine.features(self._rows)
            out = self._rows[:count, 0].tolist()
            out[0] = steps_left  # in float64 (the engine looks up the observation's float32)
        self._features = out
        return out

    def feature_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Bounds of :meth:`features`."""
        n = self.system.n
        n_corr = n * (n - 1) // 2
        low = [0.0] + [-30.0] * n + [-1.0] * n_corr + ([0.0] if self.sampled else [])
        high = [1.0] + [30.0] * n + [1.0] * n_corr + ([1e3] if self.sampled else [])
        return np.array(low), np.array(high)
