"""The sparse-attack problem of docs/math.md §4 and its reference evaluation.

A filter in steady state at K (all sensors) runs the window K+1..K+N; the attacker removes
``budget`` (c) sensor-time pairs, the defender drops exactly those measurements, and the attacker
scores ``Φ(P[K+N|K+N])``:

    P[k|k−1] = F P[k−1|k−1] F' + Q
    P[k|k]⁻¹ = P[k|k−1]⁻¹ + Σ_{i ∉ A_k} H_i' R_i⁻¹ H_i

Pairs are ``(step, sensor)``, both 0-based, step 0 = K+1 (the env's first step).
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

from baselines._inputs import resolve_system
from fdia_env._validation import check_choice, check_int
from fdia_env.kalman import information_update, objective, predict_cov, steady_state
from fdia_env.scenarios import Scenario, scenario_default
from fdia_env.systems import LinearSystem, check_system

MAX_HORIZON = 10_000  # longest attack window N a sparse problem accepts

OBJECTIVES = ("trace", "logdet")

Pair = tuple[int, int]


@dataclass(frozen=True, eq=False)
class SparseProblem:
    """A validated sparse-attack instance.

    Attributes:
        system: The linear Gaussian system (M sensors, state size n).
        budget: Sparsity budget c, ``0 <= c <= M·N``.
        horizon: Window length N, ``>= 1``.
        objective: Φ: ``"trace"`` or ``"logdet"``.

    Derived (computed in ``__post_init__``):
        P_start: (n, n) steady-state ``P[K|K]`` with every sensor.
        size: Number of candidate pairs ``M·N``.
    """

    system: LinearSystem
    budget: int
    horizon: int
    objective: str = "trace"
    P_start: np.ndarray = field(init=False, repr=False)
    size: int = field(init=False)

    def __post_init__(self) -> None:
        check_system(self.system)
        # an attack window beyond MAX_HORIZON steps is no search problem (numpy would fail to
        # allocate its masks, naming nothing); the covariance multi-shot uses the same bound
        horizon = check_int("horizon", self.horizon, minimum=1, maximum=MAX_HORIZON)
        budget = check_int("budget", self.budget, minimum=0)
        size = self.system.M * horizon
        if budget > size:
            raise ValueError(
                f"budget must be <= M * horizon = {size} (every sensor-time pair of the "
                f"window), got {budget}"
            )
        check_choice("objective", self.objective, OBJECTIVES)
        P_start = steady_state(self.system)[1]
        P_start.setflags(write=False)
        for name, value in (
            ("budget", budget),
            ("horizon", horizon),
            ("P_start", P_start),
            ("size", size),
        ):
            object.__setattr__(self, name, value)

    @property
    def M(self) -> int:
        """Number of sensors."""
        return self.system.M

    def pairs(self) -> list[Pair]:
        """Every candidate pair in the solvers' canonical order: by step, then by sensor."""
        return [(k, i) for k in range(self.horizon) for i in range(self.M)]

    def masks(self, attack_sets: Iterable[Iterable[Pair]]) -> np.ndarray:
        """(B, N, M) boolean "attacked" masks of a batch of attack sets."""
        sets = list(attack_sets)
        out = np.zeros((len(sets), self.horizon, self.M), dtype=bool)
        for b, pairs in enumerate(sets):
            for k, i in pairs:
                out[b, k, i] = True
        return out

    def evaluate_masks(self, attacked: np.ndarray) -> np.ndarray:
        """Φ(P[K+N|K+N]) of a batch of attack patterns.

        Args:
            attacked: (..., N, M) booleans, True where the pair is attacked (and dropped).

        Returns:
            (...) objective values.
        """
        attacked = np.asarray(attacked, dtype=bool)
        if attacked.shape[-2:] != (self.horizon, self.M):
            raise ValueError(
                f"attacked must have shape (..., {self.horizon}, {self.M}), got {attacked.shape}"
            )
        sys = self.system
        P = np.broadcast_to(self.P_start, (*attacked.shape[:-2], sys.n, sys.n))
        for k in range(self.horizon):
            # P[k|k]⁻¹ = (F P F' + Q)⁻¹ + Σ_{i not attacked} J_i
            P = information_update(predict_cov(P, sys.F, sys.Q), sys.J, ~attacked[..., k, :])
        return objective(P, self.objective)

    def evaluate(self, pairs: Iterable[Pair]) -> float:
        """Φ(P[K+N|K+N]) of one attack set (the reference every solver reports)."""
        return float(self.evaluate_masks(self.masks([pairs]))[0])


def make_problem(
    system_or_scenario: str | Scenario | LinearSystem,
    budget: int | None,
    horizon: int | None,
    objective: str = "trace",
) -> SparseProblem:
    """Build a :class:`SparseProblem`; ``budget``/``horizon`` default to the preset's values.

    The solvers of :mod:`baselines.sparse` take these four arguments first and pass them here.

    Args:
        system_or_scenario: Preset name, :class:`Scenario` or :class:`LinearSystem`.
        budget: Sparsity budget c (default: the preset's).
        horizon: Window length N (default: the preset's).
        objective: ``"trace"`` or ``"logdet"``.

    Returns:
        The problem: the system in steady state at K with every sensor, c, N and Φ.

    Raises:
        ValueError: Naming the parameter: a budget that is negative, not an integer or larger
            than ``M·N``; a horizon below 1; an unknown objective or scenario.
    """
    sc = resolve_system(system_or_scenario)
    budget = scenario_default(sc, "budget", budget)
    horizon = scenario_default(sc, "horizon", horizon)
    return SparseProblem(sc.system, budget, horizon, objective)
