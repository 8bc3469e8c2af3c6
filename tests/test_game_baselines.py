"""Sensor-selection game baselines (docs/math.md §5, docs/references.md §5)."""

from __future__ import annotations

import itertools
import warnings

import numpy as np
import pytest
import scipy.linalg
import scipy.optimize
from hypothesis import given, settings
from hypothesis import strategies as st

from baselines.game import (
    MixedStrategyPolicy,
    attack_covariance,
    exploitability,
    make_game,
    payoff_matrix,
    solve_bayesian,
    solve_double_oracle,
    solve_zero_sum,
    strategy_bounds,
    to_nashpy,
    to_openspiel_matrix,
)
from experiments.reproduce.ch5 import CH5_CORRECTED_L, CH5_ERRATA
from fdia_env import scenarios
from fdia_env.attacks.subsets import subsets
from fdia_env.kalman import steady_state
from fdia_env.systems import pv_sensor, tracking_system

# Full precision, pinned after this implementation and an independent scipy DARE computation
# (test_ch5_payoff_agrees_with_an_independent_dare_computation) agreed to 2e-14.
PINNED_ROWS = {  # distinct columns z1, z2, z3 of each row
    0: (25.390625, 4.6875, 4.6875),
    1: (7.16573552147, 23.534783912526, 7.16573552147),
    2: (10.0, 10.0, 23.6),
    3: (13.533864775909, 6.600052072169, 3.390687335009),
    4: (16.414772677242, 3.747855673891, 5.389488117525),
    5: (4.972778426791, 12.422917840549, 8.024355530666),
    6: (10.197498276632, 5.224478963548, 3.865497713273),
}
VALUE_INDEPENDENT = 8.106030777100386
X_INDEPENDENT = (0.400302324266, 0.599697675734)  # on z2z3, z1z2z3
VALUE_DEPENDENT = 10.824816574559316


def spread_system(M: int):
    """Tracking system with M position sensors, σ_w spread over [1, 5]."""
    return tracking_system(0.5, list(np.linspace(1.0, 5.0, M)))


# --- payoff -------------------------------------------------------------------------------


def test_ch5_payoff_matches_literature_print_and_pinned_values():
    L = payoff_matrix("ch5-game")
    np.testing.assert_array_equal(np.round(L, 1), CH5_CORRECTED_L)
    for (row, col), value in CH5_ERRATA.items():  # printed 3.8
        assert L[row, col] == pytest.approx(value, abs=5e-4)
    for row, values in PINNED_ROWS.items():
        np.testing.assert_allclose(L[row, :3], values, rtol=1e-11)
    # columns z1, z1z2, z1z3, z1z2z3 all put the power on z1; z2 and z2z3 on z2
    np.testing.assert_array_equal(L[:, [3, 4, 6]], np.repeat(L[:, [0]], 3, axis=1))
    np.testing.assert_array_equal(L[:, 5], L[:, 1])


def test_ch5_payoff_agrees_with_an_independent_dare_computation():
    T, sigma, power = 1.0, np.array([3.0, 4.0, 5.0]), 100.0
    F = np.array([[1.0, T], [0.0, 1.0]])
    g = np.array([[T**2 / 2], [T]])
    Q = 0.25 * g @ g.T
    names = subsets(3)
    expected = {a: np.zeros((7, 7)) for a in ("independent", "dependent")}
    for r, D in enumerate(names):
        H = np.zeros((len(D), 2))
        H[:, 0] = 1.0
        R = np.diag(sigma[list(D)] ** 2)
        P_pred = scipy.linalg.solve_discrete_are(F.T, H.T, Q, R)
        S = H @ P_pred @ H.T + R
        K = P_pred @ H.T @ np.linalg.inv(S)
        P = P_pred - K @ S @ K.T
        for c, A in enumerate(names):
            one_hot = np.eye(3)[A[int(np.argmin(sigma[list(A)]))]]
            w = np.zeros(3)
            w[list(A)] = 1.0 / sigma[list(A)] ** 2
            for alloc, u in (("independent", one_hot), ("dependent", w / np.linalg.norm(w))):
                sig_d = power * np.outer(u, u)[np.ix_(D, D)]  # Σ_A restricted to A ∩ D
                expected[alloc][r, c] = np.trace(P + K @ sig_d @ K.T)
    for alloc, L in expected.items():
        np.testing.assert_allclose(payoff_matrix("ch5-game", allocation=alloc), L, rtol=1e-12)


@pytest.mark.parametrize("allocation", ["independent", "dependent"])
@pytest.mark.parametrize("seed", [0, 1])
def test_factorised_payoff_equals_direct_double_loop(allocation, seed):
    rng = np.random.default_rng(seed)
    M = 4
    system = tracking_system(rng.uniform(0.1, 1.0), list(rng.uniform(0.5, 5.0, M)))
    power = float(rng.uniform(1.0, 500.0))
    names = subsets(M)
    direct = np.zeros((len(names), len(names)))
    for r, D in enumerate(names):
        in_d = np.zeros(M, dtype=bool)
        in_d[list(D)] = True
        _, P, W = steady_state(system, in_d)
        for c, A in enumerate(names):
            sigma = attack_covariance(system, A, power, allocation) * np.outer(in_d, in_d)
            direct[r, c] = np.trace(P + W @ sigma @ W.T)  # tr(P_D + W_D Σ_{A∩D} W_D')
    np.testing.assert_allclose(payoff_matrix(system, power, allocation), direct, rtol=1e-12)


def test_attack_covariance_follows_prop2_and_prop3():
    system = scenarios.get("ch5-game").system
    sig = attack_covariance(system, (1, 2), 100.0, "independent")
    np.testing.assert_array_equal(sig, np.diag([0.0, 100.0, 0.0]))  # smallest σ_w of {z2, z3}
    sig = attack_covariance(system, (0, 1, 2), 100.0, "dependent")
    sd = np.sqrt(np.diag(sig))
    assert np.trace(sig) == pytest.approx(100.0, rel=1e-14)
    np.testing.assert_allclose(sig, np.outer(sd, sd), rtol=1e-14)  # correlation 1
    c = (1 / np.array([9.0, 16.0, 25.0])) / np.sum(1 / np.array([9.0, 16.0, 25.0]))
    np.testing.assert_allclose(sd, c * 10.0 / np.linalg.norm(c), rtol=1e-14)  # c_i a / ||c||


# --- equilibria ---------------------------------------------------------------------------


def test_ch5_equilibrium_value_and_unique_defender_strategy():
    L = payoff_matrix("ch5-game")
    x, y, value = solve_zero_sum(L)
    assert round(value, 3) == 8.106
    assert value == pytest.approx(VALUE_INDEPENDENT, rel=1e-12)
    np.testing.assert_array_equal(np.round(x, 2), [0, 0, 0, 0, 0, 0.40, 0.60])
    np.testing.assert_allclose(x[5:], X_INDEPENDENT, rtol=1e-10)
    # the attacker's equilibrium is not unique; the group totals are
    assert y[[0, 3, 4, 6]].sum() == pytest.approx(0.579437084825, rel=1e-10)
    assert y[[1, 5]].sum() == pytest.approx(0.420562915175, rel=1e-10)
    assert y[2] == 0.0
    # uniqueness of x: over the optimal set {x : L'x ≤ v 1, 1'x = 1, x ≥ 0}, min and max of
    # every coordinate coincide
    for j in range(7):
        for sign in (1.0, -1.0):
            c = np.zeros(7)
            c[j] = sign
            res = scipy.optimize.linprog(
                c,
                A_ub=L.T,
                b_ub=np.full(7, value + 1e-9),
                A_eq=np.ones((1, 7)),
                b_eq=[1.0],
                method="highs",
            )
            assert sign * res.fun == pytest.approx(x[j], abs=1e-6)
    low, high = strategy_bounds(L, "defender")
    np.testing.assert_allclose(low, x, atol=1e-7)
    np.testing.assert_allclose(high, x, atol=1e-7)
    low, high = strategy_bounds(L, "attacker", groups=[[0, 3, 4, 6], [1, 5], [2]])
    np.testing.assert_allclose(low, [0.579437084825, 0.420562915175, 0.0], atol=1e-7)
    np.testing.assert_allclose(high, [0.579437084825, 0.420562915175, 0.0], atol=1e-7)
    low, high = strategy_bounds(L, "attacker")  # but each column alone is not pinned down
    assert high[0] - low[0] > 0.5


def test_strategy_bounds_of_a_game_with_a_huge_payoff_are_those_of_its_rescaled_game():
    """Regression: a 1e300 payoff made HiGHS fail ("Model error", a RuntimeError).

    Rescaled to [0, 1] (the bounds are loose by ``rtol`` times the payoff range), the game is
    ``[[0, 0], [0, 0], [0, 0], [0, 1]]`` in float64: the defender never plays row 3 and mixes
    the other rows freely; every attacker mix is an equilibrium.
    """
    L = [[-1.124e-4, 1.2964e-3], [-9.147e-4, -1.0055e-3], [-8.542e-4, -6.998e-4], [-1e-3, 1e300]]
    low, high = strategy_bounds(L, "defender")
    np.testing.assert_allclose(low, [0.0, 0.0, 0.0, 0.0], atol=1e-7)
    np.testing.assert_allclose(high, [1.0, 1.0, 1.0, 0.0], atol=1e-7)
    low, high = strategy_bounds(L, "attacker")
    np.testing.assert_allclose(low, [0.0, 0.0], atol=1e-7)
    np.testing.assert_allclose(high, [1.0, 1.0], atol=1e-7)
    rescaled = [[0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 1.0]]
    for player in ("defender", "attacker"):
        np.testing.assert_allclose(
            strategy_bounds(L, player), strategy_bounds(rescaled, player), atol=1e-9
        )


def test_ch5_dependent_equilibrium():
    L = payoff_matrix("ch5-game", allocation="dependent")
    x, y, value = solve_zero_sum(L)
    assert value == pytest.approx(VALUE_DEPENDENT, rel=1e-12)
    np.testing.assert_allclose(x, [0, 0, 0, 0, 0, 0.500421339448, 0.499578660552], atol=1e-10)
    np.testing.assert_allclose(y, [0, 0, 0, 0, 0, 0.359774759486, 0.640225240514], atol=1e-10)


def test_rock_paper_scissors_equilibrium_is_uniform():
    rps = np.array([[0.0, 1.0, -1.0], [-1.0, 0.0, 1.0], [1.0, -1.0, 0.0]])
    x, y, value = solve_zero_sum(rps)
    np.testing.assert_allclose(x, np.full(3, 1 / 3), atol=1e-12)
    np.testing.assert_allclose(y, np.full(3, 1 / 3), atol=1e-12)
    assert value == pytest.approx(0.0, abs=1e-12)
    e = exploitability(rps, [1.0, 0.0, 0.0], y, value=0.0)
    assert (e.defender, e.nash_conv) == (pytest.approx(1.0), pytest.approx(1.0))


@st.composite
def random_games(draw):
    m, n = draw(st.integers(1, 7)), draw(st.integers(1, 7))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    L = rng.normal(draw(st.floats(-10, 10)), draw(st.floats(0.1, 10)), size=(m, n))
    if draw(st.booleans()):  # integer payoffs: ties and degenerate games
        L = np.round(L)
    return L


@settings(max_examples=60, deadline=None)
@given(random_games())
def test_lp_value_equals_nashpy_and_strategies_are_unexploitable(L):
    nashpy = pytest.importorskip("nashpy")
    assert nashpy  # only needed through to_nashpy
    x, y, value = solve_zero_sum(L)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        xn, yn = to_nashpy(L).linear_program()
    scale = max(1.0, np.abs(L).max())
    assert value == pytest.approx(float(xn @ L @ yn), abs=1e-7 * scale)
    e = exploitability(L, x, y, value)
    assert e.defender <= 1e-9 * scale and e.attacker <= 1e-9 * scale
    assert e.nash_conv <= 1e-9 * scale


def test_returned_ch5_strategies_have_exploitability_below_1e9():
    for allocation in ("independent", "dependent"):
        L = payoff_matrix("ch5-game", allocation=allocation)
        x, y, value = solve_zero_sum(L)
        e = exploitability(L, x, y)
        assert max(e.defender, e.attacker, e.nash_conv) <= 1e-9
        assert e.value == pytest.approx(value, rel=1e-12)


@pytest.mark.parametrize("allocation", ["independent", "dependent"])
def test_double_oracle_equals_full_lp(allocation):
    # every M from 2 to 10 (1,023 strategies each; the full LP takes ~1 s there)
    systems = [scenarios.get("ch5-game").system] + [spread_system(M) for M in range(2, 11)]
    for system in systems:
        L = payoff_matrix(system, 100.0, allocation)
        _, _, value = solve_zero_sum(L)
        result = solve_double_oracle(system, 100.0, allocation)
        assert result.value == pytest.approx(value, rel=1e-9)
        assert 0 <= result.gap + 1e-15 and result.gap <= 1e-9 * value
        assert result.lower <= value * (1 + 1e-12) and result.upper >= value * (1 - 1e-12)
        x, y = result.strategy("defender"), result.strategy("attacker")
        assert exploitability(L, x, y, value).nash_conv <= 1e-9 * value


def test_double_oracle_never_builds_the_full_matrix(monkeypatch):
    from baselines.game.payoff import SensorGame

    shapes = []
    original = SensorGame.payoff

    def spy(self, rows=None, cols=None):
        block = original(self, rows, cols)
        shapes.append(block.shape)
        return block

    monkeypatch.setattr(SensorGame, "payoff", spy)
    result = solve_double_oracle(spread_system(8), 100.0, "dependent")
    assert shapes and max(r * c for r, c in shapes) <= 255**2 // 100
    assert result.restricted_size == shapes[-1]


def test_double_oracle_result_plays_as_a_policy():
    result = solve_double_oracle("ch5-game")
    assert set(result.defender) == {(1, 2), (0, 1, 2)}
    policy = MixedStrategyPolicy.from_subsets(result.defender, 3, seed=0)
    np.testing.assert_allclose(policy.probs, result.strategy("defender"), atol=1e-15)


# --- incomplete information ---------------------------------------------------------------


def test_bayesian_game_models():
    Li = payoff_matrix("ch5-game")
    Ld = payoff_matrix("ch5-game", allocation="dependent")
    pure = solve_bayesian([Li, Ld], [1.0, 0.0])
    assert pure.value == pytest.approx(VALUE_INDEPENDENT, rel=1e-12)
    uninformed = solve_bayesian([Li, Ld], [0.5, 0.5])
    _, _, mean_value = solve_zero_sum(0.5 * (Li + Ld))
    assert uninformed.value == pytest.approx(mean_value, rel=1e-12)
    np.testing.assert_array_equal(uninformed.y[0], uninformed.y[1])
    informed = solve_bayesian([Li, Ld], [0.5, 0.5], attacker="informed")
    assert informed.value >= uninformed.value - 1e-12
    x = informed.x
    for s, L in enumerate((Li, Ld)):  # every type best-responds to x
        assert x @ L @ informed.y[s] == pytest.approx((x @ L).max(), rel=1e-9)
    # and x best-responds to the types' mixture
    mix = 0.5 * (Li @ informed.y[0] + Ld @ informed.y[1])
    assert x @ mix == pytest.approx(mix.min(), rel=1e-9)
    assert informed.value == pytest.approx(x @ mix, rel=1e-9)


# --- policy and interop -------------------------------------------------------------------


def test_mixed_strategy_policy_is_seeded_and_samples_its_probabilities():
    probs = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.4, 0.6])
    a = MixedStrategyPolicy(probs, seed=3)
    b = MixedStrategyPolicy(probs, seed=3)
    batch = np.zeros((20_000, 2))
    actions, state = a.predict(batch, deterministic=True)
    assert state is None and actions.dtype == np.int64 and actions.shape == (20_000,)
    np.testing.assert_array_equal(actions, b.predict(batch)[0])
    freq = np.bincount(actions, minlength=7) / actions.size
    np.testing.assert_allclose(freq, probs, atol=0.015)  # > 4 standard errors
    single, _ = a.predict({"observation": np.zeros(2), "action_mask": None})
    assert isinstance(single, np.int64) and single in (5, 6)
    assert a.mode() == 6
    a.reset(seed=3)
    np.testing.assert_array_equal(a.predict(batch)[0], actions)


def test_payoff_matrix_equals_sensor_game_env_rewards():
    from fdia_env import sensor_game_v0

    for allocation in ("independent", "dependent"):
        L = payoff_matrix("ch5-game", allocation=allocation)
        env = sensor_game_v0.parallel_env(scenario="ch5-game", allocation=allocation)
        for d, a in itertools.product(range(7), range(7)):
            env.reset(seed=0)
            _, rewards, *_ = env.step({"attacker": a, "defender": d})
            assert rewards["attacker"] == pytest.approx(L[d, a], rel=1e-12)
            assert rewards["defender"] == pytest.approx(-L[d, a], rel=1e-12)


def test_attack_covariance_equals_the_env_allocation_rule():
    from fdia_env.attacks.subset import allocation_covariance

    system = tracking_system(0.5, [2.0, 1.0, 3.0, 1.0, 4.0])  # a tie: sensors 2 and 4
    for allocation, A in itertools.product(("independent", "dependent"), subsets(5)):
        np.testing.assert_allclose(
            attack_covariance(system, A, 7.0, allocation),
            allocation_covariance(system, A, 7.0, allocation),
            rtol=1e-14,
            atol=1e-14,
        )


def test_equilibrium_attacker_policy_holds_the_defender_to_the_value():
    gym = pytest.importorskip("gymnasium")
    import fdia_env  # noqa: F401  (registers the ids)

    L = payoff_matrix("ch5-game")
    x, y, value = solve_zero_sum(L)
    env = gym.make("fdia_env/SensorGameDefender-v0", opponent=MixedStrategyPolicy(y, seed=1))
    for d in np.flatnonzero(x > 0):  # every support action of x earns exactly −v against y
        rewards = []
        for seed in range(1500):
            env.reset(seed=seed)
            rewards.append(env.step(int(d))[1])
        rewards = np.array(rewards)
        assert set(np.round(-rewards, 9)) <= set(np.round(L[d], 9))
        se = rewards.std() / np.sqrt(rewards.size)
        assert rewards.mean() == pytest.approx(-value, abs=5 * se)

    # seeded resets replay the opponent's draws
    def play(seed):
        env.reset(seed=seed)
        return env.step(5)[1]

    assert [play(seed) for seed in range(20)] == [play(seed) for seed in range(20)]


def test_interop_arguments():
    L = payoff_matrix("ch5-game")
    args = to_openspiel_matrix(L)
    assert args.row_action_names == ["z1", "z2", "z3", "z1z2", "z1z3", "z2z3", "z1z2z3"]
    assert args.col_action_names == args.row_action_names
    np.testing.assert_array_equal(args.row_utilities, -L)
    np.testing.assert_array_equal(args.col_utilities, L)
    assert len(args) == 6 and args.short_name == "fdia_sensor_game"
    pytest.importorskip("nashpy")
    A, B = to_nashpy(L).payoff_matrices
    np.testing.assert_array_equal(A, -L)
    np.testing.assert_array_equal(B, L)


# --- bad input ----------------------------------------------------------------------------


def test_bad_input_raises_value_error_naming_the_parameter():
    system = scenarios.get("ch5-game").system
    L = payoff_matrix("ch5-game")
    pv_system = tracking_system(0.5, sensors=[pv_sensor(1.0, 1.0)])
    cases = [
        ("subset", lambda: attack_covariance(system, (), 100.0)),
        ("subset", lambda: attack_covariance(system, (0, 3), 100.0)),
        ("power", lambda: attack_covariance(system, (0,), 0.0)),
        ("power", lambda: payoff_matrix("ch5-game", power=-1.0)),
        ("power", lambda: solve_double_oracle("ch5-game", power=0.0)),
        ("power", lambda: payoff_matrix("ch4-pv-case1")),
        ("allocation", lambda: payoff_matrix("ch5-game", allocation="greedy")),
        ("scalar sensors", lambda: payoff_matrix(pv_system, 1.0)),
        ("priors", lambda: solve_bayesian([L, L], [0.5, 0.6])),
        ("priors", lambda: solve_bayesian([L, L], [1.0])),
        ("matrices", lambda: solve_bayesian([L, L[:3]], [0.5, 0.5])),
        ("matrices", lambda: solve_bayesian([], [])),
        ("L", lambda: solve_zero_sum([[1.0, 2.0], [3.0]])),  # ragged
        ("L", lambda: solve_zero_sum(np.ones(3))),  # not 2-D
        ("L", lambda: solve_zero_sum(np.ones((2, 2, 2)))),
        ("L", lambda: solve_zero_sum(np.zeros((0, 3)))),
        ("L", lambda: solve_zero_sum([[1.0, np.nan]])),
        ("x", lambda: exploitability(L, np.ones(7), np.full(7, 1 / 7))),
        ("y", lambda: exploitability(L, np.full(7, 1 / 7), np.ones(3))),
        ("probs", lambda: MixedStrategyPolicy([0.5, 0.6])),
        ("probs", lambda: MixedStrategyPolicy([-0.5, 1.5])),
        ("tol", lambda: solve_double_oracle("ch5-game", tol=0.0)),
        ("M must be <= 13", lambda: payoff_matrix(spread_system(14), 1.0)),
        ("row_action_names", lambda: to_openspiel_matrix(L, row_action_names=["a"])),
    ]
    for name, call in cases:
        with pytest.raises(ValueError, match=name):
            call()


def test_game_model_builds_every_subset_once():
    game = make_game(spread_system(5), 10.0, "dependent")
    assert game.size == 31 and game.W.shape == (31, 2, 5)
    np.testing.assert_allclose(np.linalg.norm(game.U, axis=1), 1.0, rtol=1e-14)
    # the empty-intersection entries are tr P_D: sensor sets disjoint from the attack
    L = game.payoff()
    names = subsets(5)
    for r, c in itertools.product(range(31), range(31)):
        if not set(names[r]) & set(names[c]):
            assert L[r, c] == pytest.approx(game.trace_P[r], rel=1e-13)


def test_reproduce_ch5_quick_writes_its_section(tmp_path, capsys):
    from experiments import reproduce

    output = tmp_path / "reproduction.md"
    assert reproduce.main(["ch5", "--quick", "--output", str(output)]) == 0
    text = output.read_text()
    assert "## Chapter 5: sensor-selection game" in text
    assert "z2z3 0.4003, z1z2z3 0.5997" in text and "8.106031" in text
    assert text.count("**same**") == 2  # defender strategy and value against the literature
    assert (tmp_path / "figures" / "ch5_payoff_heatmap.png").stat().st_size > 10_000
    assert "Chapter 5" in capsys.readouterr().out
