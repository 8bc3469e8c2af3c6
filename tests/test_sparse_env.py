"""sparse_attack_v0 behaviour: literature value, reward modes, budget rule, both compute paths."""

import gymnasium as gym
import numpy as np
import pytest

from fdia_env import scenarios, sparse_attack_v0
from fdia_env.attacks import trim_to_budget
from fdia_env.envs.simulation import Simulation
from fdia_env.kalman import information_update, predict_cov, steady_state

# docs/references.md §4: sensor 1 at K+3..K+6 and sensor 2 at K+6, ch4-position, N = 6
LITERATURE_PLAN = [0b000, 0b000, 0b001, 0b001, 0b001, 0b011]
TR_P_REFERENCE = 0.03278559152906327  # full precision; the literature prints 0.0328


def play(env, plan, seed=0):
    env.reset(seed=seed)
    rewards = []
    for a in plan:
        _, r, term, _, info = env.step({"attacker": a})
        rewards.append(r["attacker"])
    assert term["attacker"]
    return np.array(rewards), info["attacker"]


def test_literature_plan_reaches_reference_trace_in_env_and_core():
    env = sparse_attack_v0.parallel_env(scenario="ch4-position", budget=5, horizon=6)
    rewards, info = play(env, LITERATURE_PLAN)
    assert rewards[:-1].tolist() == [0.0] * 5
    assert rewards[-1] == pytest.approx(TR_P_REFERENCE, rel=1e-12)
    assert round(rewards[-1], 4) == 0.0328
    assert info["budget_left"] == 0

    system = scenarios.get("ch4-position").system
    P = steady_state(system)[1]
    for a in LITERATURE_PLAN:
        used = [(a >> i) & 1 == 0 for i in range(system.M)]
        P = information_update(predict_cov(P, system.F, system.Q), system.J, np.array(used))
    assert np.trace(P) == pytest.approx(TR_P_REFERENCE, rel=1e-12)


def test_gymnasium_view_returns_the_same_objective():
    env = gym.make("fdia_env/SparseAttack-v0", scenario="ch4-position", budget=5, horizon=6)
    env.reset(seed=0)
    total = sum(env.step(a)[1] for a in LITERATURE_PLAN)
    assert total == pytest.approx(TR_P_REFERENCE, rel=1e-12)


def test_reward_modes_sum_consistently():
    terminal, _ = play(sparse_attack_v0.parallel_env(reward_mode="terminal"), LITERATURE_PLAN)
    shaped, _ = play(sparse_attack_v0.parallel_env(reward_mode="shaped"), LITERATURE_PLAN)
    per_step, _ = play(sparse_attack_v0.parallel_env(reward_mode="per_step"), LITERATURE_PLAN)
    phi0 = float(np.trace(steady_state(scenarios.get("ch4-position").system)[1]))
    assert shaped.sum() == pytest.approx(terminal.sum() - phi0, rel=1e-12)
    assert per_step[-1] == pytest.approx(terminal[-1], rel=1e-12)
    assert np.all(np.diff(per_step) >= -1e-15)  # dropping measurements never lowers Φ here
    assert per_step.sum() == pytest.approx(np.cumsum(shaped).sum() + 6 * phi0, rel=1e-12)


def test_logdet_objective_matches_core():
    env = sparse_attack_v0.parallel_env(objective="logdet")
    rewards, _ = play(env, LITERATURE_PLAN)
    env_t = sparse_attack_v0.parallel_env()
    play(env_t, LITERATURE_PLAN)
    assert rewards[-1] == pytest.approx(np.linalg.slogdet(env_t.sim.P)[1], rel=1e-12)


@pytest.mark.parametrize("scenario", ["ch4-position", "ch4-pv-case1", "ch5-game"])
@pytest.mark.parametrize("objective", ["trace", "logdet"])
def test_closed_form_kernels_match_generic_numpy_path(scenario, objective):
    sc, spec = sparse_attack_v0.episode_spec(scenario, horizon=8, objective=objective)
    fast, generic = Simulation(sc.system, spec), Simulation(sc.system, spec, fast=False)
    rng = np.random.default_rng(1)
    for sim in (fast, generic):
        sim.reset(rng)
    from fdia_env.defenses.base import FilterInput

    for used in rng.integers(0, 2**sc.system.M, size=8):
        a, b = fast.step(FilterInput(int(used))), generic.step(FilterInput(int(used)))
        assert a == pytest.approx(b, rel=1e-12)
        np.testing.assert_allclose(fast.P, generic.P, rtol=1e-12)
        np.testing.assert_allclose(fast.features(), generic.features(), rtol=1e-10, atol=1e-12)


def test_over_budget_actions_are_trimmed_to_lowest_sensors_and_never_overspend():
    assert trim_to_budget(0b111, 2) == 0b011
    assert trim_to_budget(0b110, 1) == 0b010
    assert trim_to_budget(0b101, 0) == 0
    env = sparse_attack_v0.parallel_env(budget=4, horizon=6)
    env.reset(seed=0)
    spent = 0
    for _ in range(6):
        _, _, _, _, info = env.step({"attacker": 0b111})
        spent += int(info["attacker"]["attacked"].sum())
    assert spent == 4
    assert info["attacker"]["budget_left"] == 0


def test_action_mask_marks_exactly_the_subsets_within_budget():
    env = sparse_attack_v0.parallel_env(budget=2, horizon=6)
    obs, _ = env.reset(seed=0)
    sizes = np.array([bin(a).count("1") for a in range(8)])
    np.testing.assert_array_equal(obs["attacker"]["action_mask"], sizes <= 2)
    obs, *_ = env.step({"attacker": 0b001})
    np.testing.assert_array_equal(obs["attacker"]["action_mask"], sizes <= 1)
    obs, *_ = env.step({"attacker": 0b100})
    np.testing.assert_array_equal(obs["attacker"]["action_mask"], sizes == 0)


def test_sampled_mean_agrees_with_expected_trace():
    """The sampled squared error at K+N averages to tr P[K+N|K+N] (CLT interval, 4.5 sigma)."""
    env = sparse_attack_v0.parallel_env(dynamics="sampled")
    env.reset(seed=123)
    samples = []
    for _ in range(3000):
        env.reset()
        for a in LITERATURE_PLAN:
            _, r, *_ = env.step({"attacker": a})
        samples.append(r["attacker"])
    samples = np.array(samples)
    half_width = 4.5 * samples.std(ddof=1) / np.sqrt(samples.size)
    assert abs(samples.mean() - TR_P_REFERENCE) < half_width
    assert half_width < 0.15 * TR_P_REFERENCE  # sharp enough: the unattacked value is 62 % lower


def test_long_horizon_stays_finite_and_positive_definite():
    """10⁶ steps with random attacks (budget = every pair) keep P finite, symmetric and PD."""
    sc, spec = sparse_attack_v0.episode_spec("ch4-position", horizon=10**6)
    sim = Simulation(sc.system, spec)
    rng = np.random.default_rng(0)
    sim.reset(rng)
    from fdia_env.defenses.base import FilterInput

    used = rng.integers(0, 8, size=10**6)
    used[: 10**5] = 0  # a long blackout first: P grows like k³
    for u in used.tolist():
        sim.step(FilterInput(u))
    assert np.all(np.isfinite(sim.phi))
    P = sim.P
    assert np.allclose(P, P.T) and np.linalg.eigvalsh(P).min() > 0


def test_warmup_from_prior_converges_to_steady_state():
    env = sparse_attack_v0.parallel_env(warmup=500)
    env.reset(seed=0)
    P_ss = steady_state(scenarios.get("ch4-position").system)[1]
    np.testing.assert_allclose(env.sim.P, P_ss, rtol=1e-9)
