"""Random power-grid systems for :class:`fdia_env.envs.system_family.SystemFamilyEnv`.

:class:`GridFamily` draws DC dynamic state estimation systems of one pandapower case (the
``grid-ieee14`` preset's model by default: n = 13 bus angles, M = 34 scalar meters, see
:func:`fdia_env.systems.grid_system`) with

- **random loads**: every load of the case scaled by its own factor ``U(load_scale)``, and the
  DC power flow solved again for the new angles, which become the prior mean ``x0`` (the slack
  bus absorbs the change; the generators keep their set points);
- **random meter noise**: every meter's σ scaled by its own factor, log-uniform on
  ``noise_scale``, so ``R_j = (f_j σ_j)²``.

What changes the attack problem. In the DC model the measurement matrix ``H`` depends on the
network's reactances only, not on the loads, and the sparse attack's objective Φ(P) depends on
the covariances only (``F, Q, H, R``): **the random loads move only the prior mean, which the
objective, the optimum and the env's observation do not see.** They are part of the family so
that the drawn systems are complete (their ``x0`` is the DC power flow of their own loads), not
because they make the problem harder. The random meter noise is what changes the filter's
steady-state covariance and the optimal attack from system to system.

Systems are indexed by a *system seed* ``k``: ``family.system(k)`` is
``family.draw(numpy.random.default_rng(k))`` (load factors first, then noise factors).

>>> fam = GridFamily()
>>> s = fam.system(0)
>>> s.n, s.M, fam.state_size, fam.num_sensors
(13, 34, 13, 34)
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from fdia_env._validation import check_choice, check_int
from fdia_env.envs.family import NumberedFamily, check_range
from fdia_env.systems import LinearSystem
from fdia_env.systems.grid.cases import GRID_CASES
from fdia_env.systems.system import Sensor

FAMILY_CASES = tuple(case.name for case in GRID_CASES.values() if case.family)
"""Cases a :class:`GridFamily` accepts (``family=True`` in the table of grid cases)."""


@dataclass(frozen=True, eq=False)
class _Base:
    """The case's nominal system and what a load change does to its angles."""

    system: LinearSystem
    load_bus: np.ndarray  # (L,) position in the state of each load's bus, -1 at the slack
    load_pu: np.ndarray  # (L,) nominal load, per unit
    B_inv: np.ndarray  # (n, n) inverse of the reduced bus susceptance matrix


@functools.lru_cache(maxsize=4)
def _base(case: str) -> _Base:
    """Build the nominal system of ``case`` once (pandapower is slow to import)."""
    from fdia_env.systems.grid.measurements import grid_model
    from fdia_env.systems.grid.network import CASES, import_pandapower

    model = grid_model(case)
    net_mod = import_pandapower().networks
    net = getattr(net_mod, CASES[case])()
    network = model.network
    keep = np.arange(network.n_buses) != network.slack
    state_pos = {int(b): j for j, b in enumerate(network.buses[keep])}
    loads = net.load[net.load.in_service]
    load_bus = np.array([state_pos.get(int(b), -1) for b in loads.bus])
    load_pu = loads.p_mw.to_numpy(float) / network.base_mva
    Bbus = network.A.T @ (network.b[:, None] * network.A)
    B_inv = np.linalg.inv(Bbus[np.ix_(keep, keep)])
    return _Base(model.system, load_bus, load_pu, B_inv)


@dataclass(frozen=True)
class GridFamily(NumberedFamily):
    """Random loads and meter noise on one pandapower case (module docstring).

    Attributes:
        case: ``"ieee14"`` (default; 34 meters) or ``"ieee30"`` (71 meters).
        load_scale: (low, high): each load's factor is ``U(low, high)``, 0 < low <= high.
        noise_scale: (low, high): each meter's σ factor is log-uniform on it, 0 < low <= high.
        budget: Sparsity budget c of the attack, 0..M·N.
        horizon: Attack window N >= 1.
    """

    case: str = "ieee14"
    load_scale: tuple[float, float] = (0.5, 1.5)
    noise_scale: tuple[float, float] = (0.5, 2.0)
    budget: int = 3
    horizon: int = 2

    def __post_init__(self) -> None:
        check_choice("case", self.case, FAMILY_CASES)
        object.__setattr__(self, "load_scale", check_range("load_scale", self.load_scale))
        object.__setattr__(self, "noise_scale", check_range("noise_scale", self.noise_scale))
        check_int("horizon", self.horizon, minimum=1, maximum=10_000)
        M = GRID_CASES[self.case].meters  # known without building the case
        check_int("budget", self.budget, minimum=0, maximum=M * self.horizon)

    @property
    def num_sensors(self) -> int:
        """Sensors per system M (one per meter)."""
        return _base(self.case).system.M

    @property
    def state_size(self) -> int:
        """State dimension n (buses − 1 angles)."""
        return _base(self.case).system.n

    def draw(self, rng: np.random.Generator) -> LinearSystem:
        """One system, drawn with ``rng`` (load factors first, then meter noise factors)."""
        if not isinstance(rng, np.random.Generator):
            raise ValueError(f"rng must be a numpy Generator, got {type(rng).__name__}")
        base = _base(self.case)
        sys = base.system
        load = rng.uniform(*self.load_scale, size=base.load_pu.size)
        lo, hi = self.noise_scale
        noise = np.exp(rng.uniform(math.log(lo), math.log(hi), size=sys.M))
        return self.build(load, noise)

    def build(self, load_factors: np.ndarray, noise_factors: np.ndarray) -> LinearSystem:
        """The system with the given per-load and per-meter factors (what ``draw`` draws)."""
        base = _base(self.case)
        sys = base.system
        load_factors = np.asarray(load_factors, dtype=float)
        noise_factors = np.asarray(noise_factors, dtype=float)
        if load_factors.shape != base.load_pu.shape or not np.all(load_factors >= 0):
            raise ValueError(
                f"load_factors must be {base.load_pu.size} numbers >= 0, got {load_factors!r}"
            )
        if noise_factors.shape != (sys.M,) or not np.all(noise_factors > 0):
            raise ValueError(f"noise_factors must be {sys.M} numbers > 0, got {noise_factors!r}")
        # DC power flow is linear: more load at a bus lowers its injection by that much
        delta = np.zeros(sys.n)
        at = base.load_bus >= 0
        np.add.at(delta, base.load_bus[at], -(load_factors[at] - 1.0) * base.load_pu[at])
        x0 = sys.x0 + base.B_inv @ delta
        sensors = tuple(
            Sensor(H=s.H, R=s.R * f**2, name=s.name)
            for s, f in zip(sys.sensors, noise_factors, strict=True)
        )
        return LinearSystem(
            F=sys.F, Q=sys.Q, sensors=sensors, x0=x0, P0=sys.P0, name=f"grid-{self.case}-family"
        )

    def describe(self) -> str:
        """The family in words, for its scenarios' descriptions."""
        return f"grid family ({self.case})"
