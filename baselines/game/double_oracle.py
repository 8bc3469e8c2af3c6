"""Exact equilibrium of large sensor-selection games by double oracle (never builds all of L).

Double oracle (McMahan, Gordon & Blum, "Planning in the presence of cost functions controlled by
an adversary", ICML 2003): solve the game restricted to a few strategies per player, add each
player's best response over *all* 2^M − 1 subsets to the restricted mix of the other, repeat.
The best responses come from the factorised payoff (:class:`~baselines.game.payoff.SensorGame`):

    defender:  min_D  tr P_D + tr(W_D Σ̄ W_D'),          Σ̄ = Σ_A y_A Σ_A    (linear in y)
    attacker:  max_A  Σ_D x_D tr P_D + a² u_A' Ḡ u_A,    Ḡ = Σ_D x_D W_D' W_D  (linear in x)

so each costs O((2^M − 1)·n·M²) flops and no payoff matrix beyond the restricted one is formed.
Against the restricted equilibrium (x, y), ``lower = min_D L(D, y) ≤ v* ≤ max_A L(x, A) = upper``
for the *full* game's value v*, so ``gap = upper − lower`` certifies the answer: at termination
x and y are each within ``gap`` of optimal in the full game (their NashConv is the gap).

>>> result = solve_double_oracle("ch5-game")
>>> round(result.value, 3), result.gap <= 1e-9 * result.value
(8.106, True)
>>> {k: round(p, 2) for k, p in result.defender.items()}
{(0, 1, 2): 0.6, (1, 2): 0.4}
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from baselines.game.lp import solve_zero_sum
from baselines.game.payoff import SensorGame, make_game
from fdia_env._validation import check_int, check_positive
from fdia_env.attacks.subsets import game_subsets
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem

Subset = tuple[int, ...]


@dataclass(frozen=True)
class DoubleOracleResult:
    """A certified equilibrium of the sensor-selection game.

    Attributes:
        value: Value of the last restricted game (within ``gap`` of the full game's value).
        lower: ``min_D L(D, y)``: the attacker's mix guarantees at least this.
        upper: ``max_A L(x, A)``: the defender's mix concedes at most this.
        gap: ``upper − lower`` ≥ 0 (up to rounding): NashConv of the returned pair.
        defender: ``{subset: probability}`` over the defender's support (0-based sensor tuples).
        attacker: ``{subset: probability}`` over the attacker's support.
        iterations: Restricted games solved.
        restricted_size: Strategies in the restricted game at the end (defender, attacker).
        M: Number of sensors.
        max_subset_size: k of the strategy sets (None: every non-empty subset).
    """

    value: float
    lower: float
    upper: float
    gap: float
    defender: dict[Subset, float]
    attacker: dict[Subset, float]
    iterations: int
    restricted_size: tuple[int, int]
    M: int
    max_subset_size: int | None = None

    def strategy(self, player: str) -> np.ndarray:
        """Mixed strategy of ``"defender"`` or ``"attacker"`` over its subsets, in their order.

        (2^M − 1,) entries for the full game; with ``max_subset_size`` the player's subsets of
        :func:`~fdia_env.attacks.subsets.game_subsets`.
        """
        support = {"defender": self.defender, "attacker": self.attacker}.get(player)
        if support is None:
            raise ValueError(f"player must be 'defender' or 'attacker', got {player!r}")
        family = game_subsets(self.M, self.max_subset_size, player)
        index = {s: j for j, s in enumerate(family)}
        p = np.zeros(len(index))
        for s, prob in support.items():
            p[index[s]] = prob
        return p


def solve_double_oracle(
    system_or_scenario: str | Scenario | LinearSystem,
    power: float | None = None,
    allocation: str = "independent",
    tol: float = 1e-9,
    max_iter: int = 10_000,
    max_subset_size: int | None = None,
) -> DoubleOracleResult:
    """Equilibrium of the (2^M − 1)-strategy game without building its payoff matrix.

    Args:
        system_or_scenario: Preset name, scenario or system of scalar sensors (M ≤ 20, or any
            M with ``max_subset_size``).
        power: Attack power a² (> 0); defaults to the scenario's.
        allocation: ``"independent"`` or ``"dependent"``.
        tol: Stop when ``gap <= tol · max(|lower|, |upper|)`` (relative certificate, > 0).
        max_iter: Most restricted games to solve (≥ 1).
        max_subset_size: k of the restricted strategy sets (default the scenario's, e.g. the
            power-grid presets'; else every subset): the attacker's subsets of at most k
            sensors, the defender's leaving out at most k.

    Returns:
        A :class:`DoubleOracleResult`. If the gap cannot be closed to ``tol`` (rounding in the
        restricted LP, or ``max_iter``), the result carries the gap reached and a
        ``RuntimeWarning`` is issued.

    Raises:
        ValueError: Naming the parameter, as :func:`~baselines.game.payoff.payoff_matrix`, or
            for ``tol`` ≤ 0 or ``max_iter`` < 1.
    """
    tol = check_positive("tol", tol)
    max_iter = check_int("max_iter", max_iter, minimum=1)
    game = make_game(system_or_scenario, power, allocation, max_subset_size)
    return _double_oracle(game, tol, max_iter)


def _double_oracle(game: SensorGame, tol: float, max_iter: int) -> DoubleOracleResult:
    full = game.size - 1  # the defender starts with every sensor; the attacker best-responds
    rows = [full]
    cols = [int(np.argmax(game.attacker_values(np.array(rows), np.ones(1))))]
    in_rows, in_cols = set(rows), set(cols)
    converged, iteration = False, 0
    while iteration < max_iter:
        iteration += 1
        x, y, value = solve_zero_sum(game.payoff(np.array(rows), np.array(cols)))
        d_values = game.defender_values(np.array(cols), y)  # L(D, y) for every D
        a_values = game.attacker_values(np.array(rows), x)  # L(x, A) for every A
        d_best, a_best = int(np.argmin(d_values)), int(np.argmax(a_values))
        lower, upper = float(d_values[d_best]), float(a_values[a_best])
        if upper - lower <= tol * max(abs(lower), abs(upper)):
            converged = True
            break
        if iteration == max_iter:  # no budget to solve a grown game: x, y must match rows, cols
            break
        grew = False
        if d_best not in in_rows:
            rows.append(d_best)
            in_rows.add(d_best)
            grew = True
        if a_best not in in_cols:
            cols.append(a_best)
            in_cols.add(a_best)
            grew = True
        if not grew:  # both best responses already in play: the LP's rounding is the floor
            break
    if not converged:
        warnings.warn(
            f"double oracle stopped after {iteration} iteration(s) with gap "
            f"{upper - lower:.3g} > tol · value; the strategies are certified only to that gap",
            RuntimeWarning,
            stacklevel=3,
        )
    rows_names = game_subsets(game.M, game.max_subset_size, "defender")
    cols_names = game_subsets(game.M, game.max_subset_size, "attacker")
    return DoubleOracleResult(
        value=float(value),
        lower=lower,
        upper=upper,
        gap=upper - lower,
        defender={rows_names[r]: float(p) for r, p in zip(rows, x, strict=True) if p > 0},
        attacker={cols_names[c]: float(p) for c, p in zip(cols, y, strict=True) if p > 0},
        iterations=iteration,
        restricted_size=(len(rows), len(cols)),
        M=game.M,
        max_subset_size=game.max_subset_size,
    )
