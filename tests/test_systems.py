"""Validation of systems, sensors and scenario presets: errors name the offending parameter."""

from __future__ import annotations

import re

import numpy as np
import pytest

from fdia_env import scenarios
from fdia_env.systems import LinearSystem, Sensor, position_sensor, pv_sensor, tracking_system

F2, Q2 = np.array([[1.0, 1.0], [0.0, 1.0]]), 0.1 * np.eye(2)


def _system(**overrides):
    """A valid 2-state system with one position sensor, with some arguments replaced."""
    kwargs = {"F": F2, "Q": Q2, "sensors": (position_sensor(1.0),)}
    kwargs.update(overrides)
    return LinearSystem(**kwargs)


def test_valid_system_builds_with_stacked_matrices():
    """Control for the error tests: the baseline system builds; H, R, J are the stacked values."""
    system = _system(sensors=(position_sensor(2.0), pv_sensor(1.0, 3.0, 0.5)))
    assert (system.n, system.M, system.nz) == (2, 2, 3)
    np.testing.assert_array_equal(system.H, [[1, 0], [1, 0], [0, 1]])
    np.testing.assert_allclose(system.R, [[4, 0, 0], [0, 1, 1.5], [0, 1.5, 9]], rtol=0, atol=1e-15)
    J = [s.H.T @ np.linalg.inv(s.R) @ s.H for s in system.sensors]
    np.testing.assert_allclose(system.J, J, rtol=1e-14, atol=0)


def test_non_square_f_is_rejected():
    with pytest.raises(ValueError, match=r"LinearSystem\.F must be square"):
        _system(F=np.ones((2, 3)))


def test_q_shape_mismatch_is_rejected():
    with pytest.raises(ValueError, match=r"LinearSystem\.Q must have shape \(2, 2\)"):
        _system(Q=np.eye(3))


def test_q_not_psd_is_rejected():
    with pytest.raises(ValueError, match=r"LinearSystem\.Q must be positive semidefinite"):
        _system(Q=np.diag([1.0, -0.01]))


def test_q_not_symmetric_is_rejected():
    with pytest.raises(ValueError, match=r"LinearSystem\.Q must be symmetric"):
        _system(Q=np.array([[1.0, 0.5], [0.0, 1.0]]))


def test_r_not_positive_definite_is_rejected():
    """A singular (PSD but not PD) R is rejected: the information form needs R⁻¹."""
    with pytest.raises(ValueError, match=r"Sensor\.R must be positive definite"):
        Sensor(H=np.eye(2), R=np.array([[1.0, 1.0], [1.0, 1.0]]))


def test_p0_not_positive_definite_is_rejected():
    with pytest.raises(ValueError, match=r"LinearSystem\.P0 must be positive definite"):
        _system(P0=np.zeros((2, 2)))


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
@pytest.mark.parametrize(
    ("param", "build"),
    [
        ("LinearSystem.F", lambda v: _system(F=np.array([[1.0, v], [0.0, 1.0]]))),
        ("LinearSystem.Q", lambda v: _system(Q=np.array([[v, 0.0], [0.0, 1.0]]))),
        ("Sensor.H", lambda v: Sensor(H=np.array([[1.0, v]]), R=np.eye(1))),
        ("Sensor.R", lambda v: Sensor(H=np.array([[1.0, 0.0]]), R=np.array([[v]]))),
        ("LinearSystem.x0", lambda v: _system(x0=[0.0, v])),
        ("LinearSystem.P0", lambda v: _system(P0=np.array([[1.0, 0.0], [0.0, v]]))),
    ],
)
def test_non_finite_entries_are_rejected(param, build, bad):
    with pytest.raises(ValueError, match=re.escape(param) + r" must be finite \(no NaN or inf\)"):
        build(bad)


def test_h_column_count_mismatch_is_rejected():
    sensor = Sensor(H=np.ones((1, 3)), R=np.eye(1))
    with pytest.raises(ValueError, match=r"sensors\[0\]\.H must have 2 columns"):
        _system(sensors=(sensor,))


def test_empty_sensors_are_rejected():
    with pytest.raises(ValueError, match=r"LinearSystem\.sensors must hold at least one"):
        _system(sensors=())


def test_unknown_scenario_lists_known_names():
    with pytest.raises(ValueError, match=r"unknown scenario 'ch9'.*ch4-position.*ch5-game"):
        scenarios.get("ch9")


def test_unknown_scenario_option_is_rejected():
    with pytest.raises(ValueError, match=r"does not take options \['seed'\]"):
        scenarios.get("ch5-game", seed=1)


@pytest.mark.parametrize("sigma_v", [0.0, -0.5, np.nan, np.inf])
def test_tracking_system_rejects_non_positive_sigma_v(sigma_v):
    with pytest.raises(ValueError, match=r"sigma_v must be a finite number > 0"):
        tracking_system(sigma_v, [1.0])


@pytest.mark.parametrize(("sigma_w", "index"), [([1.0, 0.0], 1), ([-2.0, 1.0], 0)])
def test_tracking_system_rejects_non_positive_sigma_w(sigma_w, index):
    with pytest.raises(ValueError, match=rf"sigma_w\[{index}\] must be a finite number > 0"):
        tracking_system(0.5, sigma_w)


def test_tracking_system_without_sensors_is_rejected():
    with pytest.raises(ValueError, match=r"tracking_system needs sigma_w or sensors"):
        tracking_system(0.5)


@pytest.mark.parametrize("rho", [1.0, -1.0, 1.5, np.nan])
def test_pv_sensor_rejects_correlation_outside_open_interval(rho):
    with pytest.raises(ValueError, match=r"rho must lie strictly between -1 and 1"):
        pv_sensor(1.0, 1.0, rho)


def test_tracking_system_matrices_follow_the_white_noise_acceleration_model():
    """F = [[1, T], [0, 1]], Q = σ_v² ΓΓ' with Γ = [T²/2, T]' (docs/math.md §1), for T = 0.5."""
    system = tracking_system(2.0, [3.0], T=0.5)
    np.testing.assert_array_equal(system.F, [[1.0, 0.5], [0.0, 1.0]])
    np.testing.assert_allclose(system.Q, 4.0 * np.array([[1 / 64, 1 / 16], [1 / 16, 1 / 4]]))
    np.testing.assert_array_equal(system.R, [[9.0]])


@pytest.mark.parametrize("name", scenarios.names())
def test_every_preset_builds_with_finite_valid_matrices(name):
    """Finite matrices, P0 symmetric PD, Q symmetric PSD, R symmetric PD, J = H_i' R_i⁻¹ H_i."""
    system = scenarios.get(name).system
    for value in (system.F, system.Q, system.H, system.R, system.x0, system.P0, system.J):
        assert np.all(np.isfinite(value))
    assert np.array_equal(system.P0, system.P0.T) and np.linalg.eigvalsh(system.P0).min() > 0
    assert np.array_equal(system.Q, system.Q.T) and np.linalg.eigvalsh(system.Q).min() >= -1e-15
    assert np.array_equal(system.R, system.R.T) and np.linalg.eigvalsh(system.R).min() > 0
    for i, sensor in enumerate(system.sensors):
        expected = sensor.H.T @ np.linalg.solve(sensor.R, sensor.H)
        np.testing.assert_allclose(system.J[i], expected, rtol=1e-12, atol=1e-300)


def test_scenario_names_cover_the_literature_table():
    """The eleven parameter sets of docs/math.md §6, in order, then game-m10 and the grids."""
    literature = [n for n in scenarios.names() if not n.startswith(("grid-", "game-", "dc-"))]
    assert [n for n in scenarios.names() if n not in literature] == [
        "game-m10",
        "grid-ieee14",
        "grid-ieee30",
        "grid-ieee57",
        "grid-ieee118",
        "dc-ieee14-50",
        "grid-ieee14-rtu",
    ]
    assert literature == [
        "ch2-position",
        "ch2-pv-1",
        "ch2-pv-2",
        "ch3-tracking",
        "ch3-static",
        "ch4-position",
        "ch4-pv-case1",
        "ch4-pv-case2",
        "ch4-pv-case3",
        "ch4-random",
        "ch5-game",
    ]
