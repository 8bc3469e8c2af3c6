"""The static Bayesian detection problem of docs/math.md §3 and its validated inputs.

Prior ``x ~ N(x̄, Pxx)``; under H0 (probability ``p0 = 1 − p1``) the measurement is
``z = H x + w``, under H1 (probability ``p1``) ``z = H x + w + b``, with ``w ~ N(0, Pww)`` and
``b ~ N(0, Pbb)`` independent of x and of each other. Then

    z̄ = H x̄,   Pxz = Pxx H',   Pzz0 = H Pxx H' + Pww,   Pzz1 = Pzz0 + Pbb.

Every estimator of this package is linear in the innovation given the decision,
``x̂ = x̄ + K (z − z̄)``, and its mean squared error under hypothesis h is

    mse(K, Pzz_h) = tr[Pxx − K Pxz' − Pxz K' + K Pzz_h K']

(b is independent of x, so ``Pxz`` is the same under both hypotheses). The costs c1..c4 of
docs/math.md §3 are this formula for the estimator used after each decision (:mod:`.detectors`).

In the tracking case the problem is applied at the attack time K with the predicted state as
prior: ``x̄ = x̂[K|K−1]``, ``Pxx = P[K|K−1]`` (:func:`tracking_problem`).
"""

from __future__ import annotations

import dataclasses
import numbers
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fdia_env._validation import as_matrix, as_vector, check_psd
from fdia_env._validation import check_power as _check_power
from fdia_env.detection.attack import c2_optimal_pbb
from fdia_env.detection.expected import Innovation
from fdia_env.kalman import (
    information_update,
    logdet,
    predict_cov,
    spd_inv,
    spd_inv_sum,
    steady_state,
)
from fdia_env.scenarios import Scenario, resolve, scenario_default


def check_probability(name: str, value: Any) -> float:
    """``value`` as a float in [0, 1], else ``ValueError`` naming ``name``."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a probability in [0, 1], got {value!r}")
    value = float(value)
    if not 0.0 <= value <= 1.0:  # also rejects NaN
        raise ValueError(f"{name} must be a probability in [0, 1], got {value}")
    return value


def check_problem(name: str, value: Any) -> DetectionProblem:
    """``value`` if it is a :class:`DetectionProblem`, else ``TypeError`` naming ``name``."""
    if not isinstance(value, DetectionProblem):
        raise TypeError(
            f"{name} must be a DetectionProblem (from static_problem or tracking_problem), "
            f"got {type(value).__name__}"
        )
    return value


def check_power(value: Any) -> float:
    """Attack power ``a²`` in ``[0, MAX_POWER]`` as a float, else a ``ValueError``."""
    return _check_power("power", value, allow_zero=True)


@dataclass(frozen=True, eq=False)
class DetectionProblem:
    """A validated static detection instance (docs/math.md §3).

    Attributes:
        x_bar: (n,) prior mean x̄.
        Pxx: (n, n) prior covariance, symmetric PSD.
        H: (nz, n) measurement matrix.
        Pww: (nz, nz) measurement-noise covariance, symmetric positive definite.
        Pbb: (nz, nz) bias covariance under H1, symmetric PSD (zero = no attack).
        p1: Prior probability of H1, in [0, 1].

    Derived (computed in ``__post_init__``):
        n, nz: state and measurement sizes; p0: ``1 − p1``.
        z_bar: (nz,) ``H x̄``; Pxz: (n, nz) ``Pxx H'``.
        Pzz0, Pzz1: (nz, nz) measurement covariances under H0 and H1.
        Pzz0_inv, Pzz1_inv: their inverses; logdet0, logdet1: their log-determinants.
        K0, K1: (n, nz) LMMSE gains ``Pxz Pzz0⁻¹`` (clean model) and ``Pxz Pzz1⁻¹`` (H1 model).
        A: (nz, nz) ``Pzz0⁻¹ − Pzz1⁻¹`` (PSD), the matrix of the quadratic test statistic.
    """

    x_bar: np.ndarray
    Pxx: np.ndarray
    H: np.ndarray
    Pww: np.ndarray
    Pbb: np.ndarray
    p1: float
    n: int = field(init=False)
    nz: int = field(init=False)
    p0: float = field(init=False)
    z_bar: np.ndarray = field(init=False, repr=False)
    Pxz: np.ndarray = field(init=False, repr=False)
    Pzz0: np.ndarray = field(init=False, repr=False)
    Pzz1: np.ndarray = field(init=False, repr=False)
    Pzz0_inv: np.ndarray = field(init=False, repr=False)
    Pzz1_inv: np.ndarray = field(init=False, repr=False)
    logdet0: float = field(init=False, repr=False)
    logdet1: float = field(init=False, repr=False)
    K0: np.ndarray = field(init=False, repr=False)
    K1: np.ndarray = field(init=False, repr=False)
    A: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        Pxx = as_matrix("Pxx", self.Pxx)
        n = Pxx.shape[0]
        if Pxx.shape != (n, n):
            raise ValueError(f"Pxx must be square, got shape {Pxx.shape}")
        check_psd("Pxx", Pxx)
        x_bar = as_vector("x_bar", self.x_bar, n)
        H = as_matrix("H", self.H, shape=(None, n))
        nz = H.shape[0]
        Pww = as_matrix("Pww", self.Pww, shape=(nz, nz))
        check_psd("Pww", Pww, strict=True)
        Pbb = as_matrix("Pbb", self.Pbb, shape=(nz, nz))
        check_psd("Pbb", Pbb)
        p1 = check_probability("p1", self.p1)

        Pxz = Pxx @ H.T
        Pzz0 = _sym(H @ Pxz + Pww)
        Pzz1 = _sym(Pzz0 + Pbb)
        Pzz0_inv = spd_inv(Pzz0)
        # from Pzz0 and Pbb, not from Pzz1: at a large power Pzz1 is singular in float64
        Pzz1_inv, logdet1 = spd_inv_sum(Pzz0, Pbb)
        for name, value in (
            ("x_bar", x_bar),
            ("Pxx", Pxx),
            ("H", H),
            ("Pww", Pww),
            ("Pbb", Pbb),
            ("p1", p1),
            ("n", n),
            ("nz", nz),
            ("p0", 1.0 - p1),
            ("z_bar", H @ x_bar),
            ("Pxz", Pxz),
            ("Pzz0", Pzz0),
            ("Pzz1", Pzz1),
            ("Pzz0_inv", Pzz0_inv),
            ("Pzz1_inv", Pzz1_inv),
            ("logdet0", float(logdet(Pzz0))),
            ("logdet1", float(logdet1)),
            ("K0", Pxz @ Pzz0_inv),
            ("K1", Pxz @ Pzz1_inv),
            ("A", _sym(Pzz0_inv - Pzz1_inv)),
        ):
            if isinstance(value, np.ndarray) and value.flags.writeable:
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    def with_pbb(self, Pbb: np.ndarray) -> DetectionProblem:
        """The same problem with another bias covariance (e.g. the attacker's true one)."""
        return dataclasses.replace(self, Pbb=Pbb)

    def mse(self, K: np.ndarray, hypothesis: int) -> float:
        """``tr[Pxx − K Pxz' − Pxz K' + K Pzz_h K']`` of ``x̂ = x̄ + K (z − z̄)`` under H``h``.

        Args:
            K: (n, nz) gain; zero for "discard the measurement".
            hypothesis: 0 (no attack) or 1 (attack).
        """
        # tr[Pxx − K* Pxz'] + ‖(K* − K) L‖²_F with K* = Pxz Pzz_h⁻¹ and L L' = Pzz_h, in the
        # factor that keeps a strong attack's scale apart (Pzz1 itself is singular in float64
        # at a power of 1e40); K1 under H1 is K* itself
        factor = Innovation.of(self.Pzz0, self.Pbb if hypothesis == 1 else None)
        KL = factor.optimal_gain_times_factor(self.Pxz)
        if hypothesis == 1 and (K is self.K1 or np.array_equal(K, self.K1)):
            E = np.zeros_like(KL)
        else:
            E = KL - factor.gain_times_factor(np.asarray(K, dtype=float))
        return float(np.trace(self.Pxx) - np.sum(KL * KL) + np.sum(E * E))


def _sym(a: np.ndarray) -> np.ndarray:
    return 0.5 * (a + a.T)


def _resolve_p1(scenario: Scenario, p1: Any) -> float:
    return check_probability("p1", scenario_default(scenario, "p1", p1))


def static_problem(
    scenario: str | Scenario = "ch3-static",
    power: float = 100.0,
    *,
    Pbb: np.ndarray | None = None,
    p1: float | None = None,
) -> DetectionProblem:
    """The static example: the system's prior ``N(x0, P0)`` observed once by all its sensors.

    Args:
        scenario: A preset name or :class:`~fdia_env.scenarios.Scenario` (default ch3-static).
        power: Attack power a² ``>= 0``; used when ``Pbb`` is not given.
        Pbb: (nz, nz) bias covariance; default the c2-maximising one of power a²
            (:func:`~fdia_env.detection.attack.c2_optimal_pbb`), which for ch3-static is the
            ``diag(a², 0)`` of docs/math.md §6.
        p1: Prior probability of an attack (default the scenario's, 0.85 for ch3).

    Example:
        >>> problem = static_problem("ch3-static", 100.0)
        >>> problem.Pbb.round(12).tolist(), problem.p1
        ([[100.0, 0.0], [0.0, 0.0]], 0.85)
    """
    sc = resolve(scenario)
    system = sc.system
    a2 = check_power(power)
    if Pbb is None:
        Pbb = c2_optimal_pbb(system.P0, system.H, system.R, a2)
    return DetectionProblem(system.x0, system.P0, system.H, system.R, Pbb, _resolve_p1(sc, p1))


def predicted_covariance(scenario: str | Scenario = "ch3-tracking") -> np.ndarray:
    """``P[K|K−1]`` at the scenario's attack time K.

    The filter starts from ``P[0|0] = P0`` and updates with every sensor at k = 1, ..., K−1
    (``K − 1`` clean cycles, the env's ``warmup`` convention), then predicts once; with
    ``scenario.steady_state`` (or no attack step) it is the steady-state ``P[k+1|k]`` of the DARE.
    """
    sc = resolve(scenario)
    system = sc.system
    if sc.steady_state or sc.attack_step is None:
        return np.array(steady_state(system)[0])
    P = np.array(system.P0)
    for _ in range(sc.attack_step - 1):
        P = information_update(predict_cov(P, system.F, system.Q), system.J)
    return predict_cov(P, system.F, system.Q)


def tracking_problem(
    scenario: str | Scenario = "ch3-tracking",
    power: float = 30.0,
    *,
    Pbb: np.ndarray | None = None,
    p1: float | None = None,
    x_pred: np.ndarray | None = None,
) -> DetectionProblem:
    """The tracking example at the attack time K: prior ``N(x̂[K|K−1], P[K|K−1])``.

    Before K the filter is optimal, so given the past data the state at K is exactly
    ``N(x̂[K|K−1], P[K|K−1])``; the measurement at K is then the static problem with
    ``H`` and ``Pww = R`` of the system. ``P[K|K−1]`` is :func:`predicted_covariance`.

    Args:
        scenario: A preset with an attack step (default ch3-tracking, K = 100).
        power: Attack power a² ``>= 0``, ``tr Pbb`` (T = 1 in ch3-tracking, so this is also the
            weighted power ``σ_bp² + T² σ_bv²`` of docs/math.md §2).
        Pbb: (nz, nz) bias covariance; default the c2-maximising one of power a².
        p1: Prior probability of an attack (default the scenario's).
        x_pred: (n,) ``x̂[K|K−1]``; default the prior mean propagated K steps
            (``x ← F x + G u`` from x0), its expectation. No cost, probability or mean squared
            error depends on it (every test and estimate uses ``z − H x̄``).

    Example:
        >>> problem = tracking_problem("ch3-tracking", 30.0)
        >>> round(float(np.trace(problem.Pbb)), 10), problem.Pxx.round(3).tolist()
        (30.0, [[2.882, 1.061], [1.061, 0.706]])
    """
    sc = resolve(scenario)
    system = sc.system
    a2 = check_power(power)
    P_pred = predicted_covariance(sc)
    if x_pred is None:
        x_pred = np.array(system.x0)
        for _ in range(sc.attack_step or 0):
            x_pred = system.F @ x_pred + system.Gu
    if Pbb is None:
        Pbb = c2_optimal_pbb(P_pred, system.H, system.R, a2)
    return DetectionProblem(x_pred, P_pred, system.H, system.R, Pbb, _resolve_p1(sc, p1))
