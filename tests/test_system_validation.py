"""System-level validation: detectability, stabilisability, convergence checks, clear errors,
read-only arrays after pickling."""

import copy
import pickle
import time

import numpy as np
import pytest

from fdia_env import detection_game_v0, scenarios, sensor_game_v0
from fdia_env.episode import MAX_HORIZON, MAX_WARMUP, EpisodeSpec
from fdia_env.kalman import information_update, predict_cov, steady_state, steady_state_iterate
from fdia_env.systems import LinearSystem, Sensor, pv_sensor, tracking_system

POS = Sensor(H=[[1.0, 0.0]], R=[[1.0]], name="pos")


def _system(F, Q=None, sensors=(POS,), **kw):
    n = np.asarray(F).shape[0]
    return LinearSystem(F=F, Q=np.eye(n) if Q is None else Q, sensors=sensors, **kw)


# --- covariance scale: the filter's covariances and informations inside float64's reach -------


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: Sensor(H=[[1.0, 0.0]], R=[[2e304]]), r"Sensor\.R entries must be at most"),
        (  # the information H' R⁻¹ H = 2e304: its inverse would underflow
            lambda: Sensor(H=[[1.41421356, 0.0]], R=[[1e-304]]),
            r"Sensor\.R is too small for its H: its information H' R⁻¹ H must be at most",
        ),
        (  # a subnormal R: the information overflows to inf
            lambda: Sensor(H=[[1.0, 0.0]], R=[[3e-309]]),
            r"Sensor\.R is too small for its H",
        ),
        (lambda: _system(np.eye(2), Q=1e308 * np.eye(2)), r"LinearSystem\.Q entries must be"),
        (lambda: _system(np.eye(2), P0=2e304 * np.eye(2)), r"LinearSystem\.P0 entries must be"),
        (
            lambda: _system(np.eye(2), P0=np.diag([1.0, 1e-305])),
            r"LinearSystem\.P0 is too small: its information P0⁻¹ must be at most",
        ),
    ],
)
def test_covariances_beyond_float64s_reach_are_refused_naming_the_parameter_and_range(
    make, message
):
    # a system of scale 1e308 has a trace of inf; at 1e-308 an information of inf
    with pytest.raises(ValueError, match=message + r".* 1e\+304 in magnitude"):
        make()


def test_the_covariance_scale_limits_are_inclusive_and_q_has_no_lower_one():
    _system(0.5 * np.eye(2), Q=1e304 * np.eye(2), sensors=(Sensor(H=[[1.0, 0.0]], R=[[1e304]]),))
    _system(0.5 * np.eye(2), Q=1e-320 * np.eye(2), P0=2e-304 * np.eye(2))  # a tiny Q: fine
    Sensor(H=[[1e-3, 0.0]], R=[[1e-305]])  # a small R with a small H: an information of 1e299
    # the detection guide's extreme tracking index: process noise of 2.5e-301 next to R = 9
    assert tracking_system(1e-150, [3.0]).Q.max() == pytest.approx(1e-300)


# --- every preset and every single-sensor subset still builds ---------------------------------


@pytest.mark.parametrize("name", scenarios.names())
def test_every_preset_builds_and_its_single_sensor_steady_states_exist(name):
    system = scenarios.get(name).system
    if np.allclose(system.Q, 0.0):  # ch3-static: a static parameter has no steady state
        with pytest.raises(ValueError, match=r"no steady state.*marginal mode.*1/k"):
            steady_state(system)
        return
    if name.startswith(("grid-", "dc-")):  # one meter cannot see every bus angle: refused
        with pytest.raises(ValueError, match=r"sensor subset .* is not detectable"):
            steady_state(system, np.eye(system.M, dtype=bool)[0])
        masks = [np.ones(system.M, dtype=bool)]  # every meter: the preset's own steady state
    else:
        masks = list(np.eye(system.M, dtype=bool))
    for mask in masks:
        P_pred, _, _ = steady_state(system, mask)
        # the fixed point of the recursion, independently: one more predict/update cycle
        again = predict_cov(information_update(P_pred, system.J, mask), system.F, system.Q)
        np.testing.assert_allclose(again, P_pred, rtol=1e-9, atol=1e-12)


def test_tracking_model_with_its_double_eigenvalue_one_is_detectable_with_a_position_sensor():
    system = tracking_system(0.5, 3.0)  # a scalar sigma_w is one position sensor
    assert system.M == 1 and np.allclose(np.linalg.eigvals(system.F), 1.0)
    P_pred, _, _ = steady_state(system)
    assert np.all(np.isfinite(P_pred)) and np.linalg.eigvalsh(P_pred).min() > 0.0


# --- defect 2: silent failures ------------------------------------------------------------------


def test_undetectable_unstable_system_is_rejected_naming_pair_and_eigenvalue():
    """F = 1e6 I with one position sensor: the velocity mode grows unseen (NaN rewards before)."""
    with pytest.raises(ValueError, match=r"\(F, H\).*not detectable.*eigenvalue 1e\+06"):
        _system(1e6 * np.eye(2))


def test_system_without_measurement_of_a_marginal_mode_is_rejected():
    """H = 0 gave a 'steady state' of trace 8e13 after 100 000 silent iterations."""
    blind = Sensor(H=[[0.0, 0.0]], R=[[1.0]])
    with pytest.raises(ValueError, match=r"\(F, H\).*not detectable.*eigenvalue 1\b"):
        _system([[1.0, 1.0], [0.0, 1.0]], sensors=(blind,))


def test_stable_system_with_h_zero_is_accepted_and_its_steady_state_is_the_lyapunov_solution():
    F, Q = np.diag([0.5, -0.3]), np.diag([1.0, 2.0])
    system = _system(F, Q, sensors=(Sensor(H=[[0.0, 0.0]], R=[[1.0]]),))
    P_pred, _, _ = steady_state(system)
    np.testing.assert_allclose(P_pred, np.diag([1 / (1 - 0.25), 2 / (1 - 0.09)]), rtol=1e-10)


def test_unstable_mode_without_process_noise_is_not_stabilisable():
    with pytest.raises(ValueError, match=r"\(F, Q\^\(1/2\)\).*not stabilisable.*eigenvalue 2"):
        _system([[2.0]], Q=[[0.0]], sensors=(Sensor(H=[[1.0]], R=[[1.0]]),))


def test_steady_state_of_an_undetectable_subset_names_the_subset():
    """Both sensors together see both random walks; each alone leaves one unseen."""
    a = Sensor(H=[[1.0, 0.0]], R=[[1.0]], name="a")
    b = Sensor(H=[[0.0, 1.0]], R=[[1.0]], name="b")
    system = _system(np.eye(2), sensors=(a, b), name="two-walks")
    steady_state(system)  # all sensors: fine
    with pytest.raises(ValueError, match=r"sensor subset \['a'\].*not detectable.*eigenvalue 1"):
        steady_state(system, np.array([True, False]))


def test_fixed_point_iteration_raises_with_its_residual_instead_of_returning_garbage():
    system = scenarios.get("ch3-static").system  # P -> 0 like 1/k: no convergence
    with pytest.raises(RuntimeError, match=r"did not converge.*50 iterations.*relative change"):
        steady_state_iterate(system, max_iter=50)
    system = scenarios.get("ch2-position").system
    P_pred, _, _ = steady_state_iterate(system)  # converges: agrees with the DARE
    np.testing.assert_allclose(P_pred, steady_state(system)[0], rtol=1e-9)


@pytest.mark.parametrize("huge", [MAX_HORIZON + 1, 10**9, 2**63])
def test_huge_horizon_or_max_cycles_is_rejected_with_the_bound(huge):
    """Regression: max_cycles=2**63 built the env, whose first step raised an IndexError."""
    with pytest.raises(ValueError, match=rf"horizon must be <= {MAX_HORIZON}.*max_cycles"):
        EpisodeSpec(horizon=huge)
    with pytest.raises(ValueError, match=rf"horizon must be <= {MAX_HORIZON}.*max_cycles"):
        detection_game_v0.parallel_env(scenario="ch3-static", max_cycles=huge)
    with pytest.raises(ValueError, match=rf"horizon must be <= {MAX_HORIZON}.*rounds"):
        sensor_game_v0.parallel_env(rounds=huge)
    assert EpisodeSpec(horizon=MAX_HORIZON).horizon == MAX_HORIZON


def test_huge_warmup_is_rejected_at_once_with_the_bound():
    start = time.perf_counter()
    with pytest.raises(ValueError, match=rf"warmup must be <= {MAX_WARMUP}.*use warmup='steady'"):
        EpisodeSpec(horizon=3, warmup=10**9)
    with pytest.raises(ValueError, match=f"warmup must be <= {MAX_WARMUP}"):
        detection_game_v0.parallel_env(scenario="ch3-tracking", warmup=10**9)
    assert time.perf_counter() - start < 30.0  # (it hung before; not a timing test)
    assert EpisodeSpec(horizon=3, warmup=MAX_WARMUP).warmup == MAX_WARMUP
    with pytest.raises(ValueError, match="warmup must be 'steady' or an integer"):
        EpisodeSpec(horizon=3, warmup="stead")


def test_the_systems_guide_states_the_warmup_bound_the_code_enforces():
    """The guide said MAX_WARMUP = 100 000 while the code refuses anything above 10 000."""
    import re
    from pathlib import Path

    guide = (Path(__file__).resolve().parent.parent / "docs/guide/systems.md").read_text()
    stated = re.findall(r"MAX_WARMUP = ([\d\s,_]+\d)", guide)
    assert stated, "docs/guide/systems.md no longer states MAX_WARMUP"
    assert [int(re.sub(r"[\s,_]", "", v)) for v in stated] == [MAX_WARMUP] * len(stated)
    with pytest.raises(ValueError, match=f"warmup must be <= {MAX_WARMUP}"):
        EpisodeSpec(horizon=3, warmup=MAX_WARMUP + 1)


# --- defect 3: clear errors ---------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"T": "x"}, r"LinearSystem\.T must be a positive number, got 'x'"),
        ({"T": 0.0}, r"LinearSystem\.T must be a finite number > 0"),
        ({"name": 3}, r"LinearSystem\.name must be a string"),
        ({"sensors": POS}, r"LinearSystem\.sensors must be a sequence of Sensor"),
        ({"x0": ["a", "b"]}, r"LinearSystem\.x0 must be a numeric vector"),
        ({"Q": "high"}, r"LinearSystem\.Q must be a numeric matrix"),
    ],
)
def test_bad_system_parameters_raise_naming_the_parameter(kwargs, message):
    args = {"F": np.eye(2), "Q": np.eye(2), "sensors": (POS,)} | kwargs
    with pytest.raises(ValueError, match=message):
        LinearSystem(**args)


def test_empty_transition_matrix_is_a_clear_error():
    with pytest.raises(ValueError, match=r"LinearSystem\.F must be a non-empty square matrix"):
        LinearSystem(F=[], Q=[], sensors=(POS,))
    with pytest.raises(ValueError, match=r"Sensor\.H must be a non-empty matrix"):
        Sensor(H=[], R=[])


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"seed": "x"}, r"seed must be an integer, got 'x'"),
        ({"seed": -1}, r"seed must be >= 0, got -1"),
        ({"seed": 1.5}, r"seed must be an integer"),
        ({"sigma_v": "a"}, r"sigma_v must be a positive number"),
        ({"bogus": 1}, r"does not take options \['bogus'\]; it takes \['seed', 'sigma_v'\]"),
    ],
)
def test_scenario_options_are_validated_with_their_names(kwargs, message):
    with pytest.raises(ValueError, match=message):
        scenarios.get("ch4-random", **kwargs)


def test_scalar_sigma_w_is_one_position_sensor_and_bad_types_are_named():
    one, listed = tracking_system(0.5, 3.0), tracking_system(0.5, [3.0])
    np.testing.assert_array_equal(one.R, listed.R)
    np.testing.assert_array_equal(one.H, listed.H)
    with pytest.raises(ValueError, match=r"sigma_w must be a number or a sequence"):
        tracking_system(0.5, "3.0")
    with pytest.raises(ValueError, match=r"sensors must be a sequence of Sensor"):
        tracking_system(0.5, sensors=pv_sensor(1.0, 1.0))
    with pytest.raises(ValueError, match=r"rho must be a number strictly between -1 and 1"):
        pv_sensor(1.0, 1.0, rho="0.5")
    with pytest.raises(ValueError, match=r"rho must lie strictly between -1 and 1, got nan"):
        pv_sensor(1.0, 1.0, rho=float("nan"))


# --- defect 4: read-only after pickling ----------------------------------------------------------


@pytest.mark.parametrize("clone", [lambda s: pickle.loads(pickle.dumps(s)), copy.deepcopy])
def test_cloned_systems_keep_read_only_arrays_and_their_values(clone):
    original = scenarios.get("ch5-game").system
    system = clone(original)
    arrays = {k: v for k, v in vars(system).items() if isinstance(v, np.ndarray)}
    assert {"F", "Q", "H", "R", "J", "P0", "x0", "Gu", "HtRinv", "row_sensor"} <= set(arrays)
    for name, value in arrays.items():
        assert not value.flags.writeable, name
        np.testing.assert_array_equal(value, getattr(original, name))
    for sensor in system.sensors:
        assert not sensor.H.flags.writeable and not sensor.R.flags.writeable
    with pytest.raises(ValueError, match="read-only"):
        system.F[0, 0] = 5.0
    np.testing.assert_allclose(steady_state(system)[0], steady_state(original)[0], rtol=1e-12)


def test_check_system_names_the_parameter_and_the_type_given():
    from fdia_env.scenarios import get
    from fdia_env.systems import check_system

    system = get("ch4-position").system
    assert check_system(system) is system
    with pytest.raises(ValueError, match="system_or_x must be a LinearSystem, got dict"):
        check_system({}, "system_or_x")


def test_scenario_default_reads_the_attribute_then_extra_and_names_what_is_missing():
    from baselines.detection.problem import static_problem
    from fdia_env.scenarios import get, scenario_default

    sc = get("ch3-static")
    assert scenario_default(sc, "p1", None) == sc.extra["p1"] == 0.85
    assert scenario_default(sc, "p1", 0.5) == 0.5
    assert static_problem(sc).p1 == 0.85  # the detection baseline's p1 comes from extra
    with pytest.raises(ValueError, match="budget is required: scenario 'ch3-static'"):
        scenario_default(sc, "budget", None)


def test_a_complex_array_is_refused_by_name_not_cast_to_its_real_part():
    """Regression: numpy cast a complex F or R to its real part with only a ComplexWarning."""
    from fdia_env._validation import as_float_array

    with pytest.raises(ValueError, match="F must be a numeric matrix, got a complex array"):
        LinearSystem(F=np.array([[1.0 + 0.5j]]), Q=[[1.0]], sensors=(Sensor([[1.0]], [[1.0]]),))
    with pytest.raises(ValueError, match="x must be a vector, got a complex array"):
        as_float_array("x", np.array([1.0, 2.0], dtype=np.complex128), "a vector")
    assert as_float_array("x", np.array([1, 2], dtype=np.int8), "a vector").dtype == np.float64
