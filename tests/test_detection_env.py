"""detection_game_v0: exact expected reward vs Monte Carlo, boundary cases, views, bad input."""

import gymnasium as gym
import numpy as np
import pytest
import scipy.stats

from fdia_env import detection_game_v0

P1 = 0.85


def play(env, attack, tau, seed=0):
    env.reset(seed=seed)
    defend = env.defense.threshold_to_action(tau)
    _, rewards, _, _, infos = env.step({"attacker": attack, "defender": defend})
    return rewards["attacker"], infos["attacker"]


def literature_attack(env):
    return detection_game_v0.default_opponent(env, "defender").predict(None)[0]


def monte_carlo(env, attack, tau, runs, seed):
    env.reset(seed=seed)
    defend = env.defense.threshold_to_action(tau)
    out = np.empty(runs)
    for i in range(runs):
        env.reset()
        _, rewards, *_ = env.step({"attacker": attack, "defender": defend})
        out[i] = rewards["attacker"]
    return out


CASES = [  # scenario, statistic, on_detect, threshold
    ("ch3-static", "quadratic", "discard", 1.5),
    ("ch3-static", "chi2", "incorporate", 5.99),
    ("ch3-tracking", "quadratic", "incorporate", 0.8),
    ("ch3-tracking", "chi2", "discard", 3.0),
]


@pytest.mark.parametrize(("scenario", "statistic", "on_detect", "tau"), CASES)
def test_expected_reward_equals_the_monte_carlo_mean_of_the_sampled_error(
    scenario, statistic, on_detect, tau
):
    kw = {"scenario": scenario, "power": 60.0, "statistic": statistic, "on_detect": on_detect}
    if scenario == "ch3-tracking":  # the steady prior P[K|K−1], without 99 sampled warm-up steps
        kw["warmup"] = "steady"
    expected_env = detection_game_v0.parallel_env(**kw)
    attack = literature_attack(expected_env)
    exact, info = play(expected_env, attack, tau)
    samples = monte_carlo(
        detection_game_v0.parallel_env(dynamics="sampled", **kw), attack, tau, 4000, seed=1
    )
    half = 4.5 * samples.std(ddof=1) / np.sqrt(samples.size)
    assert abs(samples.mean() - exact) < half < 0.15 * exact
    assert 0.0 <= info["p_false_alarm"] <= info["p_detection"] <= 1.0


def test_boundary_thresholds_give_closed_forms():
    env = detection_game_v0.parallel_env(scenario="ch3-static", power=100.0)
    attack = literature_attack(env)
    sigma2 = np.array([3.0, 4.0])
    c4 = float(np.sum(100 * sigma2 / (100 + sigma2)))  # clean LMMSE error, Pxx = 100 I
    c2 = c4 + 100.0 * (100.0 / 103.0) ** 2  # missed attack: Pbb = diag(100, 0)
    never, info = play(env, attack, np.inf)
    # 1e-7: the attacker's Σ travels through a float32 action (relative rounding ~6e-9)
    assert never == pytest.approx(P1 * c2 + (1 - P1) * c4, rel=1e-7)
    assert info["p_false_alarm"] == 0.0 and info["p_detection"] == 0.0
    always, info = play(env, attack, 0.0)  # always discard: the prior error tr Pxx
    assert always == pytest.approx(200.0, rel=1e-9)
    assert info["p_false_alarm"] == pytest.approx(1.0) and info["p_detection"] == pytest.approx(1.0)


def test_chi2_threshold_at_the_95_percent_quantile_has_5_percent_false_alarms():
    env = detection_game_v0.parallel_env(scenario="ch3-static", statistic="chi2")
    tau = scipy.stats.chi2.ppf(0.95, df=2)
    _, info = play(env, literature_attack(env), tau)
    assert info["p_false_alarm"] == pytest.approx(0.05, abs=1e-7)  # τ through a float32 action
    samples = []  # the sampled detector agrees: false alarms among clean rounds
    env = detection_game_v0.parallel_env(
        scenario="ch3-static", statistic="chi2", dynamics="sampled"
    )
    no_attack = env.attack.to_action(0.0, env.default_sigma)
    env.reset(seed=2)
    for _ in range(4000):
        env.reset()
        *_, infos = env.step(
            {"attacker": no_attack, "defender": env.defense.threshold_to_action(tau)}
        )
        samples.append(infos["attacker"]["detected"])
    rate = np.mean(samples)
    assert abs(rate - 0.05) < 4.5 * np.sqrt(0.05 * 0.95 / 4000)


def test_threshold_map_round_trips_and_spans_zero_to_infinity():
    env = detection_game_v0.parallel_env()
    det = env.defense
    for tau in (0.0, 0.3, 1.0, 7.5, 1e4):  # float32 actions: ~3e-4 relative at 1e4 thresholds
        got = det.action_to_threshold(det.threshold_to_action(tau))
        assert got == pytest.approx(tau, rel=1e-3, abs=1e-6)
    assert det.action_to_threshold(np.array([1.0])) == np.inf
    assert det.action_to_threshold(np.array([-1.0])) == 0.0


def test_gymnasium_views_have_fixed_default_opponents():
    env = gym.make("fdia_env/DetectionDefender-v0")
    env.reset(seed=0)
    _, reward, terminated, _, info = env.step(np.zeros(1, dtype=np.float32))
    assert terminated and reward < 0 and "p_detection" in info
    env = gym.make("fdia_env/DetectionAttacker-v0", dynamics="sampled")
    env.reset(seed=0)
    assert env.step(np.zeros(4, dtype=np.float32))[1] > 0


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"statistic": "likelihood"}, r"statistic must be one of \['chi2', 'quadratic'\]"),
        ({"on_detect": "ignore"}, r"on_detect must be one of \['discard', 'incorporate'\]"),
        (
            {"assumed_sigma": np.array([[1.0, 2.0], [2.0, 1.0]])},
            "assumed_sigma must be positive semi",
        ),
        ({"assumed_sigma": np.eye(3)}, r"assumed_sigma must be \(2, 2\)"),
        ({"power": -1.0}, r"power must satisfy 0 < power <= 1e\+300"),
        ({"scenario": "ch3-tracking", "horizon": 3}, "horizon must be 1 with dynamics='expected'"),
    ],
)
def test_bad_arguments_raise(kwargs, match):
    with pytest.raises(ValueError, match=match):
        detection_game_v0.parallel_env(**kwargs)


def test_bad_actions_raise():
    env = detection_game_v0.parallel_env()
    env.reset(seed=0)
    attack = literature_attack(env)
    with pytest.raises(ValueError, match="defender action must be finite"):
        env.step({"attacker": attack, "defender": np.array([np.nan], dtype=np.float32)})
    with pytest.raises(ValueError, match="threshold must not be NaN"):
        env.defense.threshold_to_action(float("nan"))
    with pytest.raises(ValueError, match=r"probability must lie in \[0, 1\]"):
        env.attack.to_action(1.5, env.default_sigma)
    env.reset(seed=0)
    with pytest.raises(ValueError, match="attacker action must be finite"):
        env.step({"attacker": np.array([np.nan, 0, 0, 0], dtype=np.float32), "defender": [0.0]})


@pytest.mark.parametrize("power", [220.0, 240.0, 260.0])
def test_threshold_sweep_under_the_bayes_cost_recovers_obdd_alpha(power):
    from baselines.detection import bayes_cost, expected_mse, obdd, static_problem

    detector = obdd(static_problem("ch3-static", power=power))
    env = detection_game_v0.parallel_env(scenario="ch3-static", power=power, criterion="bayes_cost")
    attack = literature_attack(env)
    step = 0.05
    taus = np.arange(0.0, 6.0, step)
    costs = [play(env, attack, t)[0] for t in taus]
    assert abs(taus[int(np.argmin(costs))] - detector.threshold) <= step  # the sweep's resolution
    at_alpha, _ = play(env, attack, detector.threshold)
    assert at_alpha == pytest.approx(bayes_cost(detector).value, rel=1e-7)
    mse_env = detection_game_v0.parallel_env(scenario="ch3-static", power=power)
    assert play(mse_env, attack, detector.threshold)[0] == pytest.approx(
        expected_mse(detector), rel=1e-7
    )  # and the env's exact true MSE equals the baseline's independent closed form


def test_sampled_bayes_cost_averages_to_the_expected_bayes_cost():
    kw = {"scenario": "ch3-static", "power": 240.0, "criterion": "bayes_cost"}
    env = detection_game_v0.parallel_env(**kw)
    attack = literature_attack(env)
    exact, _ = play(env, attack, 1.2)
    samples = monte_carlo(
        detection_game_v0.parallel_env(dynamics="sampled", **kw), attack, 1.2, 3000, seed=4
    )
    half = 4.5 * samples.std(ddof=1) / np.sqrt(samples.size)
    assert abs(samples.mean() - exact) < half < 0.15 * exact


@pytest.mark.parametrize(
    ("name", "statistic", "on_detect"),
    [("obdd", "quadratic", "discard"), ("obdi", "quadratic", "incorporate"),
     ("cbd", "quadratic", "discard"), ("csd", "chi2", "discard")],
)  # fmt: skip
@pytest.mark.parametrize("criterion", ["bayes_cost", "mse"])
def test_each_detector_as_a_policy_earns_its_own_cost(name, statistic, on_detect, criterion):
    import baselines.detection as bd

    detector = getattr(bd, name)(bd.static_problem("ch3-static", power=240.0))
    env = detection_game_v0.parallel_env(
        scenario="ch3-static",
        power=240.0,
        statistic=statistic,
        on_detect=on_detect,
        criterion=criterion,
    )
    env.reset(seed=0)
    defend = bd.as_policy(detector, env).predict(None)[0]
    _, rewards, *_ = env.step({"attacker": literature_attack(env), "defender": defend})
    expected = (
        bd.bayes_cost(detector).value if criterion == "bayes_cost" else bd.expected_mse(detector)
    )
    assert rewards["attacker"] == pytest.approx(expected, rel=1e-7)  # τ through a float32 action


def test_detector_policy_refuses_a_mismatched_env():
    import baselines.detection as bd

    detector = bd.csd(bd.static_problem("ch3-static", power=240.0))
    with pytest.raises(
        ValueError, match="statistic='chi2' but the env's defender uses 'quadratic'"
    ):
        bd.as_policy(detector, detection_game_v0.parallel_env())
