"""Power-grid DC dynamic state estimation as a :class:`LinearSystem` (docs/math.md §7).

State ``x = θ`` without the slack bus (radians, relative to the slack's angle); measurements, in
per unit of the case's base power:

    flow at the f end of branch (f, t):   P_ft = b (θ_f − θ_t − φ)     (−P_ft at the t end)
    injection at bus i:                   P_i  = Σ_branches at i  ±P     (A' P_f)

so ``z = H x + offset + w`` where ``offset`` holds the phase-shift terms (zero unless the case has
a phase-shifting transformer; a known constant, it changes no covariance and the envs, which only
see the filter's covariances and errors, do not need it). Dynamics: the quasi-steady random walk
``x[k+1] = x[k] + v``, ``v ~ N(0, q I)`` (forecasting-aided state estimation), or your own F, Q.

A *sensor* is what the attacker corrupts as one unit: one meter (``sensors="meter"``) or one
bus's RTU (``sensors="bus"``: the injection meter of the bus and the flow meters at that bus's
end of its branches, stacked as one vector sensor with diagonal R).

Defaults (per unit on 100 MVA, radians): σ_flow = 0.01, σ_injection = 0.02, q = 1e-6 (an angle
drift of 0.057° per step); see :data:`DEFAULT_SIGMA_FLOW` and the grid presets in
:mod:`fdia_env.scenarios` for why these give a nontrivial steady state.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fdia_env._validation import as_matrix, check_choice, check_positive
from fdia_env.systems.grid.network import DCNetwork, dc_network
from fdia_env.systems.system import LinearSystem, Sensor

DEFAULT_SIGMA_FLOW = 0.01
"""Flow meter noise σ, per unit (1 MW on 100 MVA): a typical SCADA flow meter."""
DEFAULT_SIGMA_INJECTION = 0.02
"""Injection meter noise σ, per unit: injections sum several meters, so twice the flow σ."""
DEFAULT_Q = 1e-6
"""Random-walk variance q per step, rad² (σ = 1 mrad): load drift between SCADA scans."""
DEFAULT_P0 = 0.01
"""Prior angle variance, rad² (σ = 0.1 rad around the case's DC power-flow angles)."""

SENSOR_GROUPINGS = ("meter", "bus")
FLOW_ENDS = ("from", "both")


@dataclass(frozen=True)
class Meter:
    """One scalar measurement.

    Attributes:
        kind: ``"injection"`` or ``"flow"``.
        bus: Position (in the network's bus list) of the bus it sits at (the metered end).
        branch: Position of the branch (flows), else -1.
        end: ``"from"`` or ``"to"`` (flows), else ``""``.
    """

    kind: str
    bus: int
    branch: int = -1
    end: str = ""


@dataclass(frozen=True, eq=False)
class GridModel:
    """A grid system and the network and meters it was built from.

    Attributes:
        network: The :class:`DCNetwork`.
        meters: The meters in the order of the system's stacked measurement rows.
        H_full: (nz, Nb) measurement matrix over every bus angle (slack column included).
        offset: (nz,) constant phase-shift terms of the measurements.
        state_buses: (n,) pandapower indices of the buses whose angles are the state.
        build: Zero-argument function that builds the system (called once, by ``system``).

    ``system`` (built on first access, then cached) is the :class:`LinearSystem`; ``system.H``
    is ``H_full`` without the slack column. Building it costs O(M n²) memory (one information
    matrix per sensor), so the measurement model alone (``measure``) does not build it.
    """

    network: DCNetwork
    meters: tuple[Meter, ...]
    H_full: np.ndarray
    offset: np.ndarray
    state_buses: np.ndarray
    build: Callable[[], LinearSystem] = field(repr=False)

    @functools.cached_property
    def system(self) -> LinearSystem:
        """The :class:`LinearSystem` (built once)."""
        return self.build()

    def measure(self, theta: np.ndarray) -> np.ndarray:
        """Noise-free measurements ``H_full θ + offset`` for (..., Nb) bus angles, per unit."""
        return np.asarray(theta) @ self.H_full.T + self.offset


def _bus_positions(network: DCNetwork, injections: Any) -> list[int]:
    if isinstance(injections, str):
        check_choice("injections", injections, ("all", "none"))
        return list(range(network.n_buses)) if injections == "all" else []
    where = {int(b): k for k, b in enumerate(network.buses)}
    out = []
    for bus in injections:
        if isinstance(bus, bool) or not isinstance(bus, (int, np.integer)) or int(bus) not in where:
            raise ValueError(
                f"injections must be 'all', 'none' or pandapower bus indices of case "
                f"{network.name!r} (in service: {sorted(where)[:5]}..{max(where)}), got {bus!r}"
            )
        out.append(where[int(bus)])
    return out


def _branch_positions(network: DCNetwork, flows: Any) -> list[int]:
    if isinstance(flows, str):
        check_choice("flows", flows, ("all", "none"))
        return list(range(len(network.branches))) if flows == "all" else []
    where = {label: k for k, label in enumerate(network.branches)}
    tables = sorted({t for t, _ in network.branches})
    out = []
    for item in flows:
        try:
            label = (str(item[0]), int(item[1]))
        except (TypeError, ValueError, IndexError):
            label = None
        if label is None or label not in where or len(item) != 2:
            raise ValueError(
                f"flows must be 'all', 'none' or (table, index) labels of in-service branches of "
                f"case {network.name!r}, tables {tables} (e.g. ('line', 0)), got {item!r}"
            )
        out.append(where[label])
    return out


def _meters(
    network: DCNetwork, buses: list[int], branches: list[int], ends: str, grouping: str
) -> tuple[list[Meter], list[int]]:
    """Meters in sensor order and the sensor index of each."""
    meters = [Meter("injection", i) for i in buses]
    for k in branches:
        meters.append(Meter("flow", int(network.from_bus[k]), k, "from"))
        if ends == "both":
            meters.append(Meter("flow", int(network.to_bus[k]), k, "to"))
    if grouping == "meter":
        return meters, list(range(len(meters)))
    # one RTU per bus, in bus order: its injection first, then its flows in branch order
    order = sorted(range(len(meters)), key=lambda m: (meters[m].bus, meters[m].kind != "injection"))
    meters = [meters[m] for m in order]
    rtus = sorted({m.bus for m in meters})
    sensor = {bus: s for s, bus in enumerate(rtus)}
    return meters, [sensor[m.bus] for m in meters]


def _rows(network: DCNetwork, meters: list[Meter]) -> tuple[np.ndarray, np.ndarray]:
    """(nz, Nb) rows over all bus angles and (nz,) offsets."""
    Bf = network.b[:, None] * network.A  # P_f = Bf θ − b φ
    f_off = -network.b * network.shift
    Bbus, inj_off = network.A.T @ Bf, network.A.T @ f_off  # P_inj = A' P_f
    H = np.empty((len(meters), network.n_buses))
    off = np.empty(len(meters))
    for r, m in enumerate(meters):
        if m.kind == "injection":
            H[r], off[r] = Bbus[m.bus], inj_off[m.bus]
        else:
            sign = 1.0 if m.end == "from" else -1.0
            H[r], off[r] = sign * Bf[m.branch], sign * f_off[m.branch]
    return H, off


def _label(network: DCNetwork, m: Meter) -> str:
    bus = int(network.buses[m.bus])
    if m.kind == "injection":
        return f"inj{bus}"
    table, index = network.branches[m.branch]
    return f"{table}{index}@{bus}"


def grid_model(
    case: Any = "ieee14",
    *,
    sensors: str = "meter",
    injections: str | Sequence[int] = "all",
    flows: str | Sequence[tuple[str, int]] = "all",
    flow_ends: str | None = None,
    sigma_flow: float = DEFAULT_SIGMA_FLOW,
    sigma_injection: float = DEFAULT_SIGMA_INJECTION,
    q: float = DEFAULT_Q,
    F: np.ndarray | None = None,
    Q: np.ndarray | None = None,
    P0: np.ndarray | None = None,
    name: str | None = None,
) -> GridModel:
    """Build the grid system with its network and meters; see :func:`grid_system`."""
    grouping = check_choice("sensors", sensors, SENSOR_GROUPINGS)
    if flow_ends is None:
        flow_ends = "from" if grouping == "meter" else "both"
    ends = check_choice("flow_ends", flow_ends, FLOW_ENDS)
    sigma_flow = check_positive("sigma_flow", sigma_flow)
    sigma_injection = check_positive("sigma_injection", sigma_injection)
    network = case if isinstance(case, DCNetwork) else dc_network(case)
    buses = _bus_positions(network, injections)
    branches = _branch_positions(network, flows)
    if not buses and not branches:
        raise ValueError("injections and flows select no meter: choose at least one measurement")
    meters, owner = _meters(network, buses, branches, ends, grouping)
    H_full, offset = _rows(network, meters)
    keep = np.arange(network.n_buses) != network.slack
    H = H_full[:, keep]
    n = H.shape[1]
    if n == 0:
        raise ValueError(f"case {network.name!r} has a single bus: no angle to estimate")
    if np.linalg.matrix_rank(H) < n:
        raise ValueError(
            f"the meters (injections={injections!r}, flows={flows!r}) do not make the "
            f"{network.n_buses}-bus network observable (rank {np.linalg.matrix_rank(H)} < {n} "
            "angles); meter more buses or branches"
        )
    var = np.array([sigma_injection**2 if m.kind == "injection" else sigma_flow**2 for m in meters])
    if Q is None:
        q = check_positive("q", q)
        Q = q * np.eye(n)
    else:
        Q = as_matrix("Q", Q, shape=(n, n))
    F = np.eye(n) if F is None else as_matrix("F", F, shape=(n, n))

    def build() -> LinearSystem:
        owner_arr = np.array(owner)
        group = []
        for s in range(owner_arr.max() + 1):
            rows = np.flatnonzero(owner_arr == s)
            label = (
                _label(network, meters[rows[0]])
                if grouping == "meter"
                else f"rtu{int(network.buses[meters[rows[0]].bus])}"
            )
            group.append(Sensor(H=H[rows], R=np.diag(var[rows]), name=label))
        return LinearSystem(
            F=F,
            Q=Q,
            sensors=tuple(group),
            x0=network.theta[keep],
            P0=DEFAULT_P0 * np.eye(n) if P0 is None else P0,
            name=name or f"grid-{network.name}",
        )

    for arr in (H_full, offset):
        arr.setflags(write=False)
    return GridModel(
        network=network,
        meters=tuple(meters),
        H_full=H_full,
        offset=offset,
        state_buses=network.buses[keep],
        build=build,
    )


def grid_system(case: Any = "ieee14", **kwargs: Any) -> LinearSystem:
    """DC dynamic state estimation of a transmission network as a :class:`LinearSystem`.

    Args:
        case: ``"ieee14"``, ``"ieee30"``, ``"ieee57"``, ``"ieee118"``, ``"ieee300"`` or a
            pandapower network (``pandapower.networks.case14()``, your own ``pandapowerNet``).
        **kwargs: Keyword-only options:

            - ``sensors``: ``"meter"`` (one sensor per meter, default) or ``"bus"`` (one RTU
              per bus: its injection and the flows metered at its end of its branches).
            - ``injections``: ``"all"`` (default), ``"none"`` or pandapower bus indices.
            - ``flows``: ``"all"`` (default), ``"none"`` or branch labels ``(table, index)``,
              e.g. ``[("line", 0), ("trafo", 2)]``.
            - ``flow_ends``: ``"from"`` (one meter per branch, at its from/hv end) or
              ``"both"``; default ``"from"`` per meter, ``"both"`` per bus.
            - ``sigma_flow``, ``sigma_injection``: meter noise σ, per unit (> 0).
            - ``q``: random-walk variance per step, rad² (> 0), ``Q = q I``.
            - ``F``, ``Q``: your own (n, n) dynamics instead (n = buses − 1).
            - ``P0``: prior covariance (default 0.01 I); the prior mean is the case's
              DC power-flow angles.
            - ``name``: label (default ``"grid-<case>"``).

    Returns:
        The validated system: n = buses − 1 states, one sensor per meter or per metered bus.

    Raises:
        ImportError: Without pandapower; the message names the ``[grid]`` extra.
        ValueError: Naming the parameter: an unknown case, a network with islands or no
            branches, a meter at a missing bus or branch, σ or q ≤ 0, meters that leave the
            network unobservable, an unknown option value.

    Example:
        >>> from fdia_env.systems import grid_system
        >>> sys = grid_system("ieee14")
        >>> sys.n, sys.M, sys.sensors[0].name, sys.sensors[14].name
        (13, 34, 'inj0', 'line0@0')
        >>> rtu = grid_system("ieee14", sensors="bus")
        >>> rtu.M, rtu.nz, rtu.sensors[0].name
        (14, 54, 'rtu0')
    """
    unknown = set(kwargs) - set(grid_model.__kwdefaults__)
    if unknown:
        raise ValueError(
            f"grid_system got unknown options {sorted(unknown)}; allowed: "
            f"{sorted(grid_model.__kwdefaults__)}"
        )
    return grid_model(case, **kwargs).system
