"""The unaware filter: it keeps its nominal gains and incorporates every biased measurement."""

from __future__ import annotations

from fdia_env.attacks.base import same_sensors
from fdia_env.defenses.base import DefenseModel
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

    def batch_apply(self, actions, attacked, sigma):
        """Every sensor; the whole bias leaks."""
        xp = self.xp
        present = None if sigma is None else xp.ones(self._batch, dtype=xp.bool)
        return same_sensors(xp, self._batch, self._all, self._M), sigma, present, False
