"""Sensor selection: the defender picks the non-empty subset of sensors its filter uses."""

from __future__ import annotations

from typing import Any

import numpy as np

from fdia_env.attacks.base import AttackEffect, bits_to_mask
from fdia_env.attacks.subsets import SubsetChoice
from fdia_env.defenses.base import DefenseModel, FilterInput
from fdia_env.episode import EpisodeSpec
from fdia_env.systems import LinearSystem


class SensorSelection(SubsetChoice, DefenseModel):
    """Choose the subset D the filter uses; biases reach it only through attacked sensors in D.

    Each round is the one-shot game of docs/math.md §5: the filter has been running on D and is
    in its steady state when the attack comes, so the payoff is ``tr(P_D + W_D Σ_{A∩D} W_D')``.

    Action: ``Discrete(2**M − 1)`` (subsets by size then lexicographic); with
    ``max_subset_size=k`` only the subsets that leave out at most k sensors (sizes M − k..M), in
    the same order. Features: the attacker's last subset as a 0/1 indicator per sensor.
    """

    name = "sensor_selection"
    passive = False

    def __init__(self, max_subset_size: int | None = None) -> None:
        self._k = max_subset_size

    def bind(self, system: LinearSystem, spec: EpisodeSpec) -> None:
        """Build the action space (subsets leaving out at most ``max_subset_size`` sensors)."""
        self.bind_subsets(system.M, self._k, "defender")
        self._row_sensor = system.row_sensor

    def apply(self, action: Any, effect: AttackEffect) -> FilterInput:
        """Use subset ``action``; the bias on attacked sensors outside it is not seen."""
        j = self.last = self.subset_index(action, "defender")
        used = self.bits[j]
        leak = None
        if effect.sigma is not None and used & effect.attacked:
            rows = bits_to_mask(used, self.M)[self._row_sensor]
            leak = effect.sigma * np.outer(rows, rows)  # Σ restricted to A ∩ D
        return FilterInput(used=used, leaked_sigma=leak, steady=True)

    # --- batched (see DefenseModel) --------------------------------------------------------
    def batch_reset(self, batch: int, where: Any = None) -> None:
        """Forget the last round of the members ``where``; build the row masks once."""
        super().batch_reset(batch, where)
        if where is None:
            self._row_masks = self.xp.asarray(self._masks_np[:, self._row_sensor].astype(float))

    def batch_apply(self, actions, attacked, sigma):
        """Each member's subset; Σ restricted to A ∩ D leaks; every round restarts steady."""
        xp = self.xp
        j = xp.astype(actions, xp.int64)  # checked by the vector env
        self.b_last = j
        rows = self._row_masks[j]
        used = self._bits_arr[j]
        if sigma is None:
            return used, None, None, True
        leak = sigma * rows[:, :, None] * rows[:, None, :]
        return used, leak, (used & attacked) != 0, True
