"""The unaware filter: it keeps its nominal gains and incorporates every biased measurement."""

from __future__ import annotations

from typing import Any

from fdia_env.attacks.base import AttackEffect, bit_array
from fdia_env.backend import NUMPY
from fdia_env.defenses.base import DefenseModel, FilterInput
from fdia_env.episode import EpisodeSpec
from fdia_env.systems import LinearSystem


class UnawareFilter(DefenseModel):
    """Passive defender: uses every sensor with gains computed from R (docs/math.md §2.1).

    The injected bias covariance reaches the filter in full; the actual error covariance then
    follows the Joseph form ``M = (I − W H) M⁻ (I − W H)' + W (R + Σ) W'``.
    """

    name = "unaware"
    passive = True
    batch_backends = ("numpy", "torch")

    def bind(self, system: LinearSystem, spec: EpisodeSpec) -> None:
        """Nothing to build: the model has no action."""
        self._all = (1 << system.M) - 1
        self._M = system.M

    def apply(self, action: Any, effect: AttackEffect) -> FilterInput:
        """Every sensor is used; the bias leaks through."""
        return FilterInput(used=self._all, leaked_sigma=effect.sigma)

    def batch_apply(self, actions, attacked, sigma):
        """Every sensor; the whole bias leaks (torch: sensor sets as (B, M) boolean masks)."""
        xp = self.xp
        B = attacked.shape[0]
        present = None if sigma is None else xp.ones(B, dtype=xp.bool)
        if xp is not NUMPY:
            return xp.ones((B, self._M), dtype=xp.bool), sigma, present, False
        return bit_array([self._all] * B, self._M), sigma, present, False
