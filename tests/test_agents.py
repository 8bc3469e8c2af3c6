"""agents: the evaluation loop against the baselines, the registry, config and seeding."""

import gymnasium as gym
import numpy as np
import pytest
import scipy.stats
import torch

import fdia_env
from agents import registry
from agents.config import Hyperparameters, algo_kwargs, parse_env_kwargs
from agents.evaluate import evaluate, t_interval
from agents.seeding import seed_everything
from baselines.covariance import trace_optimal
from baselines.game import MixedStrategyPolicy, exploitability, payoff_matrix, solve_zero_sum
from baselines.sparse import dp, exhaustive


def test_evaluate_returns_the_exact_exs_value_for_its_policy():
    best = exhaustive("ch4-position", budget=5, horizon=6)
    result = evaluate(
        best.policy(), "fdia_env/SparseAttack-v0", n_episodes=3, scenario="ch4-position"
    )
    assert result.mean == pytest.approx(best.value, rel=1e-12)
    assert result.reference == pytest.approx(best.value, rel=1e-15)
    assert result.reference_name == "EXS"
    assert result.score == pytest.approx(1.0, rel=1e-12)
    assert result.ci95 == pytest.approx(0.0, abs=1e-15)  # expected dynamics: no noise


def test_evaluate_scores_a_suboptimal_heuristic_by_its_determinant_ratio():
    # ch4-pv-case2 (log-det objective): DP is a heuristic for a 2-D state and misses EXS
    best = exhaustive("ch4-pv-case2", objective="logdet")
    heuristic = dp("ch4-pv-case2", objective="logdet")
    result = evaluate(
        heuristic.policy(),
        "fdia_env/SparseAttack-v0",
        1,
        scenario="ch4-pv-case2",
        objective="logdet",
    )
    assert result.mean == pytest.approx(heuristic.value, rel=1e-12)
    assert result.reference == pytest.approx(best.value, rel=1e-15)
    assert result.score == pytest.approx(np.exp(heuristic.value - best.value), rel=1e-12)
    assert result.score < 1.0


def test_evaluate_returns_the_exact_trace_optimal_value_for_its_policy():
    env = gym.make("fdia_env/CovarianceAttack-v0", scenario="ch2-position", power=3000.0)
    best = trace_optimal("ch2-position", power=3000.0)
    result = evaluate(best.policy(env), env, n_episodes=2)
    assert result.mean == pytest.approx(best.value, rel=1e-12)
    assert result.reference == pytest.approx(best.value, rel=1e-15)
    assert result.score == pytest.approx(1.0, rel=1e-12)


@pytest.mark.parametrize("scenario", ["ch3-static", "ch3-tracking"])
def test_evaluate_returns_obdd_bayes_cost_for_its_threshold_policy(scenario):
    from baselines.detection import bayes_cost, obdd, static_problem, tracking_problem

    entry = registry.get("detection_game_v0", "defender")
    env = entry.view(scenario=scenario, **entry.scenarios[scenario])
    ref = entry.reference_of(env)
    power = entry.scenarios[scenario]["power"]
    make = static_problem if scenario == "ch3-static" else tracking_problem
    assert ref.value == pytest.approx(-bayes_cost(obdd(make(scenario, power=power))).value)
    result = evaluate(ref.policy, env, 2, 0, ref)
    assert result.mean == pytest.approx(ref.value, rel=1e-7)  # α through a float32 action
    assert result.score == pytest.approx(1.0, rel=1e-7)


def test_game_score_is_the_exploitability_of_the_policy_mix():
    L = payoff_matrix("ch5-game")
    _, y, value = solve_zero_sum(L)
    eq = evaluate(MixedStrategyPolicy(y, seed=0), "fdia_env/SensorGameAttacker-v0", 20)
    assert eq.score_name == "exploitability"
    assert eq.reference == pytest.approx(value)
    assert eq.score == pytest.approx(0.0, abs=1e-9)
    rand = evaluate("random", "fdia_env/SensorGameDefender-v0", 20)
    uniform = np.full(7, 1 / 7)
    assert rand.reference == pytest.approx(-value)  # the defender is paid −L
    assert rand.score == pytest.approx(exploitability(L, uniform, y, value).defender, rel=1e-12)
    # the uniform attacker the view plays by default: best response min_i (L u)_i
    assert rand.extras["best_response"] == pytest.approx(-(L @ uniform).min())


class RecordingPolicy:
    """Takes the largest legal subset; records the masks it was given."""

    def __init__(self):
        self.masks = []

    def predict(
        self, observation, state=None, episode_start=None, deterministic=True, action_masks=None
    ):
        self.masks.append(np.asarray(action_masks, dtype=bool))
        legal = np.flatnonzero(action_masks)
        return legal[np.argmax([bin(a).count("1") for a in legal])], state


def test_evaluate_passes_action_masks_to_policies_that_take_them():
    policy = RecordingPolicy()
    evaluate(policy, "fdia_env/SparseAttack-v0", n_episodes=1, budget=5, horizon=6)
    assert len(policy.masks) == 6
    assert policy.masks[0].all()  # a full budget: every subset of 3 sensors fits
    assert not policy.masks[-1].any() or policy.masks[-1].sum() < 8  # spent: masked


def test_random_policy_respects_the_budget_and_is_seeded():
    a = evaluate("random", "fdia_env/SparseAttack-v0", n_episodes=5, seed=3)
    b = evaluate("random", "fdia_env/SparseAttack-v0", n_episodes=5, seed=3)
    assert np.array_equal(a.returns, b.returns)
    assert 0 < a.score < 1


def test_t_interval_matches_scipy():
    r = np.array([1.0, 2.0, 4.0, 7.0])
    lo, hi = scipy.stats.t.interval(0.95, 3, loc=r.mean(), scale=scipy.stats.sem(r))
    assert t_interval(r) == pytest.approx((hi - lo) / 2, rel=1e-12)
    assert np.isnan(t_interval(np.array([1.0])))


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: registry.get("nope"), "sparse_attack_v0, covariance_attack_v0, sensor_game_v0"),
        (lambda: registry.get("sparse_attack_v0", "defender"), "learning defender: sensor_game"),
        (lambda: registry.get("sparse_attack_v0").env_kwargs("ch5-game"), "ch4-position, ch4-pv"),
        (lambda: registry.get("sparse_attack_v0").algorithm("SAC"), "MaskablePPO, PPO, A2C, DQN"),
        (lambda: registry.get("covariance_attack_v0").algorithm("xyz"), "SAC, PPO, A2C"),
        (lambda: algo_kwargs("SAC", Hyperparameters(n_epochs=3)), "applies to: PPO, MaskablePPO"),
    ],
)
def test_registry_errors_name_the_valid_choices(call, message):
    with pytest.raises(ValueError, match=message):
        call()


def test_registry_resolves_names_ids_and_algorithm_spellings():
    entry = registry.get("fdia_env/SensorGameDefender-v0", "defender")
    assert (entry.env, entry.agent) == ("sensor_game_v0", "defender")
    assert registry.get("sparse_attack_v0").algorithm("maskable_ppo") == "MaskablePPO"
    assert registry.game_names() == ["sensor_game_v0"]


def test_algo_kwargs_fill_per_algorithm_defaults():
    kw = algo_kwargs("PPO", Hyperparameters(learning_rate=3e-4, net_arch=(32,)))
    assert kw["n_steps"] == 512
    assert (kw["learning_rate"](1.0), kw["learning_rate"](0.5)) == (3e-4, 1.5e-4)  # linear
    assert algo_kwargs("DQN", Hyperparameters(learning_rate=3e-4))["learning_rate"] == 3e-4
    assert kw["policy_kwargs"] == {"net_arch": [32]}
    assert "buffer_size" not in kw
    assert parse_env_kwargs({"budget": "4", "allocation": "dependent"}) == {
        "budget": 4,
        "allocation": "dependent",
    }


def test_seed_everything_reproduces_numpy_and_torch():
    seed_everything(7)
    a = (np.random.rand(), torch.rand(1).item())  # noqa: NPY002 - the global it seeds
    seed_everything(7)
    assert (np.random.rand(), torch.rand(1).item()) == a  # noqa: NPY002
    with pytest.raises(ValueError, match="seed"):
        seed_everything(-1)


@pytest.mark.parametrize("module", ["config", "evaluate", "registry", "seeding"])
def test_docstring_examples_run(module):
    import doctest
    import importlib

    mod = importlib.import_module(f"agents.{module}")
    failed, attempted = doctest.testmod(mod, optionflags=doctest.ELLIPSIS)
    assert attempted > 0 and failed == 0


@pytest.mark.parametrize(
    ("env_id", "kwargs", "make_policy"),
    [
        ("fdia_env/SparseAttack-v0", {"dynamics": "sampled"},
         lambda env: exhaustive("ch4-position", 5, 6).policy()),
        ("fdia_env/CovarianceAttack-v0", {"dynamics": "sampled", "horizon": 3},
         lambda env: trace_optimal("ch2-position", 3000.0).policy(env)),
        ("fdia_env/DetectionDefender-v0",
         {"dynamics": "sampled", "criterion": "bayes_cost", "power": 240.0},
         lambda env: registry.get("detection_game_v0", "defender").reference_of(env).policy),
    ],
)  # fmt: skip
def test_batched_monte_carlo_evaluation_plays_the_same_episodes(env_id, kwargs, make_policy):
    env = registry.by_gym_id(env_id).view(**kwargs)
    policy = make_policy(env)
    one_by_one = evaluate(policy, env, 10, seed=3)
    batched = evaluate(policy, env, 10, seed=3, num_envs=4)  # rounds of 4, 4 and 2 episodes
    np.testing.assert_allclose(batched.returns, one_by_one.returns, rtol=1e-9, atol=1e-12)
    assert batched.mean == pytest.approx(one_by_one.mean, rel=1e-9)


def test_batched_random_policy_respects_masks():
    env = registry.get("sparse_attack_v0").view()
    result = evaluate("random", env, 64, seed=0, num_envs=32)
    assert result.returns.shape == (64,) and np.all(result.returns > 0)


@pytest.mark.parametrize("dynamics", ["expected", "sampled"])
@pytest.mark.parametrize("env_id", sorted(fdia_env.registration.kalman_gym_ids()))
def test_batched_evaluation_equals_sequential_for_every_id_with_default_opponents(env_id, dynamics):
    # the random policy and the views' default opponents (the sensor game's uniform mix
    # included) draw per episode, so episode i is the same in both loops
    kwargs = {"dynamics": dynamics}
    if "SensorGame" in env_id:
        kwargs["rounds"] = 3
    env = gym.make(env_id, **kwargs)
    one_by_one = evaluate("random", env, 7, seed=5)
    batched = evaluate("random", env, 7, seed=5, num_envs=3)  # rounds of 3, 3 and 1 episodes
    np.testing.assert_allclose(batched.returns, one_by_one.returns, rtol=1e-9, atol=1e-12)
    assert np.ptp(one_by_one.returns) > 0  # the episodes differ: the comparison can fail


def test_sparse_reference_past_exs_is_certified_by_branch_and_bound():
    from baselines.sparse.testbeds import mixed_tracking

    # C(84, 5) = 3.2e7 sets: past EXS_MAX_SETS, so branch and bound certifies the optimum
    env = gym.make("fdia_env/SparseAttack-v0", scenario=mixed_tracking(14), budget=5, horizon=6)
    ref = registry.sparse_reference(registry.parallel_of(env))
    assert ref.exact and ref.name == "B&B (certified optimum)" and ref.bound is None
    assert ref.value == pytest.approx(0.02056760660513471, rel=1e-9)
    assert ref.heuristic[0] == "SFS" and ref.heuristic[1] <= ref.value
    result = evaluate(ref.policy, env, 1, seed=0)
    assert result.score == pytest.approx(1.0, rel=1e-9)
    assert "of SFS" in result.score_text()


def test_sparse_reference_with_an_open_gap_brackets_the_score(monkeypatch):
    from baselines.sparse.testbeds import dc_grid14

    monkeypatch.setattr(registry, "BNB_TIME_LIMIT", 1.0)  # the gap stays open (300 pairs)
    env = gym.make("fdia_env/SparseAttack-v0", scenario=dc_grid14(50), budget=5, horizon=6)
    ref = registry.sparse_reference(registry.parallel_of(env))
    assert not ref.exact and ref.bound > ref.value
    result = evaluate("random", env, 20, seed=0)
    lower = result.extras["ratio_to_bound"]
    assert lower == pytest.approx(result.mean / ref.bound) and lower < result.score
    assert result.score_name == "ratio to best known"
    assert "of the optimum" in result.score_text() and "of SFS" in result.score_text()
