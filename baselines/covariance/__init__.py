"""Closed-form bias covariances against an unaware filter (docs/math.md §2), and their policies.

Single injection at the steady-state attack time K, power ``tr(Ω Σ) = a²``:

- :func:`trace_optimal`: ``max tr(P + W Σ W')``; ``structure="full"`` (dependent biases, rank
  one along the top eigenvector) or ``"diagonal"`` (independent biases across sensors);
- :func:`det_optimal`: ``max det(P + W Σ W')`` by water-filling, checked by
  :func:`kkt_residuals`;
- the literature's special cases :func:`independent_position_rule`,
  :func:`dependent_position_rule` and :func:`pv_single_sensor_rule`.

Over a window: :func:`multi_shot` (the C_j rule), cross-checked by :func:`recursion_objective`.
:func:`equivalent_sensor` reduces M sensors to one (docs/math.md §2.4). ``result.policy(env)`` plays
an answer in ``covariance_attack_v0``.

>>> from baselines.covariance import trace_optimal
>>> result = trace_optimal("ch2-position")
>>> round(result.value, 1), result.variances.round(1).tolist()
(609.9, [1920.0, 1080.0])
"""

from baselines.covariance.determinant import KKTResiduals, det_optimal, kkt_residuals, water_filling
from baselines.covariance.equivalent import EquivalentSensor, equivalent_sensor
from baselines.covariance.multishot import MultiShotResult, multi_shot, recursion_objective
from baselines.covariance.policy import CovariancePolicy
from baselines.covariance.problem import CovarianceProblem, make_problem
from baselines.covariance.result import CovarianceResult, evaluate
from baselines.covariance.trace import (
    STRUCTURES,
    dependent_position_rule,
    independent_position_rule,
    pv_single_sensor_rule,
    trace_optimal,
)

__all__ = [
    "STRUCTURES",
    "CovariancePolicy",
    "CovarianceProblem",
    "CovarianceResult",
    "EquivalentSensor",
    "KKTResiduals",
    "MultiShotResult",
    "dependent_position_rule",
    "det_optimal",
    "equivalent_sensor",
    "evaluate",
    "independent_position_rule",
    "kkt_residuals",
    "make_problem",
    "multi_shot",
    "pv_single_sensor_rule",
    "recursion_objective",
    "trace_optimal",
    "water_filling",
]
