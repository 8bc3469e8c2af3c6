"""Sensor selection: the defender picks the non-empty subset of sensors its filter uses."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from fdia_env.attacks.base import AttackEffect, as_index, as_index_array, bits_to_mask
from fdia_env.attacks.subsets import subset_bits, subsets
from fdia_env.defenses.base import DefenseModel, FilterInput
from fdia_env.episode import EpisodeSpec
from fdia_env.systems import LinearSystem


class SensorSelection(DefenseModel):
    """Choose the subset D the filter uses; biases reach it only through attacked sensors in D.

    Each round is the one-shot game of MATH.md §5: the filter has been running on D and is in its
    steady state when the attack comes, so the payoff is ``tr(P_D + W_D Σ_{A∩D} W_D')``.

    Action: ``Discrete(2**M − 1)`` (subsets by size then lexicographic). Features: the
    attacker's last subset as a 0/1 indicator per sensor.
    """

    name = "sensor_selection"
    passive = False

    def bind(self, system: LinearSystem, spec: EpisodeSpec) -> None:
        """Build the action space."""
        self.M = system.M
        self.subsets = subsets(system.M)
        self.bits = subset_bits(system.M)
        self._row_sensor = system.row_sensor
        self.action_space = spaces.Discrete(len(self.subsets))
        self.feature_low = np.zeros(system.M, dtype=np.float32)
        self.feature_high = np.ones(system.M, dtype=np.float32)
        self.opponent_last: tuple[int, ...] = ()
        self.last = 0

    def reset(self) -> None:
        """Forget the last round."""
        self.opponent_last = ()

    @property
    def last_subset(self) -> tuple[int, ...]:
        """The subset chosen in the last step (0-based sensors)."""
        return self.subsets[self.last]

    def observe_opponent(self, other: Any) -> None:
        """Remember the attacker's last subset for the next observation."""
        self.opponent_last = getattr(other, "last_subset", ())

    def features(self) -> list[float]:
        """The attacker's last subset as indicators."""
        return [1.0 if i in self.opponent_last else 0.0 for i in range(self.M)]

    def apply(self, action: Any, effect: AttackEffect) -> FilterInput:
        """Use subset ``action``; the bias on attacked sensors outside it is not seen."""
        j = as_index(action)
        if j is None or not 0 <= j < len(self.subsets):
            raise ValueError(
                f"defender action must be an integer in [0, {len(self.subsets)}) (a subset index), "
                f"got {action!r}"
            )
        self.last = j
        used = self.bits[j]
        leak = None
        if effect.sigma is not None and used & effect.attacked:
            rows = bits_to_mask(used, self.M)[self._row_sensor]
            leak = effect.sigma * np.outer(rows, rows)  # Σ restricted to A ∩ D
        return FilterInput(used=used, leaked_sigma=leak, steady=True)

    # --- batched (see DefenseModel) --------------------------------------------------------
    def batch_reset(self, batch: int, where: np.ndarray | None = None) -> None:
        """Forget the last round of the members ``where``."""
        if where is None:
            self._batch = batch
            self.b_last = np.zeros(batch, dtype=np.int64)
            self.b_opponent = np.zeros((batch, self.M))
            self._bits_arr = np.array(self.bits, dtype=np.int64)
            self._masks = np.array([[i in s for i in range(self.M)] for s in self.subsets])
            self._row_masks = np.array(
                [[(b >> int(i)) & 1 for i in self._row_sensor] for b in self.bits], dtype=float
            )
        else:
            self.b_opponent[where] = 0.0

    def batch_observe_opponent(self, other: Any) -> None:
        """Remember every member's opponent subset (same subset order on both sides)."""
        self.b_opponent = self._masks[other.b_last].astype(float)

    def batch_features(self) -> np.ndarray:
        """(B, M) the attacker's last subsets as indicators."""
        return self.b_opponent

    def batch_apply(self, actions, attacked, sigma):
        """Each member's subset; Σ restricted to A ∩ D leaks; every round restarts steady."""
        j = as_index_array(actions, len(self.subsets), "defender", "subset indices")
        self.b_last = j
        rows = self._row_masks[j]
        used = self._bits_arr[j]
        if sigma is None:
            return used, None, None, True
        leak = sigma * rows[:, :, None] * rows[:, None, :]
        return used, leak, (used & attacked) != 0, True
