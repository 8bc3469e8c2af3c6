"""sensor_game_v0: payoffs for every pure pair, allocation rules, repeated play, fixed opponents."""

import gymnasium as gym
import numpy as np
import pytest

from experiments.reproduce.ch5 import CH5_CORRECTED_L, CH5_ERRATA
from fdia_env import scenarios, sensor_game_v0
from fdia_env.attacks.subset import allocation_covariance
from fdia_env.attacks.subsets import subset_name, subsets
from fdia_env.envs.opponents import FixedMix
from fdia_env.kalman import steady_state


def env_payoffs(allocation):
    env = sensor_game_v0.parallel_env(allocation=allocation)
    n = env.action_space("attacker").n
    L = np.empty((n, n))
    for d in range(n):
        for a in range(n):
            env.reset(seed=0)
            _, rewards, terms, _, _ = env.step({"attacker": a, "defender": d})
            assert rewards["attacker"] == -rewards["defender"] and terms["attacker"]
            L[d, a] = rewards["attacker"]
    return L


def direct_payoffs(system, power, allocation):
    """tr(P_D + W_D Σ_{A∩D} W_D') from the core, one pair at a time."""
    subs = subsets(system.M)
    L = np.empty((len(subs), len(subs)))
    for i, D in enumerate(subs):
        mask = np.isin(np.arange(system.M), D)
        _, P, W = steady_state(system, mask)
        for j, A in enumerate(subs):
            sigma = allocation_covariance(system, A, power, allocation)
            sigma = sigma * np.outer(mask, mask)  # only A ∩ D reaches the filter
            L[i, j] = np.trace(P + W @ sigma @ W.T)
    return L


def test_env_payoffs_reproduce_the_literature_matrix():
    L = env_payoffs("independent")
    np.testing.assert_array_equal(np.round(L, 1), CH5_CORRECTED_L)
    for (row, col), value in CH5_ERRATA.items():  # the literature misprints them as 3.8
        assert L[row, col] == pytest.approx(value, abs=5e-4)


@pytest.mark.parametrize("allocation", ["independent", "dependent"])
def test_env_payoffs_equal_the_direct_formula(allocation):
    sc = scenarios.get("ch5-game")
    np.testing.assert_allclose(
        env_payoffs(allocation), direct_payoffs(sc.system, sc.power, allocation), rtol=1e-12
    )


def test_allocation_rules_spend_the_power_as_stated():
    system = scenarios.get("ch5-game").system
    ind = allocation_covariance(system, (1, 2), 100.0, "independent")
    assert ind[1, 1] == 100.0 and np.count_nonzero(ind) == 1  # sensor 2 has the smaller σ_w
    dep = allocation_covariance(system, (0, 1, 2), 100.0, "dependent")
    assert np.trace(dep) == pytest.approx(100.0)
    corr = dep / np.sqrt(np.outer(np.diag(dep), np.diag(dep)))
    np.testing.assert_allclose(corr, np.ones((3, 3)), rtol=1e-12)
    c = 1 / np.array([9.0, 16.0, 25.0])
    np.testing.assert_allclose(np.sqrt(np.diag(dep)) / np.sqrt(np.diag(dep)).sum(), c / c.sum())


def test_subset_order_is_by_size_then_lexicographic():
    assert [subset_name(s) for s in subsets(3)] == [
        "z1", "z2", "z3", "z1z2", "z1z3", "z2z3", "z1z2z3"
    ]  # fmt: skip


def test_repeated_rounds_show_each_player_the_others_last_subset():
    env = sensor_game_v0.parallel_env(rounds=3)
    obs, _ = env.reset(seed=0)
    assert obs["attacker"][-3:].tolist() == [0, 0, 0]
    obs, rewards, terms, _, _ = env.step({"attacker": 3, "defender": 5})  # A = z1z2, D = z2z3
    assert obs["attacker"][-3:].tolist() == [0, 1, 1]
    assert obs["defender"][-3:].tolist() == [1, 1, 0]
    assert not terms["attacker"]
    assert rewards["attacker"] == pytest.approx(CH5_CORRECTED_L[5, 3], abs=0.05)
    env.step({"attacker": 0, "defender": 0})
    *_, terms, _, _ = env.step({"attacker": 0, "defender": 0})
    assert terms["attacker"]


def test_sampled_payoff_averages_to_the_expected_payoff():
    env = sensor_game_v0.parallel_env(dynamics="sampled")
    env.reset(seed=5)
    samples = []
    for _ in range(4000):
        env.reset()
        _, r, *_ = env.step({"attacker": 1, "defender": 5})  # A = z2 leaks into D = z2z3
        samples.append(r["attacker"])
    samples = np.array(samples)
    half = 4.5 * samples.std(ddof=1) / np.sqrt(samples.size)
    expected = direct_payoffs(scenarios.get("ch5-game").system, 100.0, "independent")[5, 1]
    assert abs(samples.mean() - expected) < half < 0.15 * expected


def test_defender_view_against_a_fixed_mix():
    mix = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.4, 0.6])  # the literature's defender equilibrium
    env = gym.make("fdia_env/SensorGameAttacker-v0", opponent=FixedMix(mix))
    L = direct_payoffs(scenarios.get("ch5-game").system, 100.0, "independent")
    rewards = []
    env.reset(seed=3)
    for _ in range(3000):
        env.reset()
        rewards.append(env.step(0)[1])  # attack z1 against the mix
    assert np.mean(rewards) == pytest.approx(mix @ L[:, 0], rel=0.03)
    assert set(np.round(rewards, 6)) <= set(np.round(L[5:, 0], 6))


def test_fixed_mix_is_reproducible_and_validates():
    a, b = FixedMix([0.2, 0.3, 0.5], seed=1), FixedMix([0.2, 0.3, 0.5], seed=1)
    assert [a.predict(None)[0] for _ in range(50)] == [b.predict(None)[0] for _ in range(50)]
    draws = [FixedMix([0.0, 1.0]).predict(None)[0] for _ in range(20)]
    assert draws == [1] * 20
    with pytest.raises(ValueError, match="probs must sum to 1"):
        FixedMix([0.5, 0.6])
    with pytest.raises(ValueError, match="probs must be a non-empty vector of non-negative"):
        FixedMix([-0.5, 1.5])


def test_seeded_gym_view_episodes_are_reproducible():
    def run(seed):
        env = gym.make("fdia_env/SensorGameDefender-v0")  # uniform attacker by default
        env.reset(seed=seed)
        rewards = [env.step(6)[1]]
        for _ in range(30):
            env.reset()
            rewards.append(env.step(6)[1])
        return rewards

    assert run(4) == run(4)
    assert len(set(run(4))) > 1  # the opponent really mixes


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"allocation": "random"}, r"allocation must be one of \['independent', 'dependent'\]"),
        ({"power": 0.0}, r"power must satisfy 0 < power <= 1e\+300"),
        ({"rounds": 0}, r"rounds must be >= 1"),
        ({"scenario": "ch4-pv-case1", "power": 1.0}, r"defined for scalar sensors"),
    ],
)
def test_bad_arguments_raise(kwargs, match):
    with pytest.raises(ValueError, match=match):
        env = sensor_game_v0.parallel_env(**kwargs)
        env.reset(seed=0)
        env.step({"attacker": 0, "defender": 0})


def test_bad_actions_raise():
    env = sensor_game_v0.parallel_env()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"attacker action must be an integer in \[0, 7\)"):
        env.step({"attacker": 7, "defender": 0})
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"defender action must be an integer in \[0, 7\)"):
        env.step({"attacker": 0, "defender": -1})
