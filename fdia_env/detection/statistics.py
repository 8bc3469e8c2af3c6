"""The table of detector statistics: every place that names or computes one reads it.

A statistic is a quadratic form ``y' A y`` of the innovation ``y = z − H x̂⁻`` (docs/math.md
§3); an entry gives its matrix ``A`` from the inverses of the innovation covariances under H0
(``Pzz0⁻¹``) and under the attack model H1 (``Pzz1⁻¹``), and the default scale of the detection
game's threshold action. Read by the env's :class:`~fdia_env.defenses.ThresholdDetector`
(names, threshold scale), the one detection step (the matrix; single and vector env), and the
baselines' :class:`~baselines.detection.Detector`.

Adding a statistic is one :class:`Statistic` in :data:`STATISTICS` (its matrix written with
array operations that run on both backends, numpy and torch).

>>> import numpy as np
>>> list(STATISTICS)
['chi2', 'quadratic']
>>> STATISTICS["quadratic"].matrix(np.eye(2), 0.5 * np.eye(2))
array([[0.5, 0. ],
       [0. , 0.5]])
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from fdia_env.kalman import sym


@dataclass(frozen=True)
class Statistic:
    """One test statistic ``y' A y`` of the innovation.

    Attributes:
        name: The name the env and the baselines take (``statistic=...``).
        formula: ``A`` in words, for the docs and messages.
        matrix: ``(Pzz0_inv, Pzz1_inv) -> A``: (..., nz, nz) arrays of either backend.
        scale: ``nz -> s``, the default threshold scale of the detection game's action
            (``τ = s (1 + a) / (1 − a)``): where the statistic under H0 is of order one.
    """

    name: str
    formula: str
    matrix: Callable[[Any, Any], Any]
    scale: Callable[[int], float]


STATISTICS = MappingProxyType(
    {
        entry.name: entry
        for entry in (
            Statistic(
                "chi2",
                "Pzz0⁻¹ (the normalised innovation squared; its mean under H0 is nz)",
                lambda Pzz0_inv, Pzz1_inv: Pzz0_inv,
                lambda nz: float(nz),
            ),
            Statistic(
                "quadratic",
                "Pzz0⁻¹ − Pzz1⁻¹ (the optimal Bayesian statistic)",
                lambda Pzz0_inv, Pzz1_inv: sym(Pzz0_inv - Pzz1_inv),
                lambda nz: 1.0,
            ),
        )
    }
)
"""Statistic name → :class:`Statistic`."""
