"""Sensor selection: the defender picks the non-empty subset of sensors its filter uses."""

from __future__ import annotations

from typing import Any

from fdia_env.attacks.subsets import SubsetChoice
from fdia_env.defenses.base import DefenseModel
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

    # --- batched (see DefenseModel) --------------------------------------------------------
    def batch_reset(self, batch: int, where: Any = None) -> None:
        """Forget the last round of the members ``where``; the row masks once per backend."""
        xp = self.xp
        rebuild = where is None and self._b_xp is not xp
        super().batch_reset(batch, where)
        if rebuild:
            self._row_masks = xp.asarray(self._masks_np[:, self._row_sensor].astype(float))

    def batch_apply(self, actions, attacked, sigma):
        """Each member's subset D; Σ restricted to A ∩ D leaks; every round restarts steady."""
        xp = self.xp
        j = xp.astype(actions, xp.int64)  # checked by the env
        self.b_last = j
        used = xp.take(self._bits_arr, j)
        if sigma is None:
            return used, None, None, True
        rows = self._row_masks[j]  # (B, nz) measurement rows of D
        leak = sigma * rows[..., :, None] * rows[..., None, :]
        return used, leak, (used & attacked) != 0, True
