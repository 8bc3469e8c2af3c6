"""What every sparse-attack solver returns."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from baselines.sparse.problem import Pair, SparseProblem

if TYPE_CHECKING:
    from baselines.sparse.policy import SparsePolicy


@dataclass(frozen=True)
class SparseResult:
    """A solver's attack set and its objective value.

    Attributes:
        value: Φ(P[K+N|K+N]) of ``attacks``, recomputed by the reference recursion
            (:meth:`SparseProblem.evaluate`), so two solvers that find the same set report the
            identical number.
        attacks: The attacked ``(step, sensor)`` pairs, both 0-based (step 0 = K+1), sorted.
        solver: Name of the solver (``"exs"``, ``"sfs"``, ``"sbs"``, ``"sfs_ss"``, ``"dp"``).
        horizon: Window length N the set was computed for.
        num_sensors: Number of sensors M.
        objective: ``"trace"`` or ``"logdet"``.
        order: SFS only: the pairs in pick order (the first ``b`` picks are SFS's answer for
            budget ``b``). ``None`` for every other solver.
        evaluations: Number of objective evaluations of candidate sets (for EXS the number of
            sets, ``C(M·N, c)``; for DP the number of one-step candidates ``(s, r)`` tried).
        upper_bound: Certified upper bound on the optimum (branch and bound only; ``None`` for
            the other solvers). Equal to ``value`` when the optimum is proved.
        gap: ``gap_to(upper_bound)``, filled in from ``upper_bound`` (0 when proved optimal).
        nodes: Search-tree nodes bounded or evaluated (branch and bound only).
        seconds: Wall time of the solve (branch and bound only).
        proved_optimal: True when the search completed, so ``value`` is the optimum (up to the
            pruning tolerance, relative 1e-12, and 1e-9 for a proof
            at the root); ``None`` for solvers that give no proof.
    """

    value: float
    attacks: tuple[Pair, ...]
    solver: str
    horizon: int
    num_sensors: int
    objective: str = "trace"
    order: tuple[Pair, ...] | None = None
    evaluations: int | None = None
    upper_bound: float | None = None
    gap: float | None = None
    nodes: int | None = None
    seconds: float | None = None
    proved_optimal: bool | None = None

    def __post_init__(self) -> None:
        attacks = tuple(sorted((int(k), int(i)) for k, i in self.attacks))
        object.__setattr__(self, "attacks", attacks)
        if self.upper_bound is not None:
            if self.upper_bound < self.value - 1e-9 * max(abs(self.value), 1.0):
                raise ValueError(
                    f"upper_bound must be >= value, got {self.upper_bound!r} < {self.value!r}"
                )
            if self.gap is None:
                object.__setattr__(self, "gap", self.gap_to(self.upper_bound))
        if self.order is not None:
            object.__setattr__(self, "order", tuple((int(k), int(i)) for k, i in self.order))

    def gap_to(self, bound: float) -> float:
        """Relative gap of this result's value to an upper ``bound`` on the optimum.

        In the objective's natural units: ``1 − tr P / bound`` for the trace, and
        ``1 − det P / exp(bound)`` for log det (``bound`` is then a log-determinant). 0 means
        the value reaches the bound (optimal); 0.01 means within 1 % of it; an infinite bound
        gives 1. Clipped at 0 (a bound below the value by rounding).

        Raises:
            ValueError: If ``bound`` is not a number, is NaN or is −inf.
        """
        if isinstance(bound, bool) or not isinstance(bound, (int, float, np.floating)):
            raise ValueError(f"bound must be a number, got {bound!r}")
        bound = float(bound)
        if math.isnan(bound) or bound == -math.inf:
            raise ValueError(f"bound must be a number above -inf, got {bound!r}")
        if bound == math.inf:
            return 1.0
        if self.objective == "logdet":
            gap = -math.expm1(self.value - bound)
        else:
            gap = (bound - self.value) / abs(bound) if bound != 0 else 0.0
        return max(0.0, gap)

    @property
    def budget(self) -> int:
        """Number of attacked pairs."""
        return len(self.attacks)

    def actions(self) -> np.ndarray:
        """(N,) the env action per window step: bitmask of attacked sensors (bit 0 = sensor 1)."""
        out = np.zeros(self.horizon, dtype=np.int64)
        for k, i in self.attacks:
            out[k] |= 1 << i
        return out

    def plan(self) -> np.ndarray:
        """(N, M) int8: 1 where the pair (step, sensor) is attacked (the MultiBinary actions)."""
        out = np.zeros((self.horizon, self.num_sensors), dtype=np.int8)
        for k, i in self.attacks:
            out[k, i] = 1
        return out

    def grid(self) -> np.ndarray:
        """(M, N) ints: pick number (1-based) where SFS's ``order`` has a pair, else 0.

        For solvers without an order, 1 marks an attacked pair.
        """
        out = np.zeros((self.num_sensors, self.horizon), dtype=int)
        if self.order is None:
            for k, i in self.attacks:
                out[i, k] = 1
        else:
            for rank, (k, i) in enumerate(self.order, start=1):
                out[i, k] = rank
        return out

    def policy(self, action: str = "auto") -> SparsePolicy:
        """This answer as a policy that plays ``sparse_attack_v0`` in its ``action`` format.

        Args:
            action: The env's action format: ``"auto"`` (the env's default: bitmask up to 16
                sensors, MultiBinary above), ``"bitmask"``, ``"multibinary"`` or
                ``"sequential"``.

        Raises:
            ValueError: For another format (``"single"`` attacks one sensor a step, so it cannot
                play every plan), or ``"bitmask"`` above 16 sensors.
        """
        from baselines.sparse.policy import SparsePolicy

        return SparsePolicy.from_result(self, action=action)


def result_of(
    problem: SparseProblem,
    pairs: list[Pair],
    solver: str,
    value: float | None = None,
    order: list[Pair] | None = None,
    **fields: Any,
) -> SparseResult:
    """The :class:`SparseResult` of attacking ``pairs`` on ``problem``.

    Args:
        problem: The instance solved (its horizon, number of sensors and objective).
        pairs: The attack set, ``(step, sensor)`` pairs.
        solver: The solver's name.
        value: Φ of ``pairs`` when the solver has it; None: recomputed by
            :meth:`SparseProblem.evaluate`.
        order: The pairs in pick order, where the solver has one.
        **fields: The other :class:`SparseResult` fields (``evaluations``, ``upper_bound``, …).

    Returns:
        The result.
    """
    return SparseResult(
        value=problem.evaluate(pairs) if value is None else value,
        attacks=tuple(pairs),
        solver=solver,
        horizon=problem.horizon,
        num_sensors=problem.M,
        objective=problem.objective,
        order=None if order is None else tuple(order),
        **fields,
    )
