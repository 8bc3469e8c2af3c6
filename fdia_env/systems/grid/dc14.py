"""The IEEE 14-bus DC model built without pandapower (docs/math.md §7).

:func:`dc_grid14` builds the DC power-flow model of the IEEE 14-bus network from the 20 branch
reactances of the standard case (per unit on 100 MVA; lines and transformers alike, as in the DC
power flow), ``IEEE14_BRANCHES`` of the table of grid cases (:mod:`fdia_env.systems.grid.cases`).
The state is the 13 voltage angles of buses 2..14 (bus 1 is the reference), moving as a random
walk ``θ[k+1] = θ[k] + v[k]``, ``v ~ N(0, q I)``. Meters (each one a sensor, one scalar
measurement in per unit):

- bus injections ``P_i = Σ_j b_ij (θ_i − θ_j)`` at every bus (14 meters), then
- branch flows ``P_ij = b_ij (θ_i − θ_j)`` at the from end of every branch (20 meters), then
- the same flows metered at the to end (20 more),

so ``meters = 14`` gives the injections only and ``meters = 50`` adds 20 + 16 flow meters (the
``dc-ieee14-50`` scenario preset of :mod:`fdia_env.scenarios`). It needs no ``[grid]`` extra.

>>> system = dc_grid14(50)
>>> system.name, system.M, system.n
('dc-ieee14-50', 50, 13)
"""

from __future__ import annotations

import numpy as np

from fdia_env._validation import check_int, check_positive
from fdia_env.systems.grid.cases import IEEE14_BRANCHES
from fdia_env.systems.system import LinearSystem, Sensor


def dc_grid14(meters: int = 14, q: float = 1e-4, sigma: float = 0.02) -> LinearSystem:
    """The IEEE 14-bus DC model with ``meters`` scalar meters (module docstring).

    Args:
        meters: Number of meters, 1..54 (injections first, then from-end, then to-end flows).
        q: Random-walk variance of each angle per step (rad²).
        sigma: Standard deviation of every meter's noise (per unit).

    Raises:
        ValueError: For ``meters`` outside 1..54 or a non-positive ``q`` or ``sigma``.
    """
    meters = check_int("meters", meters, minimum=1, maximum=54)
    q = check_positive("q", q)
    sigma = check_positive("sigma", sigma)
    B = 14
    A = np.zeros((len(IEEE14_BRANCHES), B))  # branch-bus incidence, scaled by b_ij
    for row, (i, j, x) in enumerate(IEEE14_BRANCHES):
        A[row, i - 1] = 1.0 / x
        A[row, j - 1] = -1.0 / x
    incidence = np.zeros((len(IEEE14_BRANCHES), B))
    for row, (i, j, _) in enumerate(IEEE14_BRANCHES):
        incidence[row, i - 1], incidence[row, j - 1] = 1.0, -1.0
    injections = incidence.T @ A  # (B, B) the susceptance Laplacian
    rows = np.vstack([injections, A, -A])[:meters, 1:]  # drop the reference bus column
    sensors = tuple(
        Sensor(H=rows[m : m + 1], R=np.array([[sigma**2]]), name=f"m{m + 1}") for m in range(meters)
    )
    return LinearSystem(
        F=np.eye(B - 1), Q=q * np.eye(B - 1), sensors=sensors, name=f"dc-ieee14-{meters}"
    )
