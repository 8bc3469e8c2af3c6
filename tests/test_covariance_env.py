"""covariance_attack_v0: the action map, chapter-2 values through the env, sampled vs expected."""

import gymnasium as gym
import numpy as np
import pytest

from fdia_env import covariance_attack_v0, fdia_v0, scenarios
from fdia_env.kalman import steady_state
from fdia_env.systems import power_weight

# docs/references.md §2 (ch2-position, a² = 3000), as the literature prints them
CH2 = {
    "sensor 1": (np.diag([3000.0, 0.0]), 390.8),
    "sensor 2": (np.diag([0.0, 3000.0]), 220.5),
    "equal split": (np.diag([1500.0, 1500.0]), 305.7),
    "equal split, correlation 1": (1500.0 * np.ones((2, 2)), 597.7),
}


def single_injection(env, sigma):
    env.reset(seed=0)
    _, rewards, terms, _, infos = env.step({"attacker": env.attack.sigma_to_action(sigma)})
    assert terms["attacker"]
    return rewards["attacker"], infos["attacker"]


@pytest.mark.parametrize("name", sorted(CH2))
def test_chapter2_strategies_through_the_env(name):
    sigma, printed = CH2[name]
    value, info = single_injection(covariance_attack_v0.parallel_env(power=3000.0), sigma)
    assert round(value, 1) == printed
    assert info["power"] == pytest.approx(3000.0)


def test_dependent_rule_value_and_direct_core_formula():
    system = scenarios.get("ch2-position").system
    c = 1.0 / np.array([3.0, 4.0])
    c /= c.sum()
    s = c * np.sqrt(3000.0) / np.linalg.norm(c)  # σ_b,i = c_i a / ||c||, correlation 1
    sigma = np.outer(s, s)
    value, _ = single_injection(covariance_attack_v0.parallel_env(power=3000.0), sigma)
    assert round(value, 1) == 609.9
    _, P, W = steady_state(system)
    assert value == pytest.approx(np.trace(P + W @ sigma @ W.T), rel=1e-12)


@pytest.mark.parametrize("scenario", ["ch2-position", "ch2-pv-1", "ch2-pv-2", "ch4-pv-case1"])
@pytest.mark.parametrize("structure", ["full", "diagonal"])
def test_action_map_covers_the_constraint_set(scenario, structure):
    env = covariance_attack_v0.parallel_env(scenario=scenario, power=7.0, structure=structure)
    system, attack = env.system, env.attack
    omega = power_weight(system)
    rng = np.random.default_rng(0)
    for _ in range(50):  # every action maps to a PSD Σ with the exact power
        sigma, spent = attack.action_to_sigma(rng.uniform(-1, 1, attack.action_space.shape))
        assert np.trace(omega @ sigma) == pytest.approx(7.0, rel=1e-12) and spent == 7.0
        assert np.allclose(sigma, sigma.T) and np.linalg.eigvalsh(sigma).min() > -1e-12
        if structure == "diagonal":
            for i in range(system.M):
                rows = system.sensor_slice(i)
                off = np.delete(sigma[rows], np.arange(rows.start, rows.stop), axis=1)
                assert np.all(off == 0.0)
    for rank in (1, system.nz):  # every admissible Σ is reached (round trip)
        for _ in range(20):
            if structure == "full":
                A = rng.standard_normal((system.nz, rank))
                target = A @ A.T
            else:
                target = np.zeros((system.nz, system.nz))
                for i in range(system.M):
                    rows = system.sensor_slice(i)
                    A = rng.standard_normal(
                        (rows.stop - rows.start, min(rank, rows.stop - rows.start))
                    )
                    target[rows, rows] = A @ A.T
            target *= 7.0 / np.trace(omega @ target)
            action = attack.sigma_to_action(target)
            assert attack.action_space.contains(action)
            np.testing.assert_allclose(
                attack.action_to_sigma(action)[0], target, rtol=1e-5, atol=1e-6
            )


def test_zero_action_is_uniform_and_exact_power():
    env = covariance_attack_v0.parallel_env(scenario="ch2-pv-1", power=10.0)
    sigma, _ = env.attack.action_to_sigma(np.zeros(env.attack.action_space.shape))
    assert np.trace(power_weight(env.system) @ sigma) == pytest.approx(10.0)


def test_budget_mode_never_spends_more_than_the_power():
    env = covariance_attack_v0.parallel_env(power=100.0, power_mode="budget", horizon=5)
    env.reset(seed=0)
    rng = np.random.default_rng(1)
    spent = 0.0
    for _ in range(5):
        action = rng.uniform(-1, 1, env.action_space("attacker").shape).astype(np.float32)
        obs, _, _, _, infos = env.step({"attacker": action})
        spent += infos["attacker"]["power"]
        assert obs["attacker"][-1] == pytest.approx(
            infos["attacker"]["power_left"] / 100.0, rel=1e-6
        )
    assert spent <= 100.0 + 1e-9
    env.reset(seed=0)
    full_now = env.attack.sigma_to_action(np.eye(2), fraction=1.0)
    _, _, _, _, infos = env.step({"attacker": full_now})
    assert (
        infos["attacker"]["power"] == pytest.approx(100.0)
        and infos["attacker"]["power_left"] == 0.0
    )


def test_sampled_squared_error_agrees_with_expected_trace():
    """Continuous injection over 4 steps: the sampled error averages to tr M (4.5-sigma CI)."""
    kwargs = {"power": 3000.0, "horizon": 4, "reward_mode": "terminal"}
    sigma = 1500.0 * np.ones((2, 2))
    expected_env = covariance_attack_v0.parallel_env(**kwargs)
    expected_env.reset(seed=0)
    action = expected_env.attack.sigma_to_action(sigma)
    for _ in range(4):
        _, r, *_ = expected_env.step({"attacker": action})
    expected = r["attacker"]
    env = covariance_attack_v0.parallel_env(dynamics="sampled", **kwargs)
    env.reset(seed=11)
    samples = []
    for _ in range(3000):
        env.reset()
        for _ in range(4):
            _, r, *_ = env.step({"attacker": action})
        samples.append(r["attacker"])
    samples = np.array(samples)
    half = 4.5 * samples.std(ddof=1) / np.sqrt(samples.size)
    assert abs(samples.mean() - expected) < half < 0.15 * expected


def test_huge_power_over_many_steps_stays_finite_and_psd():
    env = covariance_attack_v0.parallel_env(
        scenario="ch2-pv-2", power=1e12, horizon=1000, reward_mode="per_step"
    )
    env.reset(seed=0)
    rng = np.random.default_rng(0)
    for _ in range(1000):
        action = rng.uniform(-1, 1, env.action_space("attacker").shape).astype(np.float32)
        _, r, *_ = env.step({"attacker": action})
        assert np.isfinite(r["attacker"])
    M = env.sim.M
    assert np.allclose(M, M.T, rtol=1e-12) and np.linalg.eigvalsh(M).min() > 0


def test_gym_view_and_fdia_v0_compose_the_same_env():
    genv = gym.make("fdia_env/CovarianceAttack-v0", power=3000.0)
    genv.reset(seed=0)
    action = genv.unwrapped.parallel.attack.sigma_to_action(np.diag([3000.0, 0.0]))
    assert round(genv.step(action)[1], 1) == 390.8
    env = fdia_v0.parallel_env(
        scenario="ch2-position", attack="covariance", defense="unaware", horizon=1
    )
    assert env.attack.power == 3000.0  # taken from the preset
    assert round(single_injection(env, np.diag([3000.0, 0.0]))[0], 1) == 390.8


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"power": 0.0}, r"power must satisfy 0 < power <= 1e\+300"),
        ({"power": -5.0}, r"power must satisfy 0 < power <= 1e\+300"),
        ({"power": float("nan")}, r"power must satisfy 0 < power <= 1e\+300"),
        ({"power": "high"}, r"power must be a number with 0 < power"),
        ({"structure": "banded"}, r"structure must be one of \['full', 'diagonal'\]"),
        ({"power_mode": "all"}, r"power_mode must be one of \['per_step', 'budget'\]"),
        (
            {"weight": np.eye(3)},
            r"weight must be an \(nz, nz\) = \(2, 2\) matrix matching the sensors",
        ),
        ({"weight": np.diag([1.0, -1.0])}, r"weight must be positive definite"),
        (
            {"scenario": "ch4-position"},
            r"power is required: scenario 'ch4-position' does not define one",
        ),
    ],
)
def test_bad_arguments_raise(kwargs, match):
    with pytest.raises(ValueError, match=match):
        covariance_attack_v0.parallel_env(**kwargs)


@pytest.mark.parametrize(
    ("action", "match"),
    [
        (np.array([np.nan, 0.0, 0.0], dtype=np.float32), "must be finite"),
        (np.array([2.0, 0.0, 0.0], dtype=np.float32), r"must lie in \[-1, 1\]"),
        (np.zeros(2, dtype=np.float32), r"shape \(3,\)"),
        ("big", r"shape \(3,\)"),
        (None, r"shape \(3,\)"),
    ],
)
def test_bad_actions_raise(action, match):
    env = covariance_attack_v0.parallel_env(power=3000.0)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=match):
        env.step({"attacker": action})
