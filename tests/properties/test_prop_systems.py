"""Property: system builders build sane systems or name a parameter.

``Sensor``, ``LinearSystem``, ``tracking_system``, ``pv_sensor`` and ``scenarios.get`` take
arbitrary inputs (random small matrices, non-square, non-symmetric, indefinite, NaN, wrong
types): either the system builds, and then its steady state (``fdia_env.kalman.steady_state``)
is finite, symmetric and PSD, or the call raises ``ValueError``/``TypeError`` naming a parameter.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st
from prop_support import (
    assert_psd,
    bounded,
    kwargs_of,
    matrix_values,
    mixed,
    outcome,
    pd_matrices,
    prop_settings,
    small_matrices,
    wrong_values,
)

from fdia_env import LinearSystem, Sensor, pv_sensor, scenarios, tracking_system
from fdia_env.kalman import steady_state

pytestmark = pytest.mark.filterwarnings("ignore")

positive = st.one_of(st.floats(1e-6, 1e6), st.integers(1, 100))


OUT_OF_REACH = "no steady state computable in float64"


def _check_steady(system: LinearSystem, out_of_reach_ok: bool = False) -> None:
    """The steady state is finite and PSD (or, with ``out_of_reach_ok``, documented as out of
    float64's reach: ``RuntimeError`` naming the scales, fdia_env/kalman/steady.py)."""
    with bounded():
        try:
            P_pred, P, W = steady_state(system)
        except RuntimeError as exc:
            if out_of_reach_ok and OUT_OF_REACH in str(exc):
                return
            raise
    assert_psd(P_pred, "steady P[k+1|k]")
    assert_psd(P, "steady P[k|k]")
    assert np.all(np.isfinite(W)), W


@prop_settings(40)
@given(
    kwargs=kwargs_of(
        {"H": small_matrices(), "R": matrix_values(), "name": st.text(max_size=3)},
        required=("H", "R"),
    )
)
def test_sensor_builds_or_names_a_parameter(kwargs):
    built, sensor = outcome(lambda: Sensor(**kwargs), kwargs)
    if built:
        assert np.all(np.isfinite(sensor.H)) and sensor.R.shape == (sensor.dim, sensor.dim)
        assert_psd(sensor.R, "Sensor.R")
        assert np.linalg.eigvalsh(sensor.R).min() > 0


@st.composite
def sensors_for(draw, n: int) -> tuple:
    """1..3 valid sensors with ``n`` columns."""
    out = []
    for i in range(draw(st.integers(1, 3))):
        d = draw(st.integers(1, 2))
        rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
        out.append(Sensor(H=rng.standard_normal((d, n)), R=draw(pd_matrices(d)), name=f"s{i}"))
    return tuple(out)


@st.composite
def system_kwargs(draw, wrong: bool = True) -> dict:
    """LinearSystem arguments: a consistent valid system with some entries replaced.

    ``wrong=False`` replaces them with matrices (of any shape, NaN included) but no wrong types.
    """
    n = draw(st.integers(1, 3))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    valid = {
        "F": st.just(rng.standard_normal((n, n)) * draw(st.sampled_from([0.5, 1.0, 2.0]))),
        "Q": pd_matrices(n),
        "sensors": sensors_for(n),
        "x0": st.just(rng.standard_normal(n)),
        "P0": pd_matrices(n),
        "T": positive,
    }
    kwargs = {"F": draw(valid["F"]), "Q": draw(valid["Q"]), "sensors": draw(valid["sensors"])}
    for name in draw(st.lists(st.sampled_from(sorted(valid)), unique=True)):
        if wrong:
            kwargs[name] = draw(
                st.one_of(mixed(valid[name]), small_matrices(), small_matrices(square=True))
            )
        elif name in ("F", "Q", "P0", "x0"):
            kwargs[name] = draw(
                st.one_of(valid[name], small_matrices(), small_matrices(square=True))
            )
        else:
            kwargs[name] = draw(valid[name])
    return kwargs


def _check_system(kwargs: dict) -> None:
    built, system = outcome(lambda: LinearSystem(**kwargs), kwargs)
    if built:
        assert system.F.shape == (system.n, system.n)
        assert_psd(system.Q, "Q")
        assert_psd(system.P0, "P0")


@prop_settings(50)
@given(kwargs=system_kwargs(wrong=False))
def test_linear_system_from_matrices_builds_or_names_a_parameter(kwargs):
    _check_system(kwargs)


@prop_settings(30)
@given(kwargs=system_kwargs())
@example(kwargs={"F": [[1.0]], "Q": [[1.0]], "sensors": 1.5})
@example(kwargs={"F": [[1.0]], "Q": [[1.0]], "sensors": (Sensor([[1.0]], [[1.0]]),), "T": "x"})
def test_linear_system_builds_or_names_a_parameter(kwargs):
    _check_system(kwargs)


TRACKING = {
    "sigma_v": positive,
    "sigma_w": st.lists(positive, min_size=1, max_size=3),
    "T": positive,
    "sensors": st.lists(st.builds(pv_sensor, positive, positive), max_size=2),
    "x0": st.lists(st.floats(-10, 10), min_size=2, max_size=2),
    "P0": pd_matrices(2),
}


moderate = st.floats(1e-3, 1e3)
MODERATE_TRACKING = {
    **TRACKING,
    "sigma_v": moderate,
    "sigma_w": st.lists(moderate, min_size=1, max_size=3),
    "T": st.floats(0.01, 10.0),
    "sensors": st.lists(st.builds(pv_sensor, moderate, moderate), max_size=2),
}


@prop_settings(40)
@given(kwargs=kwargs_of(MODERATE_TRACKING, required=("sigma_v", "sigma_w"), wrong=False))
def test_tracking_system_builds_with_a_psd_steady_state(kwargs):
    """Moderate valid inputs (σ in [1e-3, 1e3], T in [0.01, 10]): the steady state is PSD.

    Wider ranges are the property below (any index: closed form for position sensors).
    """
    built, system = outcome(lambda: tracking_system(**kwargs), kwargs)
    if built:
        _check_steady(system)


@prop_settings(30)
@given(kwargs=kwargs_of(TRACKING, required=("sigma_v",)))
@example(kwargs={"sigma_v": 1e9, "sigma_w": [1.0]})
@example(kwargs={"sigma_v": 1.0, "sigma_w": 1.0})
@example(  # a position-velocity sensor far beyond float64's reach: RuntimeError naming it
    kwargs={
        "sigma_v": 710754.22859873,
        "T": 710754.22859873,
        "sensors": [pv_sensor(710754.22859873, 100)],
    }
)
def test_tracking_system_builds_or_names_a_parameter(kwargs):
    """Any inputs, extreme tracking indices included: a PSD steady state or a named parameter.

    Position sensors at any index are solved in closed form; a missing sensor argument is
    named as such (``sigma_w`` or ``sensors``). A position-velocity sensor has no closed form:
    beyond the index float64 resolves, the steady state says so (a ``RuntimeError`` naming the
    scales) instead of returning a wrong covariance.
    """
    built, system = outcome(lambda: tracking_system(**kwargs), [*kwargs, "sigma_w", "sensors"])
    if built:
        velocity_seen = any(np.any(s.H[:, 1] != 0) for s in system.sensors)
        _check_steady(system, out_of_reach_ok=velocity_seen)


PV = {
    "sigma_p": positive,
    "sigma_vel": positive,
    "rho": st.floats(-0.999, 0.999),
    "name": st.text(max_size=3),
}


def _check_pv(kwargs: dict) -> None:
    built, sensor = outcome(lambda: pv_sensor(**kwargs), kwargs)
    if built:
        assert np.linalg.eigvalsh(sensor.R).min() > 0, sensor.R


@prop_settings(30)
@given(
    kwargs=kwargs_of(PV, required=("sigma_p", "sigma_vel")),
    rho=st.one_of(st.floats(allow_nan=True), st.sampled_from([1, -1, 2**63, True])),
)
def test_pv_sensor_with_a_real_rho_builds_or_names_a_parameter(kwargs, rho):
    kwargs["rho"] = rho
    _check_pv(kwargs)


@prop_settings(30)
@given(kwargs=kwargs_of(PV, required=("sigma_p", "sigma_vel")))
@example(kwargs={"sigma_p": 1.0, "sigma_vel": 1.0, "rho": None})
def test_pv_sensor_builds_or_names_a_parameter(kwargs):
    _check_pv(kwargs)


@prop_settings(30)
@given(
    name=st.sampled_from(scenarios.names()),
    options=kwargs_of({"horizon": st.integers(1, 10), "seed": st.integers(0, 10)}),
)
def test_scenarios_get_known_name_builds_or_names_an_option(name, options):
    built, sc = outcome(lambda: scenarios.get(name, **options), options or ["scenario"])
    if built and sc.steady_state:  # a static preset (F = I, Q = 0) has none, by design
        _check_steady(sc.system)


@prop_settings(30)
@example(name="x", options={})
@example(name=[1], options={})
@given(
    name=mixed(st.sampled_from(scenarios.names())),
    options=kwargs_of(
        {"horizon": st.integers(1, 10), "seed": st.integers(0, 10), "sigma_v": positive}
    ),
)
def test_scenarios_get_builds_or_names_a_parameter(name, options):
    options = {k: v for k, v in options.items() if k != "name"}
    built, sc = outcome(lambda: scenarios.get(name, **options), ["name", *options])
    if built and sc.steady_state:  # a static preset (F = I, Q = 0) has none, by design
        _check_steady(sc.system)


@prop_settings(30)
@given(kwargs=system_kwargs())
@example(kwargs={"F": [[2.0]], "Q": [[1.0]], "sensors": (Sensor(H=[[0.0]], R=[[1.0]]),)})
def test_linear_system_steady_state_is_psd_or_names_a_parameter(kwargs):
    built, system = outcome(lambda: LinearSystem(**kwargs), kwargs)
    if built:
        try:
            _check_steady(system)
        except (ValueError, TypeError) as exc:
            assert any(name in str(exc) for name in ("F", "Q", "sensors", "H", "R")), exc


@prop_settings(20)
@given(value=wrong_values())
def test_linear_system_rejects_a_non_sensor_in_sensors(value):
    kwargs = {"F": np.eye(2), "Q": np.eye(2), "sensors": (value,)}
    built, _ = outcome(lambda: LinearSystem(**kwargs), kwargs)
    assert not built
