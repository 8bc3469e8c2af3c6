"""The sensor-selection game (docs/math.md §5): payoff, LP equilibria, double oracle, policies.

- :func:`payoff_matrix`, :func:`attack_covariance`: the factorised payoff
  ``L[D, A] = tr P_D + ⟨W_D' W_D, Σ_A⟩`` and the attacker's Prop-2 / Prop-3 bias covariance;
- :func:`solve_zero_sum`, :func:`solve_bayesian`, :func:`exploitability`: LP equilibria (HiGHS)
  of complete- and incomplete-information games and their quality;
- :func:`strategy_bounds`: how much of a strategy is pinned down over all equilibria;
- :class:`BayesianGame`, :func:`bayesian_game`: the incomplete-information game (nature draws
  the attacker's type) with its equilibrium and exploitability, as ``sensor_game_v0(types=...)``
  plays it;
- :func:`solve_double_oracle`: exact equilibria of games too large to write down (M = 16:
  65,535 strategies each), certified by the best-response gap;
- :class:`MixedStrategyPolicy`: an equilibrium strategy as an SB3-style policy;
- :func:`to_nashpy`, :func:`to_openspiel_matrix`: the game in other libraries' terms.

>>> from baselines.game import payoff_matrix, solve_zero_sum
>>> x, y, value = solve_zero_sum(payoff_matrix("ch5-game"))
>>> x.round(2).tolist(), round(value, 3)
([0.0, 0.0, 0.0, 0.0, 0.0, 0.4, 0.6], 8.106)
"""

from baselines.game.bayesian import BayesianGame, bayesian_game, bayesian_game_of
from baselines.game.double_oracle import DoubleOracleResult, solve_double_oracle
from baselines.game.interop import OpenSpielMatrixArgs, to_nashpy, to_openspiel_matrix
from baselines.game.lp import (
    BayesianSolution,
    Exploitability,
    exploitability,
    solve_bayesian,
    solve_zero_sum,
    strategy_bounds,
)
from baselines.game.payoff import (
    ALLOCATIONS,
    SensorGame,
    attack_covariance,
    make_game,
    payoff_matrix,
)
from baselines.game.policy import MixedStrategyPolicy, TypedMixedStrategyPolicy

__all__ = [
    "ALLOCATIONS",
    "BayesianGame",
    "BayesianSolution",
    "DoubleOracleResult",
    "Exploitability",
    "MixedStrategyPolicy",
    "OpenSpielMatrixArgs",
    "SensorGame",
    "TypedMixedStrategyPolicy",
    "attack_covariance",
    "bayesian_game",
    "bayesian_game_of",
    "exploitability",
    "make_game",
    "payoff_matrix",
    "solve_bayesian",
    "solve_double_oracle",
    "solve_zero_sum",
    "strategy_bounds",
    "to_nashpy",
    "to_openspiel_matrix",
]
