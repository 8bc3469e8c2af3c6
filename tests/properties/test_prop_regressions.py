"""Hand-written regressions for the findings of the property suite (one test per finding)."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from prop_support import assert_psd, bounded

import baselines.covariance as cov
from fdia_env import (
    covariance_attack_v0,
    detection_game_v0,
    fdia_v0,
    sensor_game_v0,
    sparse_attack_v0,
)
from fdia_env.detection_game_v0 import default_opponent
from fdia_env.episode import MAX_WARMUP, EpisodeSpec
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
