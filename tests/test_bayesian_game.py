"""The incomplete-information sensor game: sensor_game_v0(types=..., priors=...) and its reference.

Nature draws the attacker's allocation rule (its type) every episode; the defender never observes
it. The exact game is ``baselines.game.BayesianGame`` (one payoff matrix per type); its LP
equilibrium is the env's reference, and the reproduction's incomplete-information section
(docs/reproduction.md, priors 0.5 / 0.5 over the independent and dependent types) is what that
reference returns.
"""

import itertools
import math
import re
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import api_test, parallel_api_test

from agents.evaluate import evaluate
from agents.registry import get
from baselines.game import (
    BayesianGame,
    MixedStrategyPolicy,
    TypedMixedStrategyPolicy,
    bayesian_game,
    payoff_matrix,
    solve_zero_sum,
)
from experiments.reproduce.ch5 import CH5_PRIORS
from fdia_env import sensor_game_v0

TYPES = ("independent", "dependent")
MODELS = ("informed", "uninformed")
DOCS = Path(__file__).resolve().parents[1] / "docs" / "reproduction.md"


def matrices():
    return [payoff_matrix("ch5-game", allocation=t) for t in TYPES]


def typed_env(model="informed", priors=(0.5, 0.5), **kwargs):
    return sensor_game_v0.parallel_env(types=TYPES, priors=priors, attacker_model=model, **kwargs)


def pure_payoffs(env, forced):
    """(7, 7) attacker rewards of every pure pair with the type forced to ``forced``."""
    out = np.zeros((7, 7))
    for d, a in itertools.product(range(7), range(7)):
        env.reset(seed=3, options={"attacker_type": forced})
        _, rewards, *_ = env.step({"attacker": a, "defender": d})
        out[d, a] = rewards["attacker"]
        assert rewards["defender"] == -rewards["attacker"]
    return out


# --- payoffs through the env ----------------------------------------------------------------


@pytest.mark.parametrize("model", MODELS)
def test_env_payoff_of_every_pure_pair_is_each_types_matrix(model):
    env = typed_env(model)
    for s, L in enumerate(matrices()):
        np.testing.assert_allclose(pure_payoffs(env, s), L, rtol=1e-10, atol=0)
        np.testing.assert_allclose(pure_payoffs(env, TYPES[s]), L, rtol=1e-10, atol=0)


@pytest.mark.parametrize("priors", [(0.5, 0.5), (0.3, 0.7), (1.0, 0.0)])
def test_env_payoff_averaged_over_the_type_draw_is_the_bayesian_payoff_matrix(priors):
    # the average over nature's draw is exact: each type's payoff weighted by its prior
    env = typed_env("uninformed", priors)
    per_type = np.stack([pure_payoffs(env, s) for s in range(2)])
    through_env = np.tensordot(np.array(priors), per_type, axes=1)
    Ls = matrices()
    expected = priors[0] * Ls[0] + priors[1] * Ls[1]  # Σ_s p_s L_s[D, A]
    np.testing.assert_allclose(through_env, expected, rtol=1e-10, atol=0)
    game = bayesian_game("ch5-game", TYPES, priors)
    np.testing.assert_allclose(game.mean_payoff, expected, rtol=1e-12, atol=0)
    # the two types' games differ (else the test could not tell them apart)
    assert np.abs(Ls[0] - Ls[1]).max() > 1.0


def test_sampled_dynamics_use_the_drawn_types_bias():
    # D = A = z1z2z3: the squared error's mean is tr(M) = L_s[D, A], its variance 2 tr(M²)
    # (Gaussian error); 5 standard errors of N = 3000 episodes separate the two types
    env = typed_env("informed", dynamics="sampled")
    Ls = matrices()
    n = 3000
    for s in range(2):
        errors = np.empty(n)
        for i in range(n):
            env.reset(seed=i, options={"attacker_type": s})
            _, rewards, *_ = env.step({"attacker": 6, "defender": 6})
            errors[i] = rewards["attacker"]
        se = errors.std(ddof=1) / math.sqrt(n)
        assert abs(errors.mean() - Ls[s][6, 6]) < 5 * se, (s, errors.mean(), Ls[s][6, 6], se)
        other = Ls[1 - s][6, 6]
        assert abs(errors.mean() - other) > 5 * se  # the other type's payoff is ruled out


@pytest.mark.parametrize("dynamics", ["expected", "sampled"])
def test_type_frequencies_match_the_priors_within_a_binomial_tolerance(dynamics):
    # N resets with seeds 0..N−1: the count of type 0 is Binomial(N, p0) with standard deviation
    # sqrt(N p0 (1 − p0)) = 29.0 for N = 4000, p0 = 0.3; 4.5 of them (|Δ| ≤ 130, a chance of
    # ~7e-6 for a correct sampler) is the tolerance. Seeded, so the test is deterministic.
    n, p0 = 4000, 0.3
    env = typed_env("informed", (p0, 1 - p0), dynamics=dynamics)
    types = []
    for seed in range(n):
        obs, infos = env.reset(seed=seed)
        t = infos["attacker"]["type"]
        assert obs["attacker"][-2:].tolist() == [1.0 if s == t else 0.0 for s in range(2)]
        types.append(t)
    count = types.count(0)
    sd = math.sqrt(n * p0 * (1 - p0))
    assert abs(count - n * p0) <= 4.5 * sd, (count, n * p0, sd)
    # a prior of 0 is never drawn
    never = typed_env("informed", (0.0, 1.0), dynamics=dynamics)
    assert {never.reset(seed=s)[1]["attacker"]["type"] for s in range(200)} == {1}


def test_unseeded_resets_keep_drawing_types():
    env = typed_env("informed")
    env.reset(seed=0)
    draws = {env.reset()[1]["attacker"]["type"] for _ in range(60)}
    assert draws == {0, 1}  # the chance of one type only in 60 fair draws is 2 · 2**-60


# --- information: the defender never sees the type ---------------------------------------------


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("dynamics", ["expected", "sampled"])
def test_defender_observation_and_infos_do_not_depend_on_the_type(model, dynamics):
    env = typed_env(model, dynamics=dynamics, rounds=3)
    runs = []
    for s in range(2):
        obs, infos = env.reset(seed=21, options={"attacker_type": s})
        trace = [(obs["defender"].copy(), dict(infos["defender"]), obs["attacker"].copy())]
        # the attacker's subsets z1 then z2 avoid the defender's z3: no bias reaches the filter,
        # so nothing the defender sees can reveal the type through the outcome either
        for a in (0, 1, 0):
            obs, _, _, _, infos = env.step({"attacker": a, "defender": 2})
            trace.append((obs["defender"].copy(), dict(infos["defender"]), obs["attacker"]))
        runs.append(trace)
    for (d0, i0, a0), (d1, i1, a1) in zip(*runs, strict=True):
        np.testing.assert_array_equal(d0, d1)
        assert "type" not in i0 and sorted(i0) == sorted(i1)
        for key in i0:
            np.testing.assert_array_equal(i0[key], i1[key])
        if model == "informed":  # the attacker's differ exactly in the type's one-hot
            np.testing.assert_array_equal(a0[:-2], a1[:-2])
            assert a0[-2:].tolist() == [1.0, 0.0] and a1[-2:].tolist() == [0.0, 1.0]
        else:
            np.testing.assert_array_equal(a0, a1)
    # the attacker's infos carry the type
    _, infos = env.reset(seed=21, options={"attacker_type": 1})
    assert infos["attacker"]["type"] == 1 and "type" not in infos["defender"]


def test_spaces_of_the_typed_game():
    untyped = sensor_game_v0.parallel_env()
    for model in MODELS:
        env = typed_env(model)
        assert env.observation_space("defender") == untyped.observation_space("defender")
        assert env.action_space("attacker") == untyped.action_space("attacker")
        extra = 2 if model == "informed" else 0
        assert (
            env.observation_space("attacker").shape[0]
            == untyped.observation_space("attacker").shape[0] + extra
        )
    # the default (no types) is unchanged: no type entry, no type info
    _, infos = untyped.reset(seed=0)
    assert "type" not in infos["attacker"] and untyped.attack.allocation == "independent"


@pytest.mark.parametrize("model", MODELS)
def test_typed_game_passes_the_pettingzoo_and_gymnasium_checks(model):
    kwargs = {"types": TYPES, "priors": (0.4, 0.6), "attacker_model": model}
    parallel_api_test(sensor_game_v0.parallel_env(rounds=3, **kwargs), num_cycles=20)
    api_test(sensor_game_v0.env(rounds=3, **kwargs), num_cycles=20)
    for env_id in ("fdia_env/SensorGameAttacker-v0", "fdia_env/SensorGameDefender-v0"):
        env = gym.make(env_id, **kwargs)
        check_env(env.unwrapped, skip_render_check=True)
        obs, info = env.reset(seed=0)
        assert env.observation_space.contains(obs)
        assert ("type" in info) == env_id.endswith("Attacker-v0")


@pytest.mark.parametrize("model", MODELS)
@pytest.mark.parametrize("dynamics", ["expected", "sampled"])
def test_native_vector_env_equals_sync_vector_env_of_typed_games(model, dynamics):
    from test_vector import compare_with_sync

    kwargs = {"types": TYPES, "priors": (0.3, 0.7), "attacker_model": model, "rounds": 2}
    kwargs["dynamics"] = dynamics
    for env_id in ("fdia_env/SensorGameAttacker-v0", "fdia_env/SensorGameDefender-v0"):
        # the default uniform opponent draws per member, as each single env's
        compare_with_sync(env_id, kwargs, B=5, steps=9)


def test_vector_env_forced_type_and_type_infos():
    venv = gym.make_vec(
        "fdia_env/SensorGameAttacker-v0",
        num_envs=4,
        vectorization_mode="vector_entry_point",
        types=TYPES,
    )
    obs, info = venv.reset(seed=0, options={"attacker_type": "dependent"})
    assert info["type"].tolist() == [1, 1, 1, 1] and obs[:, -2:].tolist() == [[0, 1]] * 4
    defender = gym.make_vec(
        "fdia_env/SensorGameDefender-v0",
        num_envs=2,
        vectorization_mode="vector_entry_point",
        types=TYPES,
    )
    _, info = defender.reset(seed=0)
    assert "type" not in info


# --- the reference: the exact Bayesian game --------------------------------------------------


def reproduction_mix(label):
    """The defender mix printed by docs/reproduction.md's incomplete-information section."""
    text = DOCS.read_text(encoding="utf-8")
    line = re.search(rf"^{label} attacker: defender (.*?);", text, re.MULTILINE).group(1)
    value = float(re.search(rf"^{label} attacker: .*value ([0-9]+\.[0-9]+)", text, re.MULTILINE)[1])
    names = ["z1", "z2", "z3", "z1z2", "z1z3", "z2z3", "z1z2z3"]
    x = np.zeros(7)
    for name, p in re.findall(r"(z[0-9z]+) ([0-9.]+)", line):
        x[names.index(name)] = float(p)
    return x, value


@pytest.mark.parametrize(
    "model, label, literature_x, literature_value",
    [
        # docs/math.md §5's formulation (the defender's LP on Σ_s p_s L_s), the literature's game
        ("uninformed", "Uninformed", [0, 0, 0, 0, 0, 0.4543, 0.5457], 9.445039),
        ("informed", "Informed", [0, 0, 0, 0, 0, 0.4003, 0.5997], 9.727244),
    ],
)
def test_env_reference_is_the_reproductions_incomplete_information_strategy(
    model, label, literature_x, literature_value
):
    # the spec prints no incomplete-information table; the reproduction's section
    # (python -m experiments reproduce ch5, docs/reproduction.md) is the reference, printed to
    # 4 decimals for x (tolerance 5e-5) and 6 for the value (5e-7)
    kwargs = {"types": TYPES, "priors": CH5_PRIORS, "attacker_model": model}
    defender = get("sensor_game_v0", "defender")
    ref = defender.reference_of(defender.make(**kwargs))
    x = ref.policy.probs
    np.testing.assert_allclose(x, literature_x, atol=5e-5)
    assert abs(-ref.value - literature_value) < 5e-7
    doc_x, doc_value = reproduction_mix(label)
    np.testing.assert_allclose(x, doc_x, atol=5e-5)
    assert abs(-ref.value - doc_value) < 5e-7
    # and it is an equilibrium of the exact game, checked by hand on the matrices
    Ls, p = np.stack(matrices()), np.array(CH5_PRIORS)
    v = -ref.value
    if model == "uninformed":
        worst = float((x @ (p[0] * Ls[0] + p[1] * Ls[1])).max())
    else:
        worst = float(p @ (x @ Ls).max(axis=1))  # Σ_s p_s max_j (L_s' x)_j
    assert abs(worst - v) < 1e-9 * v
    attacker = get("sensor_game_v0", "attacker")
    y = attacker.reference_of(attacker.make(**kwargs)).policy.probs
    ys = np.tile(y, (2, 1)) if np.ndim(y) == 1 else y
    best_defence = float(np.einsum("s,sij,sj->i", p, Ls, ys).min())
    assert abs(best_defence - v) < 1e-9 * v


def test_uninformed_reference_is_the_zero_sum_game_on_the_mean_matrix():
    kwargs = {"types": TYPES, "priors": (0.3, 0.7), "attacker_model": "uninformed"}
    entry = get("sensor_game_v0", "attacker")
    ref = entry.reference_of(entry.make(**kwargs))
    Ls = matrices()
    L_bar = 0.3 * Ls[0] + 0.7 * Ls[1]
    np.testing.assert_allclose(ref.matrix_game(), L_bar, rtol=1e-12)
    assert abs(ref.value - solve_zero_sum(L_bar)[2]) < 1e-9 * ref.value
    informed = entry.reference_of(entry.make(**{**kwargs, "attacker_model": "informed"}))
    assert informed.payoff is None and informed.value > ref.value  # knowing the type helps
    with pytest.raises(ValueError, match="informed-attacker Bayesian game is not a matrix game"):
        informed.matrix_game()


@pytest.mark.parametrize("model", MODELS)
def test_evaluate_scores_a_defender_by_exploitability_against_the_bayesian_game(model):
    kwargs = {"types": TYPES, "priors": (0.5, 0.5), "attacker_model": model}
    Ls, p = np.stack(matrices()), np.array([0.5, 0.5])
    game = BayesianGame(Ls, p, model)
    v = game.value
    env = get("sensor_game_v0", "defender").make(**kwargs)
    uniform = np.full(7, 1 / 7)
    result = evaluate(MixedStrategyPolicy(uniform, seed=0), env, n_episodes=3, seed=0)
    if model == "uninformed":
        by_hand = float((uniform @ (0.5 * Ls[0] + 0.5 * Ls[1])).max()) - v
    else:
        by_hand = float(0.5 * (uniform @ Ls[0]).max() + 0.5 * (uniform @ Ls[1]).max()) - v
    assert result.score_name == "exploitability"
    assert abs(result.score - by_hand) < 1e-12 * v and by_hand > 1.0
    # the equilibrium defender is unexploitable; a pure one is not
    eq = evaluate(MixedStrategyPolicy(game.solution.x, seed=0), env, n_episodes=3, seed=0)
    assert abs(eq.score) < 1e-9 * v
    pure = evaluate(MixedStrategyPolicy(np.eye(7)[6], seed=0), env, n_episodes=1, seed=0)
    assert pure.score > 0.1


def test_evaluate_scores_an_informed_attacker_type_by_type():
    kwargs = {"types": TYPES, "priors": (0.5, 0.5), "attacker_model": "informed"}
    entry = get("sensor_game_v0", "attacker")
    env = entry.make(**kwargs)
    ref = entry.reference_of(env)
    Ls, p = np.stack(matrices()), np.array([0.5, 0.5])
    v = ref.value
    # the equilibrium per type is unexploitable
    eq = evaluate(ref.policy, env, n_episodes=2, seed=0)
    assert eq.strategy.shape == (2, 7) and abs(eq.score) < 1e-9 * v
    # a type-blind attacker (the independent type's best play for both) is exploitable
    blind = np.eye(7)[1]
    res = evaluate(TypedMixedStrategyPolicy([blind, blind], seed=0), env, n_episodes=2, seed=0)
    by_hand = v - float((p[0] * Ls[0] @ blind + p[1] * Ls[1] @ blind).min())
    assert abs(res.score - by_hand) < 1e-12 * v and by_hand > 1.0
    # a policy without probs: per-type frequencies of its first actions (types from the infos)
    played = evaluate("random", env, n_episodes=40, seed=0)
    assert played.strategy.shape == (2, 7)
    np.testing.assert_allclose(played.strategy.sum(axis=1), 1.0)


def test_typed_mixed_strategy_policy_plays_each_members_type():
    env = typed_env("informed", (0.5, 0.5))
    policy = TypedMixedStrategyPolicy([np.eye(7)[0], np.eye(7)[5]], seed=0)
    for seed in range(10):
        obs, infos = env.reset(seed=seed)
        action = int(policy.predict(obs["attacker"])[0])
        assert action == (0 if infos["attacker"]["type"] == 0 else 5)


def test_equilibrium_policies_played_in_the_env_average_to_the_value():
    # Monte Carlo over nature's draw and both mixes: 4000 episodes on the native vector env;
    # the mean return is within 4 standard errors of −v
    kwargs = {"types": TYPES, "priors": (0.5, 0.5), "attacker_model": "uninformed"}
    defender, attacker = get("sensor_game_v0", "defender"), get("sensor_game_v0", "attacker")
    a_ref = attacker.reference_of(attacker.make(**kwargs))
    env = defender.make(opponent=a_ref.policy, **kwargs)
    d_ref = defender.reference_of(env)
    result = evaluate(d_ref.policy, env, n_episodes=4000, seed=0, num_envs=1000)
    se = result.returns.std(ddof=1) / math.sqrt(result.n_episodes)
    assert abs(result.mean - d_ref.value) < 4 * se, (result.mean, d_ref.value, se)


# --- bad input ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"types": TYPES, "priors": (0.5,)}, r"priors must have one probability per type \(2\)"),
        ({"types": TYPES, "priors": (1.2, -0.2)}, r"priors must be finite and >= 0"),
        ({"types": TYPES, "priors": (0.5, 0.6)}, r"priors must sum to 1"),
        ({"types": TYPES, "priors": (0.5, float("nan"))}, r"priors must be finite"),
        ({"types": TYPES, "priors": "0.5 0.5"}, r"priors must be a sequence"),
        ({"types": TYPES, "priors": (True, False)}, r"priors must hold real numbers"),
        ({"priors": (0.5, 0.5)}, r"priors needs types"),
        ({"types": ("independent", "greedy")}, r"types\[1\] must be one of"),
        ({"types": ("dependent", "dependent")}, r"types must be distinct"),
        ({"types": ()}, r"types must be a non-empty sequence"),
        ({"types": "independent"}, r"types must be a non-empty sequence"),
        ({"types": TYPES, "allocation": "dependent"}, r"pass allocation .* or types"),
        ({"types": TYPES, "attacker_model": "partial"}, r"attacker_model must be one of"),
        ({"attacker_model": "uninformed"}, r"attacker_model='uninformed' needs types"),
        ({"attacker_model": "sneaky"}, r"attacker_model must be one of"),
    ],
)
def test_bad_typed_game_arguments_raise_naming_the_parameter(kwargs, message):
    with pytest.raises(ValueError, match=message):
        sensor_game_v0.parallel_env(**kwargs)


@pytest.mark.parametrize("forced", ["greedy", 2, -1, 1.0, True])
def test_bad_forced_type_raises(forced):
    env = typed_env()
    with pytest.raises(ValueError, match="attacker_type must be one of"):
        env.reset(seed=0, options={"attacker_type": forced})


def test_unknown_reset_option_still_warns_on_the_typed_game():
    env = typed_env()
    with pytest.warns(UserWarning, match=r"reset options \['type'\] are ignored: this env reads"):
        env.reset(seed=0, options={"type": 1})


def test_bayesian_game_bad_input():
    Ls = np.stack(matrices())
    with pytest.raises(ValueError, match="priors must sum to 1"):
        BayesianGame(Ls, [0.5, 0.6])
    with pytest.raises(ValueError, match="attacker must be one of"):
        BayesianGame(Ls, [0.5, 0.5], "psychic")
    with pytest.raises(ValueError, match="matrices must share one shape"):
        BayesianGame([Ls[0], Ls[1][:, :3]], [0.5, 0.5])
    game = BayesianGame(Ls, [0.5, 0.5], "uninformed")
    with pytest.raises(ValueError, match="y must be the same for every type"):
        game.exploitability(np.full(7, 1 / 7), np.eye(7)[[0, 1]])
    with pytest.raises(ValueError, match=r"y must have shape \(7,\) or \(2, 7\)"):
        game.exploitability(np.full(7, 1 / 7), np.ones((3, 7)) / 7)
    with pytest.raises(ValueError, match="probs must be an"):
        TypedMixedStrategyPolicy([0.5, 0.5])
    with pytest.raises(ValueError, match="observation must end with the 2-entry type one-hot"):
        TypedMixedStrategyPolicy(np.eye(2)).predict(np.zeros(1))


# --- train.py game on the typed game ---------------------------------------------------------


def test_psro_meta_payoff_is_exact_over_natures_draw():
    from agents.population import empirical_payoff

    kwargs = {"types": TYPES, "priors": [0.3, 0.7], "attacker_model": "uninformed"}
    entry = get("sensor_game_v0", "attacker")
    Ls = matrices()
    for d, a in ((6, 6), (5, 1), (0, 3)):
        attacker = MixedStrategyPolicy(np.eye(7)[a], seed=0)  # pure: deterministic
        defender = MixedStrategyPolicy(np.eye(7)[d], seed=0)
        got = empirical_payoff(attacker, defender, entry, kwargs, 1, seed=5)
        assert got == pytest.approx(0.3 * Ls[0][d, a] + 0.7 * Ls[1][d, a], rel=1e-10)


def test_game_command_on_the_uninformed_typed_game_scores_against_the_bayesian_game(tmp_path):
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # train.py at the root
    import train

    args = [
        "game", "--method", "psro", "--iterations", "2", "--steps-per-iteration", "64",
        "--n-steps", "64", "--batch-size", "32", "--n-epochs", "2", "--no-progress-bar",
        "--final-eval-episodes", "3", "--runs-root", str(tmp_path / "runs"), "--env-kwargs",
        "types", '["independent","dependent"]', "priors", "[0.5,0.5]",
        "attacker_model", "uninformed",
    ]  # fmt: skip
    result = train.main(args)
    game = bayesian_game("ch5-game", TYPES, (0.5, 0.5), "uninformed")
    assert result.value == pytest.approx(9.445039404, abs=1e-8)
    for h in result.history:  # every iteration scored exactly against the Bayesian game
        e = game.exploitability(h["x"], h["y"])
        assert h["nash_conv"] == pytest.approx(e.nash_conv, abs=1e-9)
        assert h["defender"] == pytest.approx(e.defender, abs=1e-9)
    informed = [*args[: args.index("uninformed")], "informed"]
    with pytest.raises(ValueError, match="informed-attacker Bayesian game is not a matrix game"):
        train.main(informed)


def test_bad_forced_type_leaves_the_running_episode_untouched():
    env = typed_env(rounds=3)
    env.reset(seed=0, options={"attacker_type": 1})
    env.step({"attacker": 6, "defender": 6})
    before = (list(env.agents), env.sim.k, env.attack.type_index, env.state().copy())
    with pytest.raises(ValueError, match="attacker_type must be one of"):
        env.reset(seed=1, options={"attacker_type": "greedy"})
    assert (list(env.agents), env.sim.k, env.attack.type_index) == before[:3]
    np.testing.assert_array_equal(env.state(), before[3])
    env.step({"attacker": 6, "defender": 6})  # the episode goes on


@pytest.mark.parametrize(
    ("matrices", "match"),
    [
        ([], "matrices must be a non-empty sequence of payoff matrices"),
        ("ab", "matrices must be a non-empty sequence of payoff matrices"),
        ([np.eye(2), np.ones((2, 3))], r"matrices\[1\] is \(2, 3\)"),
        ([np.eye(2), [[1.0, np.nan], [0.0, 1.0]]], r"matrices\[1\] must be finite"),
    ],
)
def test_the_game_and_its_solver_refuse_the_same_matrices_alike(matrices, match):
    from baselines.game.lp import solve_bayesian

    with pytest.raises(ValueError, match=match):
        BayesianGame(matrices, [0.5, 0.5])
    with pytest.raises(ValueError, match=match):
        solve_bayesian(matrices, [0.5, 0.5])


def test_the_game_of_a_typed_env_is_the_game_of_its_options_and_an_untyped_env_is_refused():
    from baselines.game import bayesian_game, bayesian_game_of
    from fdia_env import sensor_game_v0

    env = sensor_game_v0.parallel_env(
        types=("independent", "dependent"), priors=(0.3, 0.7), attacker_model="informed"
    )
    game = bayesian_game_of(env)
    direct = bayesian_game("ch5-game", ("independent", "dependent"), (0.3, 0.7), "informed")
    np.testing.assert_array_equal(game.matrices, direct.matrices)
    assert game.priors.tolist() == [0.3, 0.7] and game.attacker == "informed"
    assert game.value == pytest.approx(direct.value, abs=1e-12)
    with pytest.raises(ValueError, match="sensor_game_v0 env with types"):
        bayesian_game_of(sensor_game_v0.parallel_env())


@pytest.mark.parametrize("given", ["ch5-game", None, "gym"])
def test_the_game_of_anything_but_a_parallel_env_names_the_parameter(given):
    """Regression: a scenario name or a Gymnasium view raised a raw AttributeError."""
    import gymnasium as gym

    from baselines.game import bayesian_game_of

    if given == "gym":
        given = gym.make("fdia_env/SensorGameAttacker-v0", types=("independent", "dependent"))
        assert bayesian_game_of(given.unwrapped.parallel).types == ("independent", "dependent")
    with pytest.raises(ValueError, match="parallel must be a sensor_game_v0 parallel env"):
        bayesian_game_of(given)
