"""Sparse-attack solvers played as policies in ``sparse_attack_v0`` reproduce their own value."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest
from conftest import attacker_return
from hypothesis import given, settings
from hypothesis import strategies as st

import fdia_env  # noqa: F401  (registers the Gymnasium ids)
from baselines.sparse import SOLVERS, SparsePolicy, sfs
from fdia_env import sparse_attack_v0
from fdia_env.systems import pv_sensor, tracking_system

RTOL = 1e-12


def play_parallel(policy, **env_kwargs) -> float:
    """Episode return of ``policy`` in the parallel env (terminal reward = Φ(P[K+N|K+N]))."""
    return attacker_return(
        sparse_attack_v0.parallel_env(reward_mode="terminal", **env_kwargs), policy
    )


def play_gymnasium(policy, **env_kwargs) -> float:
    """Episode return of ``policy`` through ``gymnasium.make`` (plain Box observations)."""
    env = gymnasium.make("fdia_env/SparseAttack-v0", **env_kwargs)
    obs, _ = env.reset(seed=0)
    total, done = 0.0, False
    while not done:
        action, _ = policy.predict(obs, deterministic=True)
        obs, reward, terminated, truncated, _ = env.step(action)
        total += reward
        done = terminated or truncated
    return total


@pytest.mark.parametrize("name", list(SOLVERS))
@pytest.mark.parametrize("horizon", [6, 10])
def test_policy_return_equals_solver_value_in_parallel_env(name, horizon):
    result = SOLVERS[name]("ch4-position", budget=5, horizon=horizon)
    ret = play_parallel(result.policy(), scenario="ch4-position", budget=5, horizon=horizon)
    assert abs(ret - result.value) <= RTOL * abs(result.value)


@pytest.mark.parametrize("name", list(SOLVERS))
def test_policy_return_equals_solver_value_through_gymnasium_make(name):
    result = SOLVERS[name]("ch4-position", budget=5, horizon=6)
    ret = play_gymnasium(result.policy(), scenario="ch4-position", budget=5, horizon=6)
    assert abs(ret - result.value) <= RTOL * abs(result.value)


@pytest.mark.parametrize("case", [1, 2, 3])
@pytest.mark.parametrize("name", list(SOLVERS))
def test_policy_return_equals_solver_value_with_logdet_on_pv_cases(name, case):
    scenario = f"ch4-pv-case{case}"
    result = SOLVERS[name](scenario, budget=5, horizon=6, objective="logdet")
    ret = play_parallel(result.policy(), scenario=scenario, budget=5, horizon=6, objective="logdet")
    assert abs(ret - result.value) <= RTOL * abs(result.value)


@st.composite
def small_systems(draw):
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    M = draw(st.integers(1, 3))
    if draw(st.booleans()):
        return tracking_system(rng.uniform(0.01, 1.0), list(rng.uniform(0.05, 2.0, M))), "trace"
    sensors = [pv_sensor(*rng.uniform(0.1, 1.0, 2), rng.uniform(-0.8, 0.8)) for _ in range(M)]
    return tracking_system(rng.uniform(0.001, 0.5), sensors=sensors), "logdet"


@settings(max_examples=20, deadline=None)
@given(small_systems(), st.integers(1, 4), st.data())
def test_policies_reproduce_values_on_random_problems(system_and_objective, horizon, data):
    system, objective = system_and_objective
    budget = data.draw(st.integers(0, min(4, system.M * horizon)))
    for name, solver in SOLVERS.items():
        result = solver(system, budget, horizon, objective)
        ret = play_parallel(
            result.policy(), scenario=system, budget=budget, horizon=horizon, objective=objective
        )
        assert abs(ret - result.value) <= RTOL * max(abs(result.value), 1e-300), name


def test_predict_reads_the_step_from_dict_box_and_batched_observations():
    result = sfs("ch4-position", budget=5, horizon=6)
    policy = result.policy()
    np.testing.assert_array_equal(result.actions(), [0, 0, 1, 1, 1, 3])
    box = np.zeros((6, 5), dtype=np.float32)
    box[:, 0] = (6 - np.arange(6)) / 6  # steps left / N at steps 0..5
    for k in range(6):
        assert policy.predict(box[k])[0] == result.actions()[k]
        as_dict = {"observation": box[k], "action_mask": None}
        assert policy.predict(as_dict)[0] == result.actions()[k]
    actions, state = policy.predict(box, state="kept")
    np.testing.assert_array_equal(actions, result.actions())
    assert state == "kept"
    assert policy.predict(np.zeros(5, dtype=np.float32))[0] == 0  # terminal observation


def test_policy_rejects_bad_plans():
    with pytest.raises(ValueError, match="actions"):
        SparsePolicy([])
    with pytest.raises(ValueError, match="actions"):
        SparsePolicy([0, -1])


@pytest.mark.parametrize("action", ["bitmask", "multibinary", "sequential"])
def test_policy_plays_in_the_envs_own_action_format(action):
    """``result.policy(action)`` returns the solver's value in each format a plan plays in."""
    best = SOLVERS["exs"]("ch4-position", budget=4, horizon=5)
    policy = best.policy(action)
    total = play_parallel(policy, scenario="ch4-position", budget=4, horizon=5, action=action)
    np.testing.assert_allclose(total, best.value, rtol=RTOL)


def test_policy_refuses_formats_a_plan_cannot_play_in():
    best = sfs("ch4-position", budget=3, horizon=4)
    with pytest.raises(ValueError, match=r"action must be one of .*'single'"):
        best.policy("single")
    with pytest.raises(ValueError, match="action must be one of"):
        best.policy("bits")
    big = sfs("grid-ieee14", budget=2, horizon=2)
    with pytest.raises(ValueError, match="action='bitmask' takes at most 16 sensors"):
        big.policy("bitmask")


def test_training_reference_plays_in_the_envs_format():
    """The EXS row of ``train.py attacker`` is scored in the env's format (MultiBinary here)."""
    from agents import registry
    from agents.evaluate import evaluate

    env = gymnasium.make(
        "fdia_env/SparseAttack-v0",
        scenario="ch4-position",
        budget=4,
        horizon=5,
        action="multibinary",
    )
    ref = registry.sparse_reference(registry.parallel_of(env))
    assert ref is not None and ref.policy is not None
    result = evaluate(ref.policy, env, 2, 0, ref)
    np.testing.assert_allclose(result.mean, ref.value, rtol=1e-9)
    np.testing.assert_allclose(result.score, 1.0, rtol=1e-9)
