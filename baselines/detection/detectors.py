"""The detectors of docs/math.md §3: OBDD, OBDI, CBD and CSD, each a threshold test on a statistic.

After the decision every detector estimates linearly (``x̂ = x̄ + K (z − z̄)``):

- D0 (no attack declared): the clean-model LMMSE, ``K = K0 = Pxz Pzz0⁻¹``;
- D1, ``on_detect="discard"``: the measurement is dropped, ``K = 0`` (x̂ = x̄);
- D1, ``on_detect="incorporate"``: the H1-model LMMSE, ``K = K1 = Pxz Pzz1⁻¹``.

The fixed costs are the mean squared errors of these estimators under each hypothesis, *not*
conditioned on the decision (:meth:`DetectionProblem.mse`):

    c1 = mse(K_D1, H1)  detected attack      c2 = mse(K0, H1)  missed attack
    c3 = mse(K_D1, H0)  false alarm          c4 = mse(K0, H0)  correct rejection

which reproduces docs/math.md §3's closed forms (discard: ``c1 = c3 = tr Pxx``; incorporate:
``c1 = tr[Pxx − Pxz Pzz1⁻¹ Pxz']``, ``c3 = tr[Pxx + Pxz Pzz1⁻¹ Pzz0 Pzz1⁻¹ Pxz' −
2 Pxz Pzz1⁻¹ Pxz']``). The Bayes test minimising ``c = p1[P(D1|H1) c1 + P(D0|H1) c2] +
p0[P(D1|H0) c3 + P(D0|H0) c4]`` decides D1 where

    p1 (c1 − c2) N(z; z̄, Pzz1) + p0 (c3 − c4) N(z; z̄, Pzz0) < 0.

With ``a = p1 (c1 − c2)``, ``b = p0 (c3 − c4)`` (``b >= 0`` always: c4 is the minimum MSE under
H0 among linear estimators) and ``q = (z − z̄)' (Pzz0⁻¹ − Pzz1⁻¹)(z − z̄)``
(:func:`bayes_threshold`):

- ``a < 0 < b``: D1 iff ``q > α = 2 ln[b |Pzz1|^{1/2} / (−a |Pzz0|^{1/2})]``;
- ``a >= 0`` (c2 <= c1, e.g. OBDD when discarding costs more than a missed attack): the left
  side is never negative, so the detector **always declares D0** (α = +inf);
- ``a < 0 = b``: always D1 (α = −inf; e.g. p1 = 1).

The statistics match the env's defender action: ``"quadratic"`` is q above, ``"chi2"`` the
normalised innovation squared ``(z − z̄)' Pzz0⁻¹ (z − z̄)``. D1 is declared when the statistic is
strictly greater than ``threshold``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import scipy.stats

from baselines.detection.problem import DetectionProblem, check_probability, check_problem
from fdia_env._validation import check_choice
from fdia_env.detection.statistics import STATISTICS as STATISTIC_TABLE

STATISTICS = tuple(STATISTIC_TABLE)  # the names of the table of detector statistics
ON_DETECT = ("discard", "incorporate")


@dataclass(frozen=True)
class Costs:
    """Fixed costs (traces of MSE matrices) of a detect-then-estimate strategy (docs/math.md §3).

    Attributes:
        c1: Attack declared under H1 (detected attack).
        c2: No attack declared under H1 (missed attack).
        c3: Attack declared under H0 (false alarm).
        c4: No attack declared under H0 (correct rejection).
    """

    c1: float
    c2: float
    c3: float
    c4: float

    def bayes(
        self,
        p1: float,
        p_d: float,
        p_fa: float,
        p_miss: float | None = None,
        p_cr: float | None = None,
    ) -> float:
        """``p1[P_d c1 + P_miss c2] + p0[P_fa c3 + P_cr c4]``.

        ``p_miss`` (``P(D0|H1)``) and ``p_cr`` (``P(D0|H0)``) default to ``1 − P_d`` and
        ``1 − P_fa``; pass them when known directly: under a strong attack c2 ~ a² and
        ``1 − P_d`` has lost every digit (:func:`~baselines.detection.evaluate.bayes_cost`).
        """
        p_miss = 1.0 - p_d if p_miss is None else p_miss
        p_cr = 1.0 - p_fa if p_cr is None else p_cr
        h1 = (p_d * self.c1 if p_d else 0.0) + (p_miss * self.c2 if p_miss else 0.0)
        h0 = (p_fa * self.c3 if p_fa else 0.0) + (p_cr * self.c4 if p_cr else 0.0)
        return p1 * h1 + (1.0 - p1) * h0


def detect_gain(problem: DetectionProblem, on_detect: str) -> np.ndarray:
    """The (n, nz) gain used after D1: zero (discard) or ``K1 = Pxz Pzz1⁻¹`` (incorporate)."""
    check_choice("on_detect", on_detect, ON_DETECT)
    return np.zeros_like(problem.K0) if on_detect == "discard" else problem.K1


def strategy_costs(problem: DetectionProblem, on_detect: str, truth: DetectionProblem) -> Costs:
    """c1..c4 of the estimators designed on ``problem``, evaluated under ``truth``'s model.

    ``truth`` differs from ``problem`` only in Pbb (the robustness experiment: the defender
    designs with an assumed Pbb, the attacker uses another); pass ``problem`` itself otherwise.
    """
    K_d1 = detect_gain(problem, on_detect)
    return Costs(
        c1=truth.mse(K_d1, 1),
        c2=truth.mse(problem.K0, 1),
        c3=truth.mse(K_d1, 0),
        c4=truth.mse(problem.K0, 0),
    )


def bayes_threshold(problem: DetectionProblem, costs: Costs) -> float:
    """Threshold α on the quadratic statistic of the Bayes test for ``costs`` (module docstring).

    Returns:
        α, +inf when the test always declares D0 (``p1 (c1 − c2) >= 0``), −inf when it always
        declares D1.

    Raises:
        ValueError: If ``c3 < c4`` beyond rounding (the test would reverse direction; no
            strategy of this package has it).
    """
    a = problem.p1 * (costs.c1 - costs.c2)
    b = problem.p0 * (costs.c3 - costs.c4)
    scale = max(abs(costs.c3), abs(costs.c4), 1.0)
    if b < -1e-12 * scale:
        raise ValueError(f"costs must have c3 >= c4 for a threshold test, got {costs}")
    if a >= 0.0:
        return math.inf
    if b <= 0.0:
        return -math.inf
    return 2.0 * math.log(b / -a) + problem.logdet1 - problem.logdet0


@dataclass(frozen=True)
class DetectionResult:
    """A detector applied to a batch of measurements.

    Attributes:
        statistic: (...,) the test statistic of each measurement.
        decision: (...,) bool, True = D1 (attack declared).
        estimate: (..., n) the state estimate after the decision.
        costs: The fixed costs c1..c4 of the strategy (under the design model).
        threshold: The threshold α (±inf for the degenerate tests).
    """

    statistic: np.ndarray
    decision: np.ndarray
    estimate: np.ndarray
    costs: Costs
    threshold: float


@dataclass(frozen=True, eq=False)
class Detector:
    """A threshold test on a statistic of the innovation, then a linear estimate.

    Attributes:
        name: Label (``"OBDD"``, ...).
        problem: The design model (x̄, Pxx, H, Pww, Pbb, p1).
        statistic: ``"quadratic"`` (``(z − z̄)'(Pzz0⁻¹ − Pzz1⁻¹)(z − z̄)``) or ``"chi2"``
            (``(z − z̄)' Pzz0⁻¹ (z − z̄)``), the env defender's statistic names.
        threshold: D1 iff statistic > threshold; ±inf allowed, NaN is not.
        on_detect: ``"discard"`` (x̂ = x̄ after D1) or ``"incorporate"`` (H1-model LMMSE).

    Derived:
        costs: c1..c4 under the design model (:func:`strategy_costs`).
        matrix: (nz, nz) the statistic's matrix (``A`` or ``Pzz0⁻¹``).
    """

    name: str
    problem: DetectionProblem
    statistic: str
    threshold: float
    on_detect: str
    costs: Costs = field(init=False)
    matrix: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        check_problem("problem", self.problem)
        check_choice("statistic", self.statistic, STATISTICS)
        check_choice("on_detect", self.on_detect, ON_DETECT)
        try:
            threshold = float(self.threshold)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"threshold must be a number, got {self.threshold!r}") from exc
        if math.isnan(threshold):
            raise ValueError(f"threshold must not be NaN, got {self.threshold!r}")
        object.__setattr__(self, "threshold", threshold)
        p = self.problem
        object.__setattr__(self, "costs", strategy_costs(p, self.on_detect, p))
        matrix = STATISTIC_TABLE[self.statistic].matrix(p.Pzz0_inv, p.Pzz1_inv)
        object.__setattr__(self, "matrix", matrix)

    def innovation(self, z: np.ndarray, x_bar: np.ndarray | None = None) -> np.ndarray:
        """``z − H x̄`` for (..., nz) measurements; ``x_bar`` (..., n) overrides the prior mean."""
        z = np.asarray(z, dtype=np.float64)
        if z.shape[-1:] != (self.problem.nz,):
            raise ValueError(f"z must have shape (..., {self.problem.nz}), got {z.shape}")
        z_bar = self.problem.z_bar if x_bar is None else np.asarray(x_bar) @ self.problem.H.T
        return z - z_bar

    def __call__(self, z: np.ndarray, x_bar: np.ndarray | None = None) -> DetectionResult:
        """Statistic, decision and estimate for a batch of measurements ``z`` (..., nz).

        Args:
            z: (..., nz) measurements.
            x_bar: (..., n) prior means, one per measurement (default the problem's x̄); the
                tracking filter's predictions ``x̂[K|K−1]`` differ run by run.
        """
        y = self.innovation(z, x_bar)
        stat = np.einsum("...i,ij,...j->...", y, self.matrix, y)
        decision = stat > self.threshold
        K_d1 = detect_gain(self.problem, self.on_detect)
        gain_y = np.where(decision[..., None], y @ K_d1.T, y @ self.problem.K0.T)
        prior = self.problem.x_bar if x_bar is None else np.asarray(x_bar, dtype=np.float64)
        return DetectionResult(stat, decision, prior + gain_y, self.costs, self.threshold)


def check_detector(name: str, value: object) -> Detector:
    """``value`` if it is a :class:`Detector`, else ``TypeError`` naming ``name``."""
    if not isinstance(value, Detector):
        raise TypeError(
            f"{name} must be a Detector (from obdd, obdi, cbd or csd), got {type(value).__name__}"
        )
    return value


def _bayes_detector(name: str, problem: DetectionProblem, on_detect: str) -> Detector:
    check_problem("problem", problem)
    costs = strategy_costs(problem, on_detect, problem)
    return Detector(name, problem, "quadratic", bayes_threshold(problem, costs), on_detect)


def obdd(problem: DetectionProblem) -> Detector:
    """Optimal Bayesian detector, discard on D1 (``c1 = c3 = tr Pxx``).

    Always declares D0 when ``c2 <= c1`` (a missed attack costs no more than discarding).

    Example:
        >>> from baselines.detection import static_problem
        >>> d = obdd(static_problem("ch3-static", 100.0))  # c2 < c1: always D0
        >>> d.threshold, round(d.costs.c1, 4), round(d.costs.c2, 4)
        (inf, 200.0, 101.0184)
        >>> d = obdd(static_problem("ch3-static", 400.0))  # α < 0 <= q: always D1
        >>> round(d.threshold, 4), round(d.costs.c2, 4)
        (-1.7831, 383.7971)
    """
    return _bayes_detector("OBDD", problem, "discard")


def obdi(problem: DetectionProblem) -> Detector:
    """Optimal Bayesian detector, incorporate with the H1 model on D1 (c2 > c1, c3 > c4)."""
    return _bayes_detector("OBDI", problem, "incorporate")


def cbd(problem: DetectionProblem) -> Detector:
    """Conventional Bayesian detector (minimum probability of error), discard on D1.

    D1 iff ``N(z; z̄, Pzz1) / N(z; z̄, Pzz0) > p0 / p1``, i.e. ``q > 2 ln(p0/p1) + ln|Pzz1| −
    ln|Pzz0|`` (the Bayes test with costs ``a = −p1``, ``b = p0``).
    """
    p = check_problem("problem", problem)
    if p.p1 == 0.0:
        alpha = math.inf
    elif p.p0 == 0.0:
        alpha = -math.inf
    else:
        alpha = 2.0 * math.log(p.p0 / p.p1) + p.logdet1 - p.logdet0
    return Detector("CBD", problem, "quadratic", alpha, "discard")


def csd(problem: DetectionProblem, level: float = 0.95) -> Detector:
    """Chi-square detector: D1 iff ``(z − z̄)' Pzz0⁻¹ (z − z̄) > χ²_{nz}(level)``, discard on D1.

    Its false-alarm rate is ``1 − level`` whatever Pbb (the statistic is χ²_{nz} under H0).
    """
    check_problem("problem", problem)
    level = check_probability("level", level)
    threshold = float(scipy.stats.chi2.ppf(level, problem.nz))
    return Detector("CSD", problem, "chi2", threshold, "discard")


# name -> constructor ``problem -> Detector`` (CSD with its default 95 % level)
DETECTORS: dict[str, Callable[[DetectionProblem], Detector]] = {
    "OBDD": obdd,
    "OBDI": obdi,
    "CBD": cbd,
    "CSD": csd,
}
