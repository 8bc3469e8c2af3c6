"""Average MSE of the detectors two ways: the Bayes cost and a Monte Carlo of the true error.

**Bayes cost** (docs/math.md §3):
``c = p1[P_d c1 + (1 − P_d) c2] + p0[P_fa c3 + (1 − P_fa) c4]`` with
the fixed costs c1..c4 and the detection probabilities ``P_fa = P(D1|H0)``, ``P_d = P(D1|H1)``
of the threshold test, computed numerically (:mod:`.gchisq`: the statistic is a generalized
chi-square under each hypothesis). The fixed costs are unconditional MSEs; the true MSE given a
decision differs because the decision depends on the same innovation as the estimate (a large
innovation is both more likely declared an attack and more likely to come from a state far from
x̄), which is why the two rankings can disagree.

**Monte Carlo** (:func:`monte_carlo`): ``x ~ N(x̄, Pxx)``, ``w ~ N(0, Pww)``, ``b ~ N(0, Pbb)``
drawn once (seeded) and shared by every estimator (common random numbers); each draw is scored
under *both* hypotheses, ``z0 = H x + w`` and ``z1 = z0 + b``, and contributes
``p1 ‖x̂(z1) − x‖² + p0 ‖x̂(z0) − x‖²``: an unbiased estimate of the average MSE without the
Bernoulli noise of drawing the hypothesis. Standard errors are the sample standard deviation of
these per-draw values over ``√draws``; paired differences between estimators
(:meth:`MonteCarlo.difference`) use the per-draw differences, which common random numbers make
far less noisy than either estimate.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from baselines.detection.detectors import (
    Costs,
    Detector,
    check_detector,
    detect_gain,
    strategy_costs,
)
from baselines.detection.mmse import MMSEEstimator
from baselines.detection.problem import DetectionProblem, check_problem
from fdia_env._validation import check_int
from fdia_env.detection.expected import expected_squared_error, statistic_weights
from fdia_env.detection.gchisq import gchisq_tails
from fdia_env.kalman import psd_sqrt


def _truth(detector: Detector, truth: DetectionProblem | None) -> DetectionProblem:
    check_detector("detector", detector)
    if truth is None:
        return detector.problem
    check_problem("truth", truth)
    d = detector.problem
    if truth.Pxx.shape != d.Pxx.shape or truth.H.shape != d.H.shape:
        raise ValueError(
            f"truth must have the detector's shapes: Pxx {d.Pxx.shape}, H {d.H.shape}; got "
            f"Pxx {truth.Pxx.shape}, H {truth.H.shape}"
        )
    return truth


def detection_probabilities(
    detector: Detector, truth: DetectionProblem | None = None
) -> tuple[float, float]:
    """``(P_fa, P_d)`` of ``detector`` when the data follow ``truth`` (default its own model).

    ``P(D1|H_h) = P(y' M y > threshold)``, ``y ~ N(0, Pzz_h)`` of ``truth``, M the statistic's
    matrix (:func:`decision_probabilities`).
    """
    _, p_fa, _, p_d = decision_probabilities(detector, truth)
    return p_fa, p_d


def decision_probabilities(
    detector: Detector, truth: DetectionProblem | None = None
) -> tuple[float, float, float, float]:
    """``(P(D0|H0), P(D1|H0), P(D0|H1), P(D1|H1))``, each accurate relative to its size.

    ``P(D0|H1)`` of a strong attack is tiny and multiplies the missed-attack cost c2 ~ a², so it
    is computed directly (:func:`~fdia_env.detection.gchisq.gchisq_tails`), never as
    ``1 − P_d``.
    """
    t = _truth(detector, truth)
    tau, A = float(detector.threshold), detector.matrix
    p_cr, p_fa = gchisq_tails(tau, statistic_weights(A, t.Pzz0, None))
    p_miss, p_d = gchisq_tails(tau, statistic_weights(A, t.Pzz0, t.Pbb))  # Pzz1 never formed
    return p_cr, p_fa, p_miss, p_d


@dataclass(frozen=True)
class BayesCost:
    """A detector's Bayes cost under a model.

    Attributes:
        p_fa: P(D1 | H0), numerical.
        p_d: P(D1 | H1), numerical.
        costs: c1..c4 of the detector's estimators under the model.
        value: The average cost c.
    """

    p_fa: float
    p_d: float
    costs: Costs
    value: float


def bayes_cost(detector: Detector, truth: DetectionProblem | None = None) -> BayesCost:
    """The Bayes cost of ``detector`` with the data following ``truth`` (default its own model).

    Example:
        >>> from baselines.detection import obdi, static_problem
        >>> r = bayes_cost(obdi(static_problem("ch3-static", 100.0)))  # always D1: P_fa = P_d = 1
        >>> round(r.p_fa, 4), round(r.p_d, 4), round(r.value, 4)
        (1.0, 1.0, 50.9451)
    """
    t = _truth(detector, truth)
    p_cr, p_fa, p_miss, p_d = decision_probabilities(detector, t)
    costs = strategy_costs(detector.problem, detector.on_detect, t)
    return BayesCost(p_fa, p_d, costs, costs.bayes(t.p1, p_d, p_fa, p_miss, p_cr))


def expected_mse(detector: Detector, truth: DetectionProblem | None = None) -> float:
    """The exact average squared error of ``detector``'s estimate (not the Bayes cost).

    Under hypothesis h the innovation is ``y ~ N(0, C_h)`` (C_h = Pzz_h of ``truth``) and
    ``x − x̄ = K_h* y + e`` with ``K_h* = Pxz C_h⁻¹`` and e independent of y, of covariance
    ``Pxx − K_h* Pxz'``. With the decision's gain ``K_D`` the error is ``(K_h* − K_D) y + e``, so

        E‖x − x̂‖² = Σ_h p_h ( tr[Pxx − K_h* Pxz'] + tr[G_0 (C_h − Y_h)] + tr[G_1 Y_h] ),

    ``G_D = (K_h* − K_D)'(K_h* − K_D)``, ``Y_h = E[y y' 1{D1}]``; computed by
    :func:`fdia_env.detection.expected.expected_squared_error` (the detection game's reward).
    This is the quantity :func:`monte_carlo` estimates; the two are compared in the tests.
    """
    t = _truth(detector, truth)
    out = expected_squared_error(
        t.Pxx,
        t.H,
        t.Pww,
        t.Pbb,
        t.p1,
        detector.matrix,
        detector.threshold,
        detector.problem.K0,
        detect_gain(detector.problem, detector.on_detect),
        assumed_sigma=detector.problem.Pbb if detector.on_detect == "incorporate" else None,
    )
    return out.mse


Estimator = Detector | MMSEEstimator


@dataclass(frozen=True)
class MonteCarloStats:
    """Monte-Carlo results of one estimator (see the module docstring).

    Attributes:
        mse: Average squared error ``p1 E‖e‖²|H1 + p0 E‖e‖²|H0``.
        se: Its standard error.
        mse_h0, mse_h1: The MSE under each hypothesis.
        p_fa, p_d: Fraction of draws declared D1 under H0 and H1 (NaN for MMSE).
        fixed_cost: Average of the fixed cost of each draw's (decision, hypothesis) pair, the
            Monte-Carlo counterpart of the Bayes cost (NaN for MMSE).
        fixed_se: Its standard error.
    """

    mse: float
    se: float
    mse_h0: float
    mse_h1: float
    p_fa: float
    p_d: float
    fixed_cost: float
    fixed_se: float


@dataclass(frozen=True)
class MonteCarlo:
    """Monte-Carlo results for several estimators on common random numbers.

    Attributes:
        draws: Number of draws.
        stats: Name -> :class:`MonteCarloStats`.
        samples: Name -> (draws,) per-draw ``p1 ‖e1‖² + p0 ‖e0‖²`` (for paired comparisons).
    """

    draws: int
    stats: dict[str, MonteCarloStats]
    samples: dict[str, np.ndarray] = field(repr=False)

    def difference(self, a: str, b: str) -> tuple[float, float]:
        """Mean and standard error of the paired per-draw difference ``MSE(a) − MSE(b)``."""
        d = self.samples[a] - self.samples[b]
        return float(d.mean()), float(d.std(ddof=1) / np.sqrt(d.size))


def draw_prior(
    problem: DetectionProblem, draws: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """``(x, x̄)``: ``draws`` states from the prior ``N(x̄, Pxx)`` and the (repeated) prior mean."""
    x = problem.x_bar + rng.standard_normal((draws, problem.n)) @ psd_sqrt(problem.Pxx).T
    return x, np.broadcast_to(problem.x_bar, x.shape)


def monte_carlo(
    truth: DetectionProblem,
    estimators: Mapping[str, Estimator],
    draws: int = 100_000,
    seed: int = 0,
    states: tuple[np.ndarray, np.ndarray] | None = None,
) -> MonteCarlo:
    """Monte-Carlo MSE, P_fa, P_d and fixed-cost average of each estimator under ``truth``.

    Args:
        truth: The data-generating model (its Pbb is the attacker's).
        estimators: Name -> detector or MMSE estimator (designed on any model of the same
            shapes, e.g. with an assumed Pbb).
        draws: Number of draws (each scored under both hypotheses).
        seed: Seed of the generator for x (unless ``states``), w and b.
        states: Optional ``(x, x̄)`` of shape (draws, n) each: true states and per-draw prior
            means (e.g. from a simulated tracking filter, :func:`simulate_prediction`); by
            default ``x ~ N(x̄, Pxx)`` of ``truth`` and x̄ its prior mean.

    Returns:
        A :class:`MonteCarlo`.
    """
    check_problem("truth", truth)
    draws = check_int("draws", draws, minimum=2)
    rng = np.random.default_rng(seed)
    if states is None:
        x, x_bar = draw_prior(truth, draws, rng)
    else:
        x, x_bar = (np.asarray(a, dtype=np.float64) for a in states)
        if x.shape != (draws, truth.n) or x_bar.shape != (draws, truth.n):
            raise ValueError(
                f"states must be two ({draws}, {truth.n}) arrays, got {x.shape} and {x_bar.shape}"
            )
    w = rng.standard_normal((draws, truth.nz)) @ np.linalg.cholesky(truth.Pww).T
    b = rng.standard_normal((draws, truth.nz)) @ psd_sqrt(truth.Pbb).T
    z0 = x @ truth.H.T + w
    z1 = z0 + b
    p1, p0 = truth.p1, truth.p0
    stats, samples = {}, {}
    for name, est in estimators.items():
        r0, r1 = est(z0, x_bar), est(z1, x_bar)
        e0 = np.sum((r0.estimate - x) ** 2, axis=-1)
        e1 = np.sum((r1.estimate - x) ** 2, axis=-1)
        per_draw = p1 * e1 + p0 * e0
        samples[name] = per_draw
        p_fa = p_d = fixed = fixed_se = float("nan")
        if isinstance(est, Detector):
            d0, d1 = r0.decision, r1.decision
            c = strategy_costs(est.problem, est.on_detect, truth)
            cost = p1 * np.where(d1, c.c1, c.c2) + p0 * np.where(d0, c.c3, c.c4)
            p_fa, p_d = float(d0.mean()), float(d1.mean())
            fixed = float(cost.mean())
            # a constant decision gives a constant cost: its SE is 0, not the rounding of std
            spread = cost.max() > cost.min()
            fixed_se = float(cost.std(ddof=1) / np.sqrt(draws)) if spread else 0.0
        stats[name] = MonteCarloStats(
            mse=float(per_draw.mean()),
            se=float(per_draw.std(ddof=1) / np.sqrt(draws)),
            mse_h0=float(e0.mean()),
            mse_h1=float(e1.mean()),
            p_fa=p_fa,
            p_d=p_d,
            fixed_cost=fixed,
            fixed_se=fixed_se,
        )
    return MonteCarlo(draws, stats, samples)
