"""Optimal Bayesian detectors with minimum MSE (docs/math.md §3), and their evaluation.

The static problem (:class:`DetectionProblem`: prior ``N(x̄, Pxx)``, ``z = H x + w (+ b)``,
attack probability p1) comes from a static scenario (:func:`static_problem`, ch3-static) or a
tracking scenario at its attack time (:func:`tracking_problem`, ch3-tracking: the prior is the
filter's prediction). The attacker's default Pbb maximises the missed-attack cost c2
(:func:`c2_optimal_pbb`, rank one).

Detectors (each a :class:`Detector`: a threshold on the env's ``"quadratic"`` or ``"chi2"``
statistic, then ``"discard"`` or ``"incorporate"`` on D1; calling one on a batch of
measurements returns decisions, estimates, the costs c1..c4 and the threshold):
:func:`obdd`, :func:`obdi`, :func:`cbd`, :func:`csd`; and the estimator :func:`mmse`.

Evaluation: :func:`bayes_cost` (fixed costs and numerical detection probabilities, Imhof's
method in :mod:`.gchisq`) and :func:`monte_carlo` (the true squared error on common random
numbers).

>>> from baselines.detection import bayes_cost, csd, monte_carlo, obdd, static_problem
>>> problem = static_problem("ch3-static", 100.0)
>>> detector = obdd(problem)  # here c2 < c1: a missed attack costs less than discarding
>>> detector.statistic, detector.threshold, detector.on_detect
('quadratic', inf, 'discard')
>>> r = bayes_cost(csd(problem))
>>> round(r.p_fa, 4), round(r.p_d, 4), round(r.value, 3)
(0.05, 0.1336, 99.569)
>>> mc = monte_carlo(problem, {"OBDD": detector, "CSD": csd(problem)}, draws=10_000, seed=0)
>>> round(mc.stats["CSD"].p_fa, 2)
0.05
"""

from baselines.detection.detectors import (
    DETECTORS,
    ON_DETECT,
    STATISTICS,
    Costs,
    DetectionResult,
    Detector,
    bayes_threshold,
    cbd,
    csd,
    obdd,
    obdi,
    strategy_costs,
)
from baselines.detection.evaluate import (
    BayesCost,
    MonteCarlo,
    MonteCarloStats,
    bayes_cost,
    decision_probabilities,
    detection_probabilities,
    expected_mse,
    monte_carlo,
)
from baselines.detection.mmse import MMSEEstimator, MMSEResult, mmse
from baselines.detection.policy import as_policy
from baselines.detection.problem import (
    DetectionProblem,
    predicted_covariance,
    static_problem,
    tracking_problem,
)
from baselines.detection.tracking import simulate_prediction
from fdia_env.detection.attack import c2_gain_matrix, c2_optimal_pbb
from fdia_env.detection.gchisq import (
    gchisq_cdf,
    gchisq_sf,
    gchisq_sf_mc,
    gchisq_tails,
    quadratic_form_weights,
)

__all__ = [
    "DETECTORS",
    "ON_DETECT",
    "STATISTICS",
    "BayesCost",
    "Costs",
    "DetectionProblem",
    "DetectionResult",
    "Detector",
    "MMSEEstimator",
    "MMSEResult",
    "MonteCarlo",
    "MonteCarloStats",
    "as_policy",
    "bayes_cost",
    "bayes_threshold",
    "c2_gain_matrix",
    "c2_optimal_pbb",
    "cbd",
    "csd",
    "decision_probabilities",
    "detection_probabilities",
    "expected_mse",
    "gchisq_cdf",
    "gchisq_sf",
    "gchisq_sf_mc",
    "gchisq_tails",
    "mmse",
    "monte_carlo",
    "obdd",
    "obdi",
    "predicted_covariance",
    "quadratic_form_weights",
    "simulate_prediction",
    "static_problem",
    "strategy_costs",
    "tracking_problem",
]
