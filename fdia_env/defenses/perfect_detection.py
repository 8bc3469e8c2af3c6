"""Perfect detection: every attacked measurement is detected and dropped (docs/math.md §4)."""

from __future__ import annotations

from typing import Any

from fdia_env.attacks.base import AttackEffect
from fdia_env.defenses.base import DefenseModel, FilterInput
from fdia_env.episode import EpisodeSpec
from fdia_env.systems import LinearSystem


class PerfectDetection(DefenseModel):
    """Passive defender that drops exactly the attacked measurements; no bias gets through."""

    name = "perfect_detection"
    passive = True
    batch_backends = ("numpy", "torch")

    def bind(self, system: LinearSystem, spec: EpisodeSpec) -> None:
        """Nothing to build: the model has no action."""
        self._all = (1 << system.M) - 1

    def apply(self, action: Any, effect: AttackEffect) -> FilterInput:
        """Use every sensor that was not attacked."""
        return FilterInput(used=self._all & ~effect.attacked)

    def batch_apply(self, actions, attacked, sigma):
        """Every un-attacked sensor, no leak (bitmasks, or (B, M) boolean masks)."""
        if attacked.ndim == 2:
            return ~attacked, None, None, False
        return self._all & ~attacked, None, None, False
