"""The detection game's exact best responses and the ``detection_learned`` result table."""

import dataclasses
import json

import numpy as np
import pytest

from baselines.detection import (
    bayes_cost,
    detection_probabilities,
    monte_carlo,
    obdd,
    static_problem,
    tracking_problem,
)
from baselines.detection.response import (
    DetectionGame,
    best_attack,
    best_threshold,
    minimax_threshold,
)
from experiments import results
from experiments.results import detection_learned as dl
from experiments.results.detection_learned_report import format_tables
from fdia_env import detection_game_v0

CSD_TAU = 5.991464547107979  # χ²₂ at 95 %


def step_reward(env, attack, defend):
    """The attacker's reward of one step of the parallel env."""
    env.reset(seed=0)
    _, rewards, *_ = env.step({"attacker": attack, "defender": defend})
    return rewards["attacker"]


def test_mse_optimal_threshold_beats_obdd_and_is_the_env_reward():
    env = detection_game_v0.parallel_env(scenario="ch3-static", power=1000.0, criterion="mse")
    game = DetectionGame.of(env)
    best = best_threshold(game, game.preset_probability, game.preset_sigma)
    preset = game.attack_action(game.preset_probability, game.preset_sigma)
    # OBDD's α < 0: it always discards, so its error is tr P0 = 200 whatever the attack
    alpha = obdd(static_problem("ch3-static", 1000.0)).threshold
    obdd_value = -game.attacker_reward(game.preset_probability, game.preset_sigma, alpha)
    assert alpha < 0 and obdd_value == pytest.approx(-200.0, rel=1e-12)
    # the true-MSE optimum is a finite threshold, 31 units (15.6 %) better than OBDD's α
    assert best.threshold == pytest.approx(1.875, abs=0.01)
    assert best.value == pytest.approx(-168.8675, rel=1e-5)
    assert best.value >= obdd_value + 30.0
    assert best.value >= best.grid_values.max() - 1e-12  # the refinement never loses
    assert -step_reward(env, preset, best.action) == pytest.approx(best.value, rel=1e-7)


def test_bayes_cost_optimal_threshold_is_obdd_alpha():
    # a² = 240: OBDD's α is finite and positive (α = 1.2698), the optimum of the Bayes cost
    env = detection_game_v0.parallel_env(scenario="ch3-static", power=240.0, criterion="bayes_cost")
    game = DetectionGame.of(env)
    best = best_threshold(game, game.preset_probability, game.preset_sigma)
    detector = obdd(static_problem("ch3-static", 240.0))
    assert best.value == pytest.approx(-bayes_cost(detector).value, rel=1e-9)
    assert best.threshold == pytest.approx(detector.threshold, abs=1e-3)


def test_attack_best_response_to_csd_beats_the_preset_and_matches_env_and_monte_carlo():
    env = detection_game_v0.parallel_env(
        scenario="ch3-static", power=1000.0, criterion="mse", statistic="chi2"
    )
    game = DetectionGame.of(env)
    br = best_attack(game, CSD_TAU, starts=6, refine=2)
    preset = game.attacker_reward(game.preset_probability, game.preset_sigma, CSD_TAU)
    # p* = 1 and the power spread over both measurements (Σ* ≈ 500 I): ×1.348 over the preset
    assert br.probability == 1.0 and br.value == pytest.approx(269.889, rel=1e-4)
    assert br.value >= 1.3 * preset
    assert np.trace(br.sigma) == pytest.approx(1000.0, rel=1e-9)
    assert br.sigma[0, 0] == pytest.approx(500.0, rel=0.01)
    defend = game.threshold_action(CSD_TAU)
    assert step_reward(env, br.action, defend) == pytest.approx(br.value, rel=1e-7)
    # independent: the true squared error of 20 000 seeded draws (exact 269.89; MC 268.66 ± 1.90)
    truth = dataclasses.replace(game.design, Pbb=br.sigma, p1=1.0)
    mc = monte_carlo(truth, {"csd": game.detector(game.threshold(defend))}, 20_000, seed=0)
    assert abs(mc.stats["csd"].mse - br.value) <= 4.0 * mc.stats["csd"].se
    # the reward is linear in p (the reason p* is 0 or 1)
    half = game.attacker_reward(0.5, br.sigma, CSD_TAU)
    assert half == pytest.approx(0.5 * (br.value + br.no_attack), rel=1e-12)


def test_attacker_evades_the_rank_one_quadratic_test():
    # the defender's statistic only sees the first measurement (assumed Σ = diag(a², 0)): the
    # best response puts the power on the second one, never detected: ×5.1 over the preset
    env = detection_game_v0.parallel_env(scenario="ch3-static", power=1000.0)
    game = DetectionGame.of(env)
    br = best_attack(game, 1.875, starts=6, refine=2)
    preset = game.attacker_reward(game.preset_probability, game.preset_sigma, 1.875)
    assert br.sigma[1, 1] >= 0.999 * 1000.0
    assert br.value >= 5.0 * preset
    # undetectable: the test fires as often under the attack as without it (P_d = P_fa)
    truth = dataclasses.replace(game.design, Pbb=br.sigma)
    p_fa, p_d = detection_probabilities(game.detector(1.875), truth)
    assert p_d == pytest.approx(p_fa, rel=1e-4)


def test_minimax_threshold_of_the_evadable_test_is_always_detect():
    env = detection_game_v0.parallel_env(scenario="ch3-static", power=1000.0)
    game = DetectionGame.of(env)
    mm = minimax_threshold(game, grid=3, starts=3, refine=1)
    # a = -1 discards everything (worst case tr P0 = 200); a = 0 and a = 1 are evaded
    assert mm.action[0] == -1.0 and mm.value == pytest.approx(-200.0, rel=1e-12)
    assert np.all(mm.grid_values[1:] < -500.0)


def test_tracking_game_prior_is_the_filter_prediction():
    game = DetectionGame.of(detection_game_v0.parallel_env(scenario="ch3-tracking", power=100.0))
    expected = tracking_problem("ch3-tracking", power=100.0).Pxx
    np.testing.assert_allclose(game.design.Pxx, expected, rtol=1e-9)


def test_quick_table_learned_policies_beat_random_and_respect_the_references(capsys, tmp_path):
    assert results.main(["detection_learned", "--quick", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "Learned attacker" in out and "Learned against learned" in out
    rows = json.loads((tmp_path / "detection_learned.json").read_text())
    by = {}
    for r in rows:
        by.setdefault(r["table"], []).append(r)
    (mse,) = [r for r in by["defender_refs"] if r["criterion"] == "mse"]
    (bayes,) = [r for r in by["defender_refs"] if r["criterion"] == "bayes_cost"]
    # τ*_MSE beats OBDD's α under the MSE (84.4 %) and is what the env pays there
    assert mse["best_value"] >= mse["obdd_value"] + 30.0
    assert mse["env_value"] == pytest.approx(mse["best_value"], rel=1e-7)
    assert bayes["best_value"] == pytest.approx(bayes["obdd_value"], rel=1e-9)
    refs = {r["detector"]: r for r in by["attacker_refs"]}
    assert refs["OBDD"]["constant"] and refs["OBDD"]["br_value"] == pytest.approx(200.0)
    assert refs["CSD"]["br_value"] >= 1.3 * refs["CSD"]["preset_value"]
    for r in refs.values():
        assert r["env_value"] == pytest.approx(r["br_value"], rel=1e-7)
    # seed 0, 800 SAC steps: the learned attacker reaches 74.1 % of the best response against
    # τ*_MSE, random attacks 31.1 %; the learned defender 93.3 % of τ*, OBDD 84.4 %, random 79.4 %
    (att,) = by["learned_attackers"]
    assert att["learned_score"][0] >= 0.6 and att["learned_score"][0] >= att["random_score"] + 0.3
    (dfd,) = by["learned_defenders"]
    assert dfd["learned_score"][0] >= dfd["random_score"] + 0.08
    assert dfd["learned_score"][0] >= dfd["obdd_score"] + 0.05
    for r in by["rounds"]:  # no learned policy beats the exact best response to its opponent
        if r["round"] > 0:
            assert r["payoff"] <= r["best_response"] + 1e-6 * abs(r["best_response"])
    assert (tmp_path / "results_detection_learned_attacker.png").stat().st_size > 10_000


def test_each_tables_cells_stand_under_their_headers():
    setting = {"scenario": "ch3-static", "power": 1000.0}
    res = {
        "defender_refs": [
            {**setting, "criterion": "mse", "best_threshold": 8.0912, "best_value": -14.77081,
             "env_value": -14.77081, "obdd_threshold": float("inf"), "obdd_value": -16.2,
             "obdd_score": 0.844, "random_score": 0.374}
        ],
        "attacker_refs": [
            {**setting, "criterion": "mse", "detector": "OBDD", "constant": True,
             "threshold": 3.80912, "preset_value": 150.0, "br_value": 200.0, "env_value": 200.0,
             "br_probability": 1.0, "br_sigma": [[1.04, 0.0], [0.0, 2.26]], "br_gain": 1.3333}
        ],
        "learned_attackers": [
            {**setting, "detector": "CSD", "steps": 800, "learned": (150.2, 3.1),
             "learned_p": (0.91234, float("nan")), "br_value": 200.0,
             "learned_score": (0.741, 0.02), "random_score": 0.311, "preset_value": 150.0}
        ],
        "learned_defenders": [
            {**setting, "steps": 800, "learned": (-210.5, float("nan")), "best_value": -200.0,
             "learned_score": (0.933, 0.011), "obdd_score": 0.844, "random_score": 0.794}
        ],
        "rounds": [],
    }  # fmt: skip
    rows = [line for line in format_tables(res).splitlines() if line.startswith("| ch3")]
    assert rows == [
        "| ch3-static a²=1000 | mse | 8.091 | -14.7708 | -14.7708 | inf | -16.2 | 84.4% | 37.4% |",
        "| ch3-static a²=1000 | mse | OBDD (always discards: constant) | 3.809 | 150 | 200 | 200 "
        "| 1 | [[1.0, 0.0], [0.0, 2.3]] | ×1.333 |",
        "| ch3-static a²=1000 | CSD | 800 | 150.2 ± 3.1 | 0.912 | 200 | 74.1% ± 2.0% | 31.1% "
        "| 75.0% |",
        "| ch3-static a²=1000 | 800 | -210.5 | -200 | 93.30% ± 1.1% | 84.40% | 79.4% |",
    ]


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda g: best_threshold(g, 0.85, g.preset_sigma, grid=2), "grid must be an integer"),
        (lambda g: best_threshold(g, 1.5, g.preset_sigma), "probability must be"),
        (lambda g: best_attack(g, 1.0, starts=0), "starts must be an integer"),
        (lambda g: best_attack(g, 1.0, refine=True), "refine must be an integer"),
        (lambda g: best_attack(g, float("nan")), "threshold must not be NaN"),
        (lambda g: minimax_threshold(g, grid=1), "grid must be an integer >= 2"),
        (lambda g: g.threshold(2.0), "defender action must be 1 finite"),
        (lambda g: g.attack(np.zeros(3)), "attacker action must be 4 finite"),
    ],
)
def test_bad_input_is_named(call, match):
    game = DetectionGame.of(detection_game_v0.parallel_env(scenario="ch3-static", power=10.0))
    with pytest.raises(ValueError, match=match):
        call(game)


def test_game_of_refuses_other_envs_and_long_episodes():
    from fdia_env import sensor_game_v0

    with pytest.raises(ValueError, match="env must be a detection_game_v0"):
        DetectionGame.of(sensor_game_v0.parallel_env())
    env = detection_game_v0.parallel_env(scenario="ch3-static", horizon=2)
    with pytest.raises(ValueError, match="horizon=1"):
        DetectionGame.of(env)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"seeds": 0}, "seeds must be an integer >= 1"),
        ({"attacker_steps": 1.5}, "attacker_steps must be an integer"),
        ({"rounds": -1}, "rounds must be an integer >= 0"),
        ({"minimax_grid": 1}, "minimax_grid must be 0"),
        ({"detectors": ("OBDX",)}, "detectors and learn_against must be among"),
        ({"attacker_criteria": ("mae",)}, "attacker_criteria among"),
    ],
)
def test_budget_names_bad_values(kwargs, match):
    with pytest.raises(ValueError, match=match):
        dl.Budget(**kwargs)
