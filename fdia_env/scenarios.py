"""Named parameter sets of the literature (docs/math.md §6) and power-grid presets (§7 there).

>>> from fdia_env import scenarios
>>> sc = scenarios.get("ch4-position")
>>> sc.system.M, sc.budget, sc.horizon
(3, 5, 6)

Power-grid presets (need the ``[grid]`` extra; built with
:func:`fdia_env.systems.grid_system` on first :func:`get`, then cached). One sensor per meter: an
injection meter at every bus and a flow meter at the from end of every branch; σ_flow = 0.01,
σ_injection = 0.02 (per unit on 100 MVA), random walk ``Q = q I`` with q = 1e-6 rad², the
filter in steady state at the window start; the prior mean is the case's DC power-flow angles.

| name | model | values |
|---|---|---|
| grid-ieee14 | IEEE 14-bus, n = 13 angles, M = 34 meters | c = 6, N = 6, a² = 0.01, game k = 2 |
| grid-ieee30 | IEEE 30-bus, n = 29, M = 71 | c = 6, N = 4, a² = 0.01, game k = 1 |
| grid-ieee57 | IEEE 57-bus, n = 56, M = 137 | c = 6, N = 3, a² = 0.01, game k = 1 |
| grid-ieee118 | IEEE 118-bus, n = 117, M = 304 | c = 6, N = 3, a² = 0.01, game k = 1 |

A power-grid preset that needs no extra (:func:`fdia_env.systems.grid.dc14.dc_grid14`, built
from the IEEE 14-bus reactances without pandapower; random walk ``q = 1e-4`` rad², every meter
σ = 0.02 pu):

| name | model | values |
|---|---|---|
| dc-ieee14-50 | IEEE 14-bus DC, n = 13 angles, M = 50 meters | c = 5, N = 6 (300 pairs) |

``dc-ieee14-50`` is the 300-pair sparse-attack instance of the certified results: with the
trace objective (the sparse env's default) branch and bound proves the optimum, 1.769e-4,
while SFS stops at 98.5 % of it (a set with a single meter in common with the optimum's).

One RTU per bus (its injection and the flows at its end; needs the ``[grid]`` extra, as the
grid presets):

| name | model | values |
|---|---|---|
| grid-ieee14-rtu | IEEE 14-bus, n = 13 angles, M = 14 RTUs | c = 6, N = 6 (84 pairs) |

``grid-ieee14-rtu`` is the sparse-attack instance of the grid results where the greedy heuristics
fail: with the log det objective SFS and SFS-SS stop at 54.1 % of branch and bound's proved
optimum (``train.py`` trains it with ``objective="logdet"``).

Beyond the literature, a larger sensor game in the spirit of ``ch5-game``:

| name | model | values |
|---|---|---|
| game-m10 | 10 position sensors | σ_w = 3.0, 3.5, ..., 7.5; σ_v, T, x̂0, P0, a² as ch5-game |

``game-m10`` continues ch5-game's σ_w = 3, 4, 5 to ten sensors in steps of 0.5: 1,023 strategies
per player, small enough for the full LP on ``payoff_matrix`` (value 2.956, independent rule) and
mixed at equilibrium (the defender drops 0 to 3 of the best sensors, the attacker hits one of
the four best), so the double oracle needs several iterations.

Why these values: with σ and q as above the steady-state ``tr P`` is 0.27 (ieee14) to 0.34
(ieee118) of the static estimator's ``tr (H' R⁻¹ H)⁻¹``, so prediction and measurements both
matter (docs/math.md §7); a² = 0.01 pu² (a 10 MW bias standard deviation) makes the single-meter
attack term ``a² |W e_i|²`` 1 to 3 times ``tr P``; c and N leave the sparse problems far beyond
exhaustive search (C(204, 6) ≈ 1e11 sets for ieee14) while SFS, SBS, SFS-SS and DP run in
seconds. ``k`` is the sensor game's ``max_subset_size``: the attacker picks at most k meters,
the defender leaves out at most k (no single meter is critical, so every such defender subset
keeps the network observable).
"""

from __future__ import annotations

import functools
import inspect
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from fdia_env._validation import check_int, check_positive
from fdia_env.systems import LinearSystem, Sensor, pv_sensor, tracking_system
from fdia_env.systems.grid.cases import GRID_CASES


@dataclass(frozen=True, eq=False)
class Scenario:
    """A system plus the experiment defaults the literature used with it.

    Attributes:
        name: Preset name.
        system: The linear Gaussian system.
        description: One line on where the parameters come from.
        budget: Sparsity budget c (sparse attacks), if the source states one.
        horizon: Attack window length N, if stated.
        power: Attack power a², if stated.
        attack_step: Time step of the attack, if stated.
        steady_state: Whether the filter starts the window in steady state.
        extra: Other stated values (probabilities, sweeps, run counts).
    """

    name: str
    system: LinearSystem
    description: str
    budget: int | None = None
    horizon: int | None = None
    power: float | None = None
    attack_step: int | None = None
    steady_state: bool = True
    extra: dict[str, Any] = field(default_factory=dict)


def _ch2_position() -> Scenario:
    sys = tracking_system(0.5, [np.sqrt(3.0), 2.0], name="ch2-position")
    return Scenario("ch2-position", sys, "2 position sensors, σ_w² = 3, 4 (ch. 2)", power=3000.0)


def _ch2_pv(two: bool) -> Callable[[], Scenario]:
    def build() -> Scenario:
        sensors = [pv_sensor(np.sqrt(3.0), 2.0, 0.0, name="z1")]
        if two:
            sensors.append(pv_sensor(2.0, np.sqrt(5.0), 0.0, name="z2"))
        name = "ch2-pv-2" if two else "ch2-pv-1"
        sys = tracking_system(0.5, sensors=sensors, name=name)
        return Scenario(
            name, sys, f"{len(sensors)} position+velocity sensor(s) (ch. 2)", power=3000.0
        )

    return build


def _ch3_tracking() -> Scenario:
    sys = tracking_system(
        0.5, sensors=[pv_sensor(np.sqrt(3.0), 2.0, 0.0, name="z1")], name="ch3-tracking"
    )
    return Scenario(
        "ch3-tracking",
        sys,
        "1 position+velocity sensor, R = diag(3, 4) (ch. 3)",
        attack_step=100,
        horizon=200,
        steady_state=False,
        extra={"p1": 0.85, "power_range": (7.5, 120.0), "mc_runs": 10_000},
    )


def _ch3_static() -> Scenario:
    sensor = Sensor(H=np.eye(2), R=np.diag([3.0, 4.0]), name="z1")
    sys = LinearSystem(
        F=np.eye(2),
        Q=np.zeros((2, 2)),
        sensors=(sensor,),
        x0=[10.0, 5.0],
        P0=100.0 * np.eye(2),
        name="ch3-static",
    )
    return Scenario(
        "ch3-static",
        sys,
        "static parameter, prior N([10, 5], 100 I) (ch. 3)",
        steady_state=False,
        extra={"p1": 0.85, "power_range": (0.0, 400.0), "Pbb": "diag(a², 0)"},
    )


def _ch4_position(horizon: int = 6) -> Scenario:
    sys = tracking_system(0.02, [0.2, 0.4, 0.5], name="ch4-position")
    return Scenario("ch4-position", sys, "3 position sensors (ch. 4)", budget=5, horizon=horizon)


def _ch4_pv(case: int) -> Callable[[], Scenario]:
    def build() -> Scenario:
        sigma_v = 0.02 if case == 1 else 0.001
        sig = [0.5, 0.2 if case == 3 else 0.5, 0.5]
        rho = [0.5, 0.0, -0.5]
        sensors = [
            pv_sensor(s, s, r, name=f"z{i + 1}")
            for i, (s, r) in enumerate(zip(sig, rho, strict=True))
        ]
        name = f"ch4-pv-case{case}"
        sys = tracking_system(sigma_v, sensors=sensors, name=name)
        return Scenario(
            name,
            sys,
            f"3 position+velocity sensors, case {case} (ch. 4)",
            budget=5,
            horizon=6,
            extra={"objective": "logdet"},
        )

    return build


def _ch4_random(seed: int = 0, sigma_v: float = 0.1) -> Scenario:
    rng = np.random.default_rng(seed)
    sigma_w = rng.uniform(0.0, 1.0, size=10)
    sigma_w = np.maximum(sigma_w, 1e-6)  # U(0, 1) can return exactly 0; a sensor needs R > 0
    sys = tracking_system(sigma_v, list(sigma_w), name="ch4-random")
    return Scenario(
        "ch4-random",
        sys,
        f"10 position sensors, σ_w ~ U(0, 1) (seed {seed})",
        budget=10,
        horizon=6,
        extra={"seed": seed},
    )


def _sensor_game(name: str, sigma_w: list[float], description: str) -> Scenario:
    """A sensor-selection game of ch. 5: position sensors of noise ``sigma_w``, T = 0.5."""
    sys = tracking_system(
        0.5, sigma_w, x0=[1.0, 1.0], P0=np.array([[0.25, 0.25], [0.25, 0.5]]), name=name
    )
    return Scenario(name, sys, description, power=100.0, attack_step=100)


def _ch5_game() -> Scenario:
    return _sensor_game(
        "ch5-game", [3.0, 4.0, 5.0], "3 position sensors, sensor-selection game (ch. 5)"
    )


# name -> (case, budget c, horizon N, sensor-game max_subset_size k): the cases of the table of
# grid cases that have a preset
GRID_PRESETS: dict[str, tuple[str, int, int, int]] = {
    f"grid-{case.name}": (
        case.name,
        case.preset.budget,
        case.preset.horizon,
        case.preset.max_subset_size,
    )
    for case in GRID_CASES.values()
    if case.preset is not None
}
GRID_POWER = 0.01


def _game_m10() -> Scenario:
    return _sensor_game(
        "game-m10",
        [3.0 + 0.5 * i for i in range(10)],
        "10 position sensors, σ_w = 3.0..7.5, sensor-selection game (ch. 5 setting, M = 10)",
    )


def _dc_ieee14_50() -> Scenario:
    from fdia_env.systems.grid.dc14 import dc_grid14

    sys = dc_grid14(50)
    return Scenario(
        "dc-ieee14-50",
        sys,
        "IEEE 14-bus DC model without pandapower, 50 meters (injections and flows), "
        "13 angles (docs/math.md §7)",
        budget=5,
        horizon=6,
    )


@functools.cache
def _grid_ieee14_rtu() -> Scenario:
    from fdia_env.systems.grid import grid_system

    sys = grid_system("ieee14", sensors="bus", name="grid-ieee14-rtu")
    return Scenario(
        "grid-ieee14-rtu",
        sys,
        f"ieee14: DC dynamic state estimation, {sys.M} RTUs (one per bus), {sys.n} angles "
        "(docs/math.md §7)",
        budget=6,
        horizon=6,
        power=GRID_POWER,
        extra={"case": "ieee14"},
    )


def _grid(name: str) -> Callable[[], Scenario]:
    @functools.cache
    def build() -> Scenario:
        from fdia_env.systems.grid import grid_system

        case, budget, horizon, k = GRID_PRESETS[name]
        sys = grid_system(case, name=name)
        return Scenario(
            name,
            sys,
            f"{case}: DC dynamic state estimation, {sys.M} meters, {sys.n} angles "
            "(docs/math.md §7)",
            budget=budget,
            horizon=horizon,
            power=GRID_POWER,
            extra={"case": case, "max_subset_size": k},
        )

    return build


_PRESETS: dict[str, Callable[..., Scenario]] = {
    "ch2-position": _ch2_position,
    "ch2-pv-1": _ch2_pv(two=False),
    "ch2-pv-2": _ch2_pv(two=True),
    "ch3-tracking": _ch3_tracking,
    "ch3-static": _ch3_static,
    "ch4-position": _ch4_position,
    "ch4-pv-case1": _ch4_pv(1),
    "ch4-pv-case2": _ch4_pv(2),
    "ch4-pv-case3": _ch4_pv(3),
    "ch4-random": _ch4_random,
    "ch5-game": _ch5_game,
    "game-m10": _game_m10,
    **{name: _grid(name) for name in GRID_PRESETS},
    "dc-ieee14-50": _dc_ieee14_50,
    "grid-ieee14-rtu": _grid_ieee14_rtu,
}


def names() -> list[str]:
    """The known preset names."""
    return list(_PRESETS)


def get(name: str, **kwargs: Any) -> Scenario:
    """Build the named preset.

    Args:
        name: One of :func:`names`.
        **kwargs: Preset options: ``horizon`` for ``ch4-position``; ``seed`` and ``sigma_v`` for
            ``ch4-random``.

    Raises:
        ValueError: For an unknown name (the message lists the known ones), an option the
            preset does not take (the message lists those it takes), or a bad option value
            (``horizon`` an integer >= 1, ``seed`` an integer >= 0, ``sigma_v`` > 0).
    """
    if not isinstance(name, str) or name not in _PRESETS:  # str first: a list is unhashable
        raise ValueError(
            f"unknown scenario {name!r}; known scenarios: {', '.join(_PRESETS)} "
            "(name must be one of them)"
        )
    accepted = inspect.signature(_PRESETS[name]).parameters
    unknown = sorted(set(kwargs) - set(accepted))
    if unknown:
        takes = sorted(accepted) or "none"
        raise ValueError(f"scenario {name!r} does not take options {unknown}; it takes {takes}")
    for option, value in kwargs.items():  # validated here: the builders trust their options
        if option == "horizon":
            check_int("horizon", value, minimum=1)
        elif option == "seed":
            check_int("seed", value, minimum=0)  # numpy seeds are non-negative integers
        elif option == "sigma_v":
            check_positive("sigma_v", value)
    return _PRESETS[name](**kwargs)


def scenario_default(sc: Scenario, name: str, value: Any) -> Any:
    """``value`` if given, else the preset's ``name`` (its attribute, else its ``extra`` entry).

    Args:
        sc: The scenario whose preset fills the default.
        name: The parameter (``"budget"``, ``"horizon"``, ``"power"``, or a key of ``extra``
            such as ``"p1"``).
        value: The caller's value; None takes the preset's.

    Raises:
        ValueError: ``"<name> is required: ..."`` when ``value`` is None and the preset defines
            none.

    Example:
        >>> scenario_default(get("ch4-position"), "budget", None), scenario_default(
        ...     get("ch4-position"), "budget", 3)
        (5, 3)
    """
    if value is not None:
        return value
    preset = getattr(sc, name, None)
    if preset is None:
        preset = sc.extra.get(name)
    if preset is None:
        raise ValueError(f"{name} is required: scenario {sc.name!r} does not define one")
    return preset


def resolve(scenario: str | Scenario | LinearSystem) -> Scenario:
    """Accept a preset name, a :class:`Scenario` or a bare :class:`LinearSystem`."""
    if isinstance(scenario, Scenario):
        return scenario
    if isinstance(scenario, LinearSystem):
        return Scenario(scenario.name, scenario, "user-supplied system")
    if isinstance(scenario, str):
        return get(scenario)
    raise ValueError(
        "scenario must be a preset name, a Scenario or a LinearSystem, "
        f"got {type(scenario).__name__}"
    )
