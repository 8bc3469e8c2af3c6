"""Hand-written regressions for the findings of the property suite (one test per finding)."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from prop_support import assert_psd, bounded

import baselines.covariance as cov
import baselines.detection as det
import baselines.game as game
import baselines.sparse as sparse
from fdia_env import (
    covariance_attack_v0,
    detection_game_v0,
    fdia_v0,
    scenarios,
    sensor_game_v0,
    sparse_attack_v0,
    tracking_system,
)
from fdia_env.detection_game_v0 import default_opponent
from fdia_env.episode import MAX_WARMUP, EpisodeSpec
from fdia_env.kalman import inv2
from fdia_env.systems import noise_factor, pbh_defects
from fdia_env.vector.env import MAX_NUM_ENVS

pytestmark = pytest.mark.filterwarnings("ignore")


@pytest.mark.parametrize("module", [sparse_attack_v0, covariance_attack_v0, detection_game_v0])
@pytest.mark.parametrize("warmup", [MAX_WARMUP + 1, 10**9, 2**63])
def test_huge_warmup_is_rejected_naming_warmup_instead_of_hanging(module, warmup):
    with bounded(5.0), pytest.raises(ValueError, match=rf"warmup must be <= {MAX_WARMUP}"):
        module.parallel_env(warmup=warmup)


def test_largest_warmup_still_builds():
    env = sparse_attack_v0.parallel_env(warmup=MAX_WARMUP)
    env.reset(seed=0)
    assert_psd(env.sim.P, "P after the longest warm-up")
    # the warm-up converged to the steady state the default start uses
    steady = sparse_attack_v0.parallel_env().sim.P_start
    np.testing.assert_allclose(env.sim.P_start, steady, rtol=1e-9)


@pytest.mark.parametrize("warmup", [np.zeros(0), np.array([1, 2]), "Steady", "x"])
def test_warmup_of_the_wrong_kind_names_warmup(warmup):
    with pytest.raises(ValueError, match="warmup must be"):
        EpisodeSpec(horizon=1, warmup=warmup)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"objective": np.zeros(0)},
        {"reward_mode": np.array(["terminal", "shaped"])},
        {"render_mode": np.zeros(0)},
        {"illegal_action": ["trim"]},
    ],
)
def test_array_for_a_choice_names_the_parameter(kwargs):
    (name,) = kwargs
    with pytest.raises(ValueError, match=rf"{name} must be one of"):
        sparse_attack_v0.parallel_env(**kwargs)


def test_budget_over_the_window_from_max_cycles_names_max_cycles():
    with pytest.raises(ValueError, match="budget must be <= M \\* horizon = 3") as info:
        sparse_attack_v0.parallel_env(max_cycles=1)  # the preset's budget is 5
    assert "max_cycles" in str(info.value) and "horizon = 1" in str(info.value)


@pytest.mark.parametrize(
    ("kwargs", "missing"),
    [
        ({"scenario": "ch3-tracking", "attack": "sparse", "horizon": 2}, "budget"),
        ({"scenario": "ch3-tracking", "attack": "covariance", "horizon": 2}, "power"),
        (
            {
                "scenario": "ch3-static",
                "attack": "probabilistic",
                "defense": "threshold_detector",
                "horizon": 1,
            },
            "assumed_sigma",
        ),
    ],
)
def test_fdia_v0_missing_model_parameter_names_the_kwargs(kwargs, missing):
    kind = "defense" if missing == "assumed_sigma" else "attack"
    kwargs.setdefault("attack_kwargs", {"power": 1.0} if kind == "defense" else None)
    with pytest.raises(ValueError, match=rf"{kind}_kwargs must give \['{missing}'\]"):
        fdia_v0.parallel_env(**kwargs)


def test_expected_tracking_horizon_from_max_cycles_names_max_cycles():
    with pytest.raises(ValueError, match="horizon must be 1 with dynamics='expected'") as info:
        detection_game_v0.parallel_env(scenario="ch2-position", max_cycles=2)
    assert "max_cycles" in str(info.value)


def test_sensor_game_on_vector_sensors_fails_at_construction_naming_scenario():
    with pytest.raises(ValueError, match="scenario 'ch2-pv-2' cannot host the subset attack"):
        sensor_game_v0.parallel_env(scenario="ch2-pv-2")


@pytest.mark.parametrize("num_envs", [MAX_NUM_ENVS + 1, 10**9, 2**63])
def test_huge_num_envs_is_rejected_naming_num_envs(num_envs):
    with bounded(5.0), pytest.raises(ValueError, match=rf"num_envs must be <= {MAX_NUM_ENVS}"):
        gym.make_vec(
            "fdia_env/SparseAttack-v0", num_envs=num_envs, vectorization_mode="vector_entry_point"
        )


@pytest.mark.parametrize("agent", ["defender", "x", None, 0, np.zeros(0)])
@pytest.mark.parametrize("vector", [False, True])
def test_wrong_agent_names_agent(agent, vector):
    with warnings.catch_warnings(), pytest.raises(ValueError, match=r"agent must be one of"):
        warnings.simplefilter("ignore")
        if vector:
            gym.make_vec(
                "fdia_env/CovarianceAttack-v0",
                num_envs=2,
                vectorization_mode="vector_entry_point",
                agent=agent,
            )
        else:
            gym.make("fdia_env/CovarianceAttack-v0", agent=agent)


# --- baselines.covariance ---------------------------------------------------------------------
@pytest.mark.parametrize("bad", [[], "x", object(), 1.5])
@pytest.mark.parametrize(
    "func",
    [
        cov.trace_optimal,
        cov.det_optimal,
        cov.independent_position_rule,
        cov.dependent_position_rule,
        cov.pv_single_sensor_rule,
        cov.equivalent_sensor,
        cov.make_problem,
    ],
)
def test_covariance_baselines_name_system_or_scenario(func, bad):
    with pytest.raises(ValueError, match="system_or_scenario"):
        func(bad)


@pytest.mark.parametrize(
    ("func", "scenario"),
    [
        (cov.pv_single_sensor_rule, "ch2-position"),
        (cov.independent_position_rule, "ch2-pv-2"),
        (cov.dependent_position_rule, "ch2-pv-1"),
    ],
)
def test_rule_on_the_wrong_sensors_names_system_or_scenario(func, scenario):
    with pytest.raises(ValueError, match=r"system_or_scenario: .* needs"):
        func(scenario)


@pytest.mark.parametrize("xi", [{"a": 1}, object(), "x", [1 + 2j]])
def test_water_filling_of_non_numbers_names_xi(xi):
    with pytest.raises(ValueError, match="xi must be"):
        cov.water_filling(xi, 1.0)


def test_multi_shot_huge_horizon_names_horizon():
    with bounded(5.0), pytest.raises(ValueError, match="horizon must be <= 10000"):
        cov.multi_shot("ch2-position", 3000.0, horizon=10**9)


@pytest.mark.parametrize(
    ("sigmas", "match"),
    [
        ("x", "sigmas must be an"),
        (np.full((1, 2, 2), np.nan), "sigmas must be finite"),
        (-np.ones((1, 2, 2)), r"sigmas\[0\] must be positive semidefinite"),
    ],
)
def test_recursion_objective_checks_sigmas(sigmas, match):
    with pytest.raises(ValueError, match=match):
        cov.recursion_objective("ch2-position", sigmas)


def test_recursion_objective_of_zero_bias_is_the_steady_trace():
    """Cross-check of the validated path: Σ = 0 keeps M = P, so the value is N·tr P / N."""
    value = cov.recursion_objective("ch2-position", np.zeros((3, 2, 2)))
    P = cov.make_problem("ch2-position").P
    assert value == pytest.approx(float(np.trace(P)), rel=1e-9)


# --- a known defect in code another worker owns -----------------------------------------------
def test_detection_game_error_covariance_psd_at_power_1e18():
    env = detection_game_v0.parallel_env(power=1e18)
    env.reset(seed=0)
    attack = default_opponent(env, "defender").predict(None)[0]
    obs, *_ = env.step({"attacker": attack, "defender": np.array([-1.0], np.float32)})
    assert_psd(env.sim.M, "M")
    assert np.all(np.isfinite(obs["attacker"]))


@pytest.mark.parametrize("power", [1e15, 1e18, 2.0**63, 1e30])
def test_det_optimal_logdet_stays_exact_at_huge_power(power):
    """log det(P + W Σ W') at a huge power: finite, and log(1 + a² g) of the rank-one optimum.

    ch2-position's optimum is rank one (two scalar sensors, one direction), so the value is
    ``log det P + log(1 + a² g)`` with g the top gain at unit power; the difference to the
    power 3000 value is therefore known in closed form. Forming P + W Σ W' first gave −inf
    from a² = 1e18 on (the small eigenvalue lost to round-off) and 31.5347 instead of 31.5010
    at 1e15.
    """
    ref = cov.det_optimal("ch2-position", 3000.0)
    result = cov.det_optimal("ch2-position", power)
    logdet_P = float(np.linalg.slogdet(ref.P)[1])
    g = np.expm1(ref.value - logdet_P) / 3000.0  # from the well-conditioned reference
    assert np.isfinite(result.value)
    assert result.value == pytest.approx(logdet_P + np.log1p(power * g), rel=1e-9)


# --- bad inputs to the sparse, game and detection baselines and the system builders ------------
@pytest.mark.parametrize("bad", [[], "x", object()])
@pytest.mark.parametrize(
    "func",
    [
        sparse.exhaustive,
        sparse.sfs,
        sparse.sbs,
        sparse.sfs_ss,
        sparse.dp,
        sparse.branch_and_bound,
        sparse.upper_bound,
        game.payoff_matrix,
        game.solve_double_oracle,
        game.make_game,
    ],
)
def test_sparse_and_game_baselines_name_system_or_scenario(func, bad):
    with pytest.raises(ValueError, match=r"^system_or_scenario: "):
        func(bad)


def test_sparse_make_problem_of_an_empty_list_names_system_or_scenario():
    with pytest.raises(ValueError, match=r"^system_or_scenario: scenario must be a preset name"):
        sparse.make_problem([], budget=1, horizon=1)


def test_unknown_preset_in_a_baseline_keeps_the_list_of_presets():
    with pytest.raises(ValueError, match=r"system_or_scenario: unknown scenario 'x'.*ch5-game"):
        game.payoff_matrix("x")


def test_attack_covariance_of_bytes_names_system():
    with pytest.raises(TypeError, match="system must be a LinearSystem, got bytes"):
        game.attack_covariance(system=b"x", subset=[0], power=1.0)


def test_strategy_bounds_of_an_array_player_names_player():
    with pytest.raises(ValueError, match="player must be 'defender' or 'attacker'"):
        game.strategy_bounds(L=[[1.0]], player=np.zeros(0))


def test_solve_bayesian_of_an_array_attacker_names_attacker():
    with pytest.raises(ValueError, match=r"attacker must be one of \['uninformed', 'informed'\]"):
        game.solve_bayesian([game.payoff_matrix("ch5-game")], [1.0], attacker=np.zeros(0))


@pytest.mark.parametrize("func", [det.obdd, det.obdi, det.cbd, det.csd, det.mmse])
@pytest.mark.parametrize("bad", [None, "ch3-static", object()])
def test_detector_of_a_non_problem_names_problem(func, bad):
    with pytest.raises(TypeError, match=r"problem must be a DetectionProblem .*got "):
        func(bad)


@pytest.mark.parametrize("func", [det.bayes_cost, det.expected_mse, det.detection_probabilities])
def test_evaluation_of_a_non_detector_names_detector(func):
    with pytest.raises(TypeError, match=r"detector must be a Detector .*got NoneType"):
        func(None)


def test_evaluation_against_a_non_problem_truth_names_truth():
    detector = det.obdd(det.static_problem("ch3-static", 100.0))
    with pytest.raises(TypeError, match="truth must be a DetectionProblem"):
        det.bayes_cost(detector, truth="ch3-static")


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"Pxx": object()}, "Pxx must be a numeric matrix"),
        ({"Pxx": -np.eye(2)}, "Pxx must be positive semidefinite"),
        ({"H": np.eye(3)}, r"H must have shape \(any, 2\)"),
        ({"Pww": np.zeros((2, 2))}, "Pww must be positive definite"),
        ({"power": -1.0}, r"power must satisfy 0 <= power <= 1e\+300, got -1.0"),
        ({"power": "x"}, "power must be a number"),
    ],
)
def test_c2_optimal_pbb_checks_each_input(kwargs, match):
    args = {"Pxx": np.eye(2), "H": np.eye(2), "Pww": np.eye(2), "power": 1.0, **kwargs}
    with pytest.raises(ValueError, match=match):
        det.c2_optimal_pbb(**args)


def test_c2_optimal_pbb_of_valid_inputs_is_unchanged():
    """Cross-check: a² u u' along the top eigenvector of G = K0' K0 (here K0 = diag(100/103,
    100/104), so the first axis)."""
    Pbb = det.c2_optimal_pbb(100 * np.eye(2), np.eye(2), np.diag([3.0, 4.0]), 50.0)
    np.testing.assert_allclose(Pbb, [[50.0, 0.0], [0.0, 0.0]], atol=1e-12)


@pytest.mark.parametrize(
    ("x", "weights", "match"),
    [
        (object(), np.array([1.0]), "x must be a real number or an array of real numbers"),
        (1.0, object(), "weights must be a real number or an array"),
        (1.0, "x", "weights must be"),
    ],
)
def test_gchisq_sf_of_non_numbers_names_the_parameter(x, weights, match):
    with pytest.raises(ValueError, match=match):
        det.gchisq_sf(x, weights)


@pytest.mark.parametrize(
    ("A", "cov", "match"),
    [
        (None, 1.0, "A must be finite"),
        (object(), 1.0, "A must be a numeric matrix"),
        (np.ones((2, 3)), np.eye(2), "A must be square"),
        (np.eye(3), np.eye(2), r"cov must have shape \(3, 3\)"),
        (np.eye(2), -np.eye(2), "cov must be positive semidefinite"),
    ],
)
def test_quadratic_form_weights_checks_a_and_cov(A, cov, match):
    with pytest.raises(ValueError, match=match):
        det.quadratic_form_weights(A, cov)


def test_quadratic_form_weights_of_valid_inputs():
    """Eigenvalues of L' A L with L L' = cov: for A = I they are cov's eigenvalues."""
    cov_ = np.array([[2.0, 1.0], [1.0, 2.0]])
    np.testing.assert_allclose(det.quadratic_form_weights(np.eye(2), cov_), [1.0, 3.0], rtol=1e-12)


@pytest.mark.parametrize("sensors", [np.zeros(2), [1.0], "z1"])
def test_tracking_system_of_a_non_sensor_sequence_names_sensors(sensors):
    with pytest.raises(ValueError, match="sensors must be a sequence of Sensor"):
        tracking_system(1.0, sensors=sensors)


def test_tracking_system_of_an_empty_array_of_sensors_names_sensors():
    """``sensors or ()`` asked an array for its truth value; an empty one is no sensor."""
    with pytest.raises(ValueError, match="tracking_system needs sigma_w or sensors"):
        tracking_system(1.0, sensors=np.zeros(0))
    # with sigma_w the empty array adds nothing: the same system as without it
    system = tracking_system(1.0, [2.0], sensors=np.zeros(0))
    assert system.M == 1 and system.R.tolist() == [[4.0]]


@pytest.mark.parametrize("name", ["x", [1], None, 3])
def test_scenarios_get_of_an_unknown_name_names_name(name):
    with pytest.raises(ValueError, match=r"unknown scenario .*\(name must be one of them\)"):
        scenarios.get(name)


@pytest.mark.parametrize(("sigma_v", "T"), [(1e10, 1.0), (1e6, 100.0), (1.0, 1e6)])
def test_pbh_noise_test_does_not_mistake_a_large_process_noise_for_none(sigma_v, T):
    """σ_v = 1e10 used to put the noise factor's scale on F's unit entries and report 'the
    marginal mode receives no process noise'; each block is now scaled on its own."""
    system = tracking_system(sigma_v, [1.0], T=T)
    bad = pbh_defects(system.F, noise_factor(system.Q), side="cols", unstable_only=False)
    assert bad == []


def test_pbh_noise_test_still_flags_a_noise_free_marginal_mode():
    bad = pbh_defects(np.eye(2), np.zeros((2, 2)), side="cols", unstable_only=False)
    assert len(bad) == 2


def test_pbh_tests_a_repeated_eigenvalue_once_and_keeps_its_multiplicity(monkeypatch):
    """The grids' F = I has one eigenvalue n times: one rank test (one SVD), not n; every copy
    of a failing eigenvalue is still reported, and distinct eigenvalues are each tested."""
    calls = []
    svd = np.linalg.svd

    def counted(*args, **kwargs):
        calls.append(1)
        return svd(*args, **kwargs)

    monkeypatch.setattr(np.linalg, "svd", counted)
    blind = np.eye(5)[:4]  # the fifth state is never measured
    assert pbh_defects(np.eye(5), blind, side="rows", unstable_only=False) == [1.0] * 5
    assert pbh_defects(np.eye(5), np.eye(5), side="rows", unstable_only=False) == []
    assert len(calls) == 2
    F = np.diag([1.0, 1.0, 1.5, 2.0])
    bad = pbh_defects(F, np.eye(4)[[0, 2]], side="rows", unstable_only=False)
    assert sorted(bad, key=abs) == [1.0, 1.0, 2.0] and len(calls) == 5  # 1, 1.5, 2: three tests


def test_inv2_of_nan_entries_returns_nan_instead_of_recursing():
    out = inv2(np.full((2, 2), np.nan))
    assert out.shape == (2, 2) and np.all(np.isnan(out))


def test_double_oracle_stopped_by_max_iter_reports_the_strategies_it_solved():
    """max_iter = 1 grew the restricted game after its last solve, so the strategies no longer
    matched the rows (``zip() argument 2 is shorter than argument 1``)."""
    with pytest.warns(RuntimeWarning, match="double oracle stopped after 1 iteration"):
        result = game.solve_double_oracle("ch5-game", max_iter=1)
    assert result.restricted_size == (1, 1)
    assert sum(result.defender.values()) == pytest.approx(1.0, abs=1e-12)
    assert result.lower <= result.value + 1e-9 <= result.upper + 2e-9


@pytest.mark.parametrize("horizon", [10_001, 2**63])
def test_sparse_problem_huge_horizon_names_horizon(horizon):
    """sbs(ch4-position, budget=horizon=2**63) raised numpy's 'Maximum allowed dimension
    exceeded', naming no parameter."""
    with bounded(5.0), pytest.raises(ValueError, match="horizon must be <= 10000"):
        sparse.sbs("ch4-position", budget=1, horizon=horizon)
