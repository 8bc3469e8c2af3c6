"""The table of power-grid cases: every place that lists grid cases reads it.

One :class:`GridCase` per pandapower case the suite knows. Derived from it:

- :data:`fdia_env.systems.grid.network.CASES` (the names :func:`~fdia_env.systems.grid.dc_network`
  accepts);
- the ``grid-<case>`` scenario presets of :mod:`fdia_env.scenarios` (the cases with a
  :class:`GridPreset`);
- the cases of :class:`fdia_env.envs.grid_family.GridFamily` (``family=True``) and their meter
  counts, known without building the case (pandapower is slow to import);
- :func:`fdia_env.systems.grid.dc14.dc_grid14`, the IEEE 14-bus DC model built without
  pandapower from :data:`IEEE14_BRANCHES`.

Adding a grid case is one :class:`GridCase` in :data:`GRID_CASES` (its counts are checked
against pandapower by ``tests/test_grid.py``).

>>> GRID_CASES["ieee14"].meters, [c.name for c in GRID_CASES.values() if c.preset]
(34, ['ieee14', 'ieee30', 'ieee57', 'ieee118'])
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType


@dataclass(frozen=True)
class GridPreset:
    """The experiment defaults of a case's ``grid-<case>`` scenario preset.

    Attributes:
        budget: Sparsity budget c of the sparse attack.
        horizon: Attack window N.
        max_subset_size: The sensor game's k (attacker picks, defender leaves out at most k).
    """

    budget: int
    horizon: int
    max_subset_size: int


@dataclass(frozen=True)
class GridCase:
    """One pandapower case in the DC model (one meter per bus injection and per branch flow).

    Attributes:
        name: Case name (``"ieee14"``): ``dc_network(name)``, ``grid_system(name)``.
        pandapower: The ``pandapower.networks`` function that builds it (``"case14"``).
        buses: Buses Nb (the state holds the Nb − 1 angles other than the slack's).
        branches: In-service branches L (lines and transformers).
        preset: Defaults of its ``grid-<name>`` scenario, or None for no preset.
        family: Whether :class:`~fdia_env.envs.grid_family.GridFamily` draws systems of it.
    """

    name: str
    pandapower: str
    buses: int
    branches: int
    preset: GridPreset | None = None
    family: bool = False

    @property
    def meters(self) -> int:
        """Meters M of its grid system: an injection at every bus, a flow at every branch."""
        return self.buses + self.branches

    @property
    def states(self) -> int:
        """State dimension n: the bus angles other than the slack's."""
        return self.buses - 1


GRID_CASES = MappingProxyType(
    {
        case.name: case
        for case in (
            GridCase("ieee14", "case14", 14, 20, GridPreset(6, 6, 2), family=True),
            GridCase("ieee30", "case30", 30, 41, GridPreset(6, 4, 1), family=True),
            GridCase("ieee57", "case57", 57, 80, GridPreset(6, 3, 1)),
            GridCase("ieee118", "case118", 118, 186, GridPreset(6, 3, 1)),
            GridCase("ieee300", "case300", 300, 411),
        )
    }
)
"""Case name → :class:`GridCase`."""

# The IEEE 14-bus network without pandapower: (from bus, to bus, x in per unit on 100 MVA),
# buses 1-based, in the standard case's branch order (lines and transformers alike, no taps).
IEEE14_BRANCHES: tuple[tuple[int, int, float], ...] = (
    (1, 2, 0.05917),
    (1, 5, 0.22304),
    (2, 3, 0.19797),
    (2, 4, 0.17632),
    (2, 5, 0.17388),
    (3, 4, 0.17103),
    (4, 5, 0.04211),
    (4, 7, 0.20912),
    (4, 9, 0.55618),
    (5, 6, 0.25202),
    (6, 11, 0.19890),
    (6, 12, 0.25581),
    (6, 13, 0.13027),
    (7, 8, 0.17615),
    (7, 9, 0.11001),
    (9, 10, 0.08450),
    (9, 14, 0.27038),
    (10, 11, 0.19207),
    (12, 13, 0.19988),
    (13, 14, 0.34802),
)
