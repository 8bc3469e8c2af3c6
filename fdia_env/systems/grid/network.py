"""The DC model of a transmission network, read from pandapower (docs/math.md §7).

pandapower is an optional dependency (``pip install fdia-env[grid]``): it is imported inside
:func:`dc_network`, never at module import, so ``import fdia_env`` does not need it.

Branch model. The susceptances are pandapower's own DC branch model (the one ``rundcpp`` solves,
MATPOWER's ``makeBdc``): a branch from bus f to bus t with series reactance ``x`` (per unit on
``net.sn_mva``), off-nominal tap ratio ``τ`` (1 for lines) and phase shift ``φ`` carries

    P_ft = b (θ_f − θ_t − φ),    b = 1 / (x τ)

from f to t (−P_ft at the t end). Two things here go beyond docs/math.md §7, which states the model
with ``b = 1/x`` and no taps: pandapower's DC model divides by the tap ratio (the IEEE 14-, 57-,
118- and 300-bus cases have off-nominal transformers, e.g. τ = 0.978, 0.969, 0.932 in case14),
and a phase-shifting transformer adds the constant ``−b φ`` to the flow. Both are kept, so that
the measurement model reproduces ``rundcpp`` exactly; the phase-shift term is a known constant
(``offset``) that does not change any covariance. None of the shipped cases 14–300 has a nonzero
shift in pandapower 3.5. Resistance, line charging and shunts play no part in the branch model
(shunt conductance only changes what the loads are, not how angles map to flows).
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fdia_env.systems.grid.cases import GRID_CASES

CASES: dict[str, str] = {case.name: case.pandapower for case in GRID_CASES.values()}
"""Case names accepted by :func:`dc_network` -> the ``pandapower.networks`` function (from
the table of grid cases, :data:`fdia_env.systems.grid.cases.GRID_CASES`)."""

EXTRA_HINT = 'pandapower is needed for the power-grid systems: pip install "fdia-env[grid]"'


def import_pandapower() -> Any:
    """``pandapower``, or an ImportError that names the ``[grid]`` extra."""
    try:
        import pandapower
        import pandapower.networks
    except ImportError as exc:  # pragma: no cover - the test environment has the extra
        raise ImportError(EXTRA_HINT) from exc
    return pandapower


@dataclass(frozen=True, eq=False)
class DCNetwork:
    """A connected network in the DC approximation.

    Attributes:
        name: Case name (``"ieee14"``, ...) or ``"custom"``.
        base_mva: The per-unit base power (``net.sn_mva``).
        buses: (Nb,) pandapower bus indices, one per electrical bus of the model.
        slack: Position in ``buses`` of the angle reference (the case's slack bus).
        branches: (L,) labels ``(table, index)`` of the in-service branches, e.g. ``("line", 3)``,
            ``("trafo", 0)``, in pandapower's order (lines, then transformers, then the rest).
        from_bus, to_bus: (L,) positions in ``buses`` of each branch's from (hv) and to (lv) end.
        x: (L,) series reactance, per unit.
        tap: (L,) off-nominal tap ratio τ (1 for lines).
        shift: (L,) phase shift φ, radians.
        theta: (Nb,) the angles of pandapower's DC power flow on the case's loads, radians,
            relative to the slack bus (the prior mean of the grid systems).

    Derived:
        b: (L,) branch susceptance ``1 / (x τ)``.
        A: (L, Nb) branch–bus incidence (+1 at the from end, −1 at the to end).
    """

    name: str
    base_mva: float
    buses: np.ndarray
    slack: int
    branches: tuple[tuple[str, int], ...]
    from_bus: np.ndarray
    to_bus: np.ndarray
    x: np.ndarray
    tap: np.ndarray
    shift: np.ndarray
    theta: np.ndarray
    b: np.ndarray = field(init=False, repr=False)
    A: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        L, Nb = len(self.branches), len(self.buses)
        if L == 0:
            raise ValueError(f"case {self.name!r} has no in-service lines or transformers")
        bad = ~np.isfinite(self.x) | (self.x == 0.0) | ~np.isfinite(self.tap) | (self.tap == 0.0)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise ValueError(
                f"branch {self.branches[i]} of case {self.name!r} has reactance {self.x[i]} and "
                f"tap {self.tap[i]}: the DC model needs finite, nonzero x and tap"
            )
        A = np.zeros((L, Nb))
        A[np.arange(L), self.from_bus] = 1.0
        A[np.arange(L), self.to_bus] = -1.0
        for name, value in (("b", 1.0 / (self.x * self.tap)), ("A", A)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)

    @property
    def n_buses(self) -> int:
        """Number of buses Nb (the state has Nb − 1 angles)."""
        return len(self.buses)

    def flows(self, theta: np.ndarray) -> np.ndarray:
        """(..., L) from-end branch flows ``b (θ_f − θ_t − φ)`` for (..., Nb) angles, per unit."""
        return (np.asarray(theta) @ self.A.T - self.shift) * self.b

    def injections(self, theta: np.ndarray) -> np.ndarray:
        """(..., Nb) net injections into the network ``A' P_f``, per unit."""
        return self.flows(theta) @ self.A


def _case_net(case: Any) -> tuple[str, Any]:
    pp = import_pandapower()
    if isinstance(case, str):
        if case not in CASES:
            raise ValueError(
                f"case must be one of {sorted(CASES)} or a pandapower network, got {case!r}"
            )
        return case, getattr(pp.networks, CASES[case])()
    if type(case).__name__ == "pandapowerNet":
        return "custom", copy.deepcopy(case)
    raise ValueError(
        f"case must be one of {sorted(CASES)} or a pandapower network, got {type(case).__name__}"
    )


def _check_connected(name: str, net: Any) -> None:
    import pandapower.topology as top

    graph = top.create_nxgraph(net, respect_switches=True, include_out_of_service=False)
    in_service = set(net.bus.index[net.bus.in_service])
    islands = [c & in_service for c in top.connected_components(graph)]
    islands = [c for c in islands if c]
    if len(islands) > 1:
        small = sorted(min(islands, key=len))
        raise ValueError(
            f"case {name!r} must be one connected network: it has {len(islands)} islands "
            f"(e.g. buses {small[:10]}); remove the island or put it out of service"
        )


def dc_network(case: Any) -> DCNetwork:
    """Read the DC model of ``case`` with pandapower.

    Args:
        case: ``"ieee14"``, ``"ieee30"``, ``"ieee57"``, ``"ieee118"``, ``"ieee300"`` (the cases
            ``pandapower.networks`` ships offline) or a pandapower network (not modified).

    Returns:
        The :class:`DCNetwork`, with the angles of pandapower's DC power flow on the case's loads.

    Raises:
        ImportError: Without pandapower (names the ``[grid]`` extra).
        ValueError: For an unknown case name, a network without lines, with islands, without a
            slack (ext_grid), or whose DC power flow fails.
    """
    pp = import_pandapower()
    name, net = _case_net(case)
    if not (len(net.line) and net.line.in_service.any()) and not (
        len(net.trafo) and net.trafo.in_service.any()
    ):
        raise ValueError(f"case {name!r} has no in-service lines or transformers")
    _check_connected(name, net)
    if not (len(net.ext_grid) and net.ext_grid.in_service.any()):
        raise ValueError(f"case {name!r} needs an in-service ext_grid as the angle reference")
    try:
        pp.rundcpp(net)
    except Exception as exc:  # pandapower raises its own error classes
        raise ValueError(f"pandapower's DC power flow failed on case {name!r}: {exc}") from exc
    from pandapower.pypower.idx_brch import BR_STATUS, BR_X, F_BUS, SHIFT, T_BUS, TAP
    from pandapower.pypower.idx_bus import BUS_I, BUS_TYPE, REF

    ppc = net._ppc
    bus_lookup = net._pd2ppc_lookups["bus"]
    ppc_bus = ppc["bus"]
    live = ppc_bus[:, BUS_TYPE].real != 4  # type 4: out of service
    ppc_ids = ppc_bus[live, BUS_I].real.astype(int)
    position = {int(p): k for k, p in enumerate(ppc_ids)}
    # one pandapower label per electrical bus (the lowest index of buses fused by switches)
    label = {}
    for pp_bus in sorted(net.bus.index[net.bus.in_service]):
        label.setdefault(int(bus_lookup[pp_bus]), int(pp_bus))
    buses = np.array([label[int(p)] for p in ppc_ids])
    ref = np.flatnonzero(ppc_bus[live, BUS_TYPE].real == REF)
    slack = int(ref[0])

    br = ppc["branch"]
    tables = sorted(net._pd2ppc_lookups["branch"].items(), key=lambda kv: kv[1][0])
    labels = []
    for table, (start, stop) in tables:
        index = net[table].index if len(net[table]) == stop - start else range(stop - start)
        labels += [(table, int(i)) for i in index]
    keep = br[: len(labels), BR_STATUS].real > 0
    rows = np.flatnonzero(keep)
    tap = br[rows, TAP].real.copy()
    tap[tap == 0.0] = 1.0  # MATPOWER convention: 0 means a line
    theta = np.deg2rad(net.res_bus.va_degree.loc[buses].to_numpy())
    return DCNetwork(
        name=name,
        base_mva=float(net.sn_mva),
        buses=buses,
        slack=slack,
        branches=tuple(labels[r] for r in rows),
        from_bus=np.array([position[int(f)] for f in br[rows, F_BUS].real]),
        to_bus=np.array([position[int(t)] for t in br[rows, T_BUS].real]),
        x=br[rows, BR_X].real.copy(),
        tap=tap,
        shift=np.deg2rad(br[rows, SHIFT].real),
        theta=theta - theta[slack],
    )
