"""Stealthy attacks against bad-data detection: exact baselines.

- :func:`security_index`: the fewest meters an undetectable attack on each state needs (MILP,
  minimum cut, exhaustive checks);
- :func:`minimum_meter_attack`, :func:`budgeted_attack`: the sparsest undetectable attack and
  the most damaging one on a meter budget (exact MILPs);
- :func:`basic_measurement_set`, :func:`undetectable_attack`: protecting n independent meters
  rules out every undetectable attack, and fewer do not;
- :func:`protection_game`, :func:`protection_exploitability`: the equilibrium of the game where
  a defender protects meters on a budget and the attacker picks a stealthy budgeted attack
  (double oracle with MILP best responses), and what any protection concedes to a
  best-responding attacker;
- :func:`mo_sinopoli`: whether a sensor set admits a stealthy attack that drives a Kalman
  filter's error unbounded under a χ² innovation detector, and the attack;
- :func:`optimal_linear_attack`: the linear attack ``z̃ = T z + b`` on a remote estimator's
  innovations with the largest error under a Kullback-Leibler stealthiness budget.

Their ``.policy()`` plays them in ``stealth_attack_v0``. See docs/guide/stealth.md.
"""

from baselines.stealth.attack import (
    StealthyAttack,
    basic_measurement_set,
    budgeted_attack,
    minimum_meter_attack,
    undetectable_attack,
)
from baselines.stealth.dynamic import StealthyKalmanAttack, kalman_model, mo_sinopoli
from baselines.stealth.linear import LinearAttack, optimal_linear_attack
from baselines.stealth.policy import MixedActionPolicy, StealthPolicy
from baselines.stealth.protection import (
    ProtectionGame,
    matrix_game,
    protection_exploitability,
    protection_game,
)
from baselines.stealth.security_index import METHODS, SecurityIndex, security_index

__all__ = [
    "METHODS",
    "LinearAttack",
    "MixedActionPolicy",
    "ProtectionGame",
    "SecurityIndex",
    "StealthPolicy",
    "StealthyAttack",
    "StealthyKalmanAttack",
    "basic_measurement_set",
    "budgeted_attack",
    "kalman_model",
    "matrix_game",
    "minimum_meter_attack",
    "mo_sinopoli",
    "optimal_linear_attack",
    "protection_exploitability",
    "protection_game",
    "security_index",
    "undetectable_attack",
]
