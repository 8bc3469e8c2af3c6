"""The incomplete-information sensor game as one object: matrices, priors, equilibrium, quality.

Nature draws the attacker's type s (an allocation rule) with prior p_s; the defender never
learns it. Two attacker models (:func:`~baselines.game.lp.solve_bayesian`):

- ``"uninformed"`` (docs/math.md §5, the literature's formulation): the attacker's strategy y cannot
  depend on its type, so the game is the matrix game on ``L̄ = Σ_s p_s L_s``. Exploitability of
  the defender's x: ``max_j (L̄'x)_j − v``; of y: ``v − min_i (L̄ y)_i``.
- ``"informed"`` (Harsanyi): type s plays its own y_s. A best-responding attacker answers x
  type by type, so x concedes ``Σ_s p_s max_j (L_s'x)_j``; the defender's best response to
  (y_s) is ``min_i Σ_s p_s (L_s y_s)_i``.

Both are the exact games that ``sensor_game_v0(types=..., priors=..., attacker_model=...)``
plays in expectation over nature's draw (``tests/test_bayesian_game.py``).

>>> game = bayesian_game("ch5-game", ("independent", "dependent"), (0.5, 0.5), "uninformed")
>>> sol = game.solution
>>> sol.x.round(4).tolist(), round(sol.value, 6)
([0.0, 0.0, 0.0, 0.0, 0.0, 0.4543, 0.5457], 9.445039)
>>> round(game.exploitability(np.full(7, 1 / 7), sol.y).defender, 4)  # the uniform defender
3.4673
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from baselines._inputs import resolve_system
from baselines.game.lp import (
    ATTACKER_MODELS,
    BayesianSolution,
    Exploitability,
    as_payoffs,
    as_strategy,
    solve_bayesian,
)
from baselines.game.payoff import payoff_matrix
from fdia_env.attacks.typed import check_priors, check_types
from fdia_env.scenarios import Scenario
from fdia_env.systems import LinearSystem


@dataclass(frozen=True, eq=False)
class BayesianGame:
    """S payoff matrices (one per attacker type), their priors and the attacker model.

    Attributes:
        matrices: (S, m, n) payoffs ``L_s[D, A]`` to the attacker (the defender minimises).
        priors: (S,) probabilities of the types.
        attacker: ``"uninformed"`` or ``"informed"``.
        types: Names of the types (e.g. the allocation rules), or None.
    """

    matrices: np.ndarray
    priors: np.ndarray
    attacker: str = "uninformed"
    types: tuple[str, ...] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.attacker, str) or self.attacker not in ATTACKER_MODELS:
            raise ValueError(
                f"attacker must be one of {list(ATTACKER_MODELS)}, got {self.attacker!r}"
            )
        stack = as_payoffs(self.matrices)
        priors = as_strategy(self.priors, len(stack), "priors")
        if self.types is not None and len(self.types) != len(stack):
            raise ValueError(f"types must name the {len(stack)} matrices, got {self.types!r}")
        for name, value in (("matrices", stack), ("priors", priors)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def n_types(self) -> int:
        """S."""
        return int(self.matrices.shape[0])

    @functools.cached_property
    def mean_payoff(self) -> np.ndarray:
        """``L̄ = Σ_s p_s L_s``, the uninformed game's matrix.

        Entry (D, A) is also the expected payoff of the pure pair (D, A) over nature's draw.
        """
        out = np.tensordot(self.priors, self.matrices, axes=1)
        out.setflags(write=False)
        return out

    @functools.cached_property
    def solution(self) -> BayesianSolution:
        """The equilibrium (:func:`~baselines.game.lp.solve_bayesian`, HiGHS)."""
        return solve_bayesian(list(self.matrices), self.priors, attacker=self.attacker)

    @property
    def value(self) -> float:
        """The equilibrium's expected payoff to the attacker."""
        return self.solution.value

    def attacker_strategy(self, y: Any) -> np.ndarray:
        """``y`` as an (S, n) strategy per type (an (n,) type-blind one is broadcast).

        Raises:
            ValueError: For a wrong shape or a row that is not a probability vector; in the
                uninformed model, for rows that differ (that attacker cannot use its type).
        """
        S, n = self.n_types, self.matrices.shape[2]
        arr = np.asarray(y, dtype=np.float64)
        if arr.ndim == 1:
            arr = np.tile(arr, (S, 1))
        if arr.shape != (S, n):
            raise ValueError(f"y must have shape ({n},) or ({S}, {n}), got {np.shape(y)}")
        rows = np.stack([as_strategy(row, n, f"y[{s}]") for s, row in enumerate(arr)])
        if self.attacker == "uninformed" and np.abs(rows - rows[0]).max() > 1e-12:
            raise ValueError(
                "y must be the same for every type in the uninformed model (the attacker does "
                "not know its type); pass an (n,) strategy"
            )
        return rows

    def defender_worst_case(self, x: Any) -> float:
        """What a best-responding attacker gets against ``x`` (the defender's guarantee)."""
        x = as_strategy(x, self.matrices.shape[1], "x")
        if self.attacker == "uninformed":
            return float((x @ self.mean_payoff).max())
        per_type = np.einsum("i,sij->sj", x, self.matrices).max(axis=1)  # max_j (L_s'x)_j
        return float(self.priors @ per_type)

    def attacker_worst_case(self, y: Any) -> float:
        """What a best-responding defender concedes against ``y``: ``min_i Σ_s p_s (L_s y_s)_i``."""
        ys = self.attacker_strategy(y)
        return float(np.einsum("s,sij,sj->i", self.priors, self.matrices, ys).min())

    def payoff(self, x: Any, y: Any) -> float:
        """Expected payoff ``Σ_s p_s x' L_s y_s``."""
        x = as_strategy(x, self.matrices.shape[1], "x")
        ys = self.attacker_strategy(y)
        return float(np.einsum("s,i,sij,sj->", self.priors, x, self.matrices, ys))

    def exploitability(self, x: Any, y: Any, value: float | None = None) -> Exploitability:
        """Each side's exploitability against the exact Bayesian game and their NashConv.

        Args:
            x: (m,) the defender's mixed strategy.
            y: (n,) a type-blind attacker strategy, or (S, n) one per type (informed model).
            value: The game value (default: the equilibrium's).

        Returns:
            An :class:`~baselines.game.lp.Exploitability`: ``defender`` = worst case of x
            minus v (uninformed: ``max_j (L̄'x)_j − v``; informed:
            ``Σ_s p_s max_j (L_s'x)_j − v``), ``attacker`` = ``v − min_i Σ_s p_s (L_s y_s)_i``.
        """
        v = self.value if value is None else float(value)
        best_attack = self.defender_worst_case(x)
        best_defence = self.attacker_worst_case(y)
        return Exploitability(
            defender=best_attack - v,
            attacker=v - best_defence,
            nash_conv=best_attack - best_defence,
            value=v,
        )


def bayesian_game(
    system_or_scenario: str | Scenario | LinearSystem,
    types: Sequence[str],
    priors: Sequence[float] | np.ndarray | None = None,
    attacker: str = "uninformed",
    power: float | None = None,
    max_subset_size: int | None = None,
) -> BayesianGame:
    """The sensor game's :class:`BayesianGame`: one :func:`payoff_matrix` per allocation type.

    Args:
        system_or_scenario: As :func:`~baselines.game.payoff.payoff_matrix`.
        types: Distinct allocation rules (``"independent"``, ``"dependent"``).
        priors: Their probabilities (default uniform).
        attacker: ``"uninformed"`` or ``"informed"``.
        power: Attack power (default the scenario's).
        max_subset_size: As :func:`~baselines.game.payoff.payoff_matrix`.

    Raises:
        ValueError: Naming the parameter (types, priors, attacker, or as ``payoff_matrix``).
    """
    types = check_types(types)
    p = check_priors(priors, len(types))
    sc = resolve_system(system_or_scenario)
    mats = [payoff_matrix(sc, power, t, max_subset_size) for t in types]
    return BayesianGame(np.stack(mats), p, attacker, types)


def bayesian_game_of(parallel: Any) -> BayesianGame:
    """The :class:`BayesianGame` a typed ``sensor_game_v0`` parallel env plays.

    Args:
        parallel: ``sensor_game_v0.parallel_env(types=..., ...)`` (its scenario and its typed
            attack's types, priors, attacker model, power and largest subset).

    Raises:
        ValueError: For an object that is not a parallel env with an attack (a Gymnasium view,
            a scenario name) or an env whose attack has no types (an untyped sensor game).

    Example:
        >>> from fdia_env import sensor_game_v0
        >>> env = sensor_game_v0.parallel_env(types=("independent", "dependent"))
        >>> game = bayesian_game_of(env)
        >>> game.types, game.matrices.shape
        (('independent', 'dependent'), (2, 7, 7))
    """
    attack = getattr(parallel, "attack", None)
    if attack is None:
        raise ValueError(
            "parallel must be a sensor_game_v0 parallel env with types=(...), got a "
            f"{type(parallel).__name__} (a Gymnasium view: pass env.unwrapped.parallel)"
        )
    if getattr(attack, "types", None) is None:
        raise ValueError(
            "parallel must be a sensor_game_v0 env with types=(...) (a typed attack), got one "
            f"with a {type(attack).__name__}"
        )
    return bayesian_game(
        parallel.scenario,
        attack.types,
        attack.priors,
        attack.attacker_model,
        attack.power,
        attack.max_subset_size,
    )
