"""Subset attack: the attacker picks a non-empty sensor subset and splits its power by a rule.

The power a² is split over the attacked subset A by one of the literature's rules for scalar
(position) sensors (MATH.md §2.2, §5):

- ``"independent"`` (Prop. 2): all power on the smallest-variance sensor of A;
- ``"dependent"`` (Prop. 3): correlation 1 over A with ``σ_b,i = c_i a / ||c||``,
  ``c_i = (1/σ_i²) / Σ_{j∈A} (1/σ_j²)``.

Both give ``tr Σ_A = a²``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from fdia_env._validation import check_choice, check_positive
from fdia_env.attacks.base import AttackEffect, AttackModel, as_index
from fdia_env.attacks.subsets import subset_bits, subsets
from fdia_env.episode import EpisodeSpec
from fdia_env.systems import LinearSystem

ALLOCATIONS = ("independent", "dependent")
MAX_GAME_SENSORS = 16


def allocation_covariance(
    system: LinearSystem, subset: tuple[int, ...], power: float, allocation: str
) -> np.ndarray:
    """Σ_A over the stacked measurement (nz, nz) for attacked ``subset`` (0-based sensors).

    Raises:
        ValueError: For an empty subset, an unknown rule, or sensors that are not scalar.
    """
    check_choice("allocation", allocation, ALLOCATIONS)
    power = check_positive("power", power)
    if not subset:
        raise ValueError("subset must hold at least one sensor")
    if any(not 0 <= i < system.M for i in subset):
        raise ValueError(f"subset must hold sensor indices in [0, {system.M}), got {subset}")
    if system.nz != system.M:
        raise ValueError(
            "the independent and dependent allocation rules are defined for scalar sensors; "
            f"this system stacks {system.nz} measurements from {system.M} sensors"
        )
    idx = np.array(sorted(subset))
    variances = np.diag(system.R)[idx]
    sigma = np.zeros((system.nz, system.nz))
    if allocation == "independent":
        best = idx[int(np.argmin(variances))]  # first of any ties
        sigma[best, best] = power
        return sigma
    c = (1.0 / variances) / np.sum(1.0 / variances)
    s = c * np.sqrt(power) / np.linalg.norm(c)  # σ_b,i = c_i a / ||c||, correlation 1
    sigma[np.ix_(idx, idx)] = np.outer(s, s)
    return sigma


class SubsetAttack(AttackModel):
    """Attack a non-empty sensor subset with power a² split by ``allocation``.

    Action: ``Discrete(2**M − 1)``, index ``j`` = the j-th subset by size then lexicographic
    (:func:`fdia_env.attacks.subsets.subsets`). Features: the defender's last subset as a 0/1
    indicator per sensor (all zeros before the first round).
    """

    name = "subset"

    def __init__(self, power: float, allocation: str = "independent") -> None:
        self.power = check_positive("power", power)
        self.allocation = check_choice("allocation", allocation, ALLOCATIONS)
        self.last = 0
        self.opponent_last: tuple[int, ...] = ()

    def bind(self, system: LinearSystem, spec: EpisodeSpec) -> None:
        """Precompute every subset's bias covariance."""
        if system.M > MAX_GAME_SENSORS:
            raise ValueError(
                f"the subset action supports at most {MAX_GAME_SENSORS} sensors, got {system.M}"
            )
        self.M = system.M
        self.subsets = subsets(system.M)
        self.bits = subset_bits(system.M)
        self._sigmas: dict[int, np.ndarray] = {}
        self._system = system
        self.action_space = spaces.Discrete(len(self.subsets))
        self.feature_low = np.zeros(system.M, dtype=np.float32)
        self.feature_high = np.ones(system.M, dtype=np.float32)

    def reset(self) -> None:
        """Forget the last round."""
        self.opponent_last = ()

    @property
    def last_subset(self) -> tuple[int, ...]:
        """The subset chosen in the last step (0-based sensors)."""
        return self.subsets[self.last]

    def observe_opponent(self, other: Any) -> None:
        """Remember the defender's last subset for the next observation."""
        self.opponent_last = getattr(other, "last_subset", ())

    def features(self) -> list[float]:
        """The defender's last subset as indicators."""
        return [1.0 if i in self.opponent_last else 0.0 for i in range(self.M)]

    def sigma(self, j: int) -> np.ndarray:
        """Σ of subset index ``j`` (cached)."""
        if j not in self._sigmas:
            self._sigmas[j] = allocation_covariance(
                self._system, self.subsets[j], self.power, self.allocation
            )
        return self._sigmas[j]

    def apply(self, action: Any) -> AttackEffect:
        """Attack subset ``action``."""
        j = as_index(action)
        if j is None or not 0 <= j < len(self.subsets):
            raise ValueError(
                f"attacker action must be an integer in [0, {len(self.subsets)}) (a subset index), "
                f"got {action!r}"
            )
        self.last = j
        return AttackEffect(attacked=self.bits[j], sigma=self.sigma(j))

    def info(self) -> dict[str, Any]:
        """The attacked subset (0-based sensors)."""
        return {"attacked": list(self.subsets[self.last])}
