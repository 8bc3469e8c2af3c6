"""Sparse-attack instances beyond the literature's, for branch and bound and its benchmarks.

:func:`mixed_tracking` is the literature's 1-D target-tracking model (docs/math.md §1) with many
sensors of two kinds, alternating: position+velocity sensors (``H = I₂``, random standard
deviations in [0.2, 1] and correlation in [−0.8, 0.8]) and position sensors (σ in [0.1, 1]).
Their information matrices are not proportional, so neither DP nor the allocation bound is exact
and branch and bound has to search.

:func:`dc_grid14` (the DC power-flow model of the IEEE 14-bus network, built without pandapower)
lives in :mod:`fdia_env.systems.grid.dc14` and is re-exported here, where the benchmarks and
tests of branch and bound have always imported it; its 50-meter model is also the
``dc-ieee14-50`` scenario preset of :mod:`fdia_env.scenarios`.
"""

from __future__ import annotations

import numpy as np

from fdia_env._validation import check_int, check_positive
from fdia_env.systems import LinearSystem, position_sensor, pv_sensor, tracking_system
from fdia_env.systems.grid.dc14 import dc_grid14

__all__ = ["dc_grid14", "mixed_tracking"]


def mixed_tracking(sensors: int = 14, seed: int = 0, sigma_v: float = 0.1) -> LinearSystem:
    """Target tracking with ``sensors`` sensors, alternately position+velocity and position.

    Args:
        sensors: Number of sensors M >= 1 (even indices position+velocity, odd position).
        seed: Seed of the random noise levels.
        sigma_v: Process noise standard deviation of the tracking model.

    Raises:
        ValueError: For ``sensors < 1`` or a non-positive ``sigma_v``.
    """
    sensors = check_int("sensors", sensors, minimum=1)
    sigma_v = check_positive("sigma_v", sigma_v)
    rng = np.random.default_rng(seed)
    out = [
        pv_sensor(*rng.uniform(0.2, 1.0, 2), rng.uniform(-0.8, 0.8), name=f"z{i + 1}")
        if i % 2 == 0
        else position_sensor(rng.uniform(0.1, 1.0), name=f"z{i + 1}")
        for i in range(sensors)
    ]
    return tracking_system(sigma_v, sensors=out, name=f"mixed-tracking-{sensors}")
