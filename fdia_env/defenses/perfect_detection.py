"""Perfect detection: every attacked measurement is detected and dropped (docs/math.md §4)."""

from __future__ import annotations

from fdia_env.defenses.base import DefenseModel
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

    def batch_apply(self, actions, attacked, sigma):
        """Every un-attacked sensor, no leak (bitmasks, or (B, M) boolean masks on torch)."""
        if getattr(attacked, "ndim", 0) == 2:  # masks (the batch of one's bitmask is an int)
            return ~attacked, None, None, False
        return self._all & ~attacked, None, None, False
