"""The ``stealth`` result table's fast core: the enumerated optimum and the table's layout."""

from __future__ import annotations

import numpy as np
import pytest

from experiments.results import cli
from experiments.results.stealth import (
    format_rows,
    learned_attacker,
    learned_protection,
    milp_reference,
    references,
    shift_payoffs,
    threshold_game,
)


def test_enumerated_optimum_of_the_shift_actions_is_bus_7():
    payoffs = shift_payoffs(3)
    assert payoffs.shape == (2**13 - 1,)
    top = np.flatnonzero(payoffs >= payoffs.max() - 1e-12) + 1  # non-zero bit vectors, in order
    shifted = [np.flatnonzero((t >> np.arange(13)) & 1).tolist() for t in top]
    # state 6 (bus 7, radial) alone, or with four or five more states: 3 meters, undetectable
    assert shifted == [[6], [4, 6, 9, 10, 11], [4, 6, 9, 10, 11, 12]]
    assert payoffs.max() == pytest.approx((1 - 0.05) * 0.05, rel=1e-12)
    # every other action needs more than 3 meters: trimmed, it is seen for sure (payoff ~0)
    assert np.sort(payoffs)[-4] < 1e-12
    assert cli.TABLES["stealth"] == "experiments.results.stealth"


def test_threshold_game_value_is_the_smallest_rate_against_a_stealthy_attack():
    game = threshold_game(3)
    alphas = np.array(game["alphas"])
    # a stealthy 3-meter shift is seen with probability α exactly, whatever the rate: each rate
    # concedes (1 − α) · 0.05 + α (the false-alarm cost), the smallest rate is the equilibrium
    np.testing.assert_allclose(game["concedes"], (1 - alphas) * 0.05 + alphas, rtol=1e-12)
    assert game["value"] == pytest.approx((1 - 0.001) * 0.05 + 0.001, rel=1e-9)
    assert game["defender"] == pytest.approx([1.0, 0.0, 0.0, 0.0, 0.0], abs=1e-9)


def test_ieee118_reference_is_the_min_cut_shift_played_in_the_env():
    ref = references(3, "grid-ieee118")
    # a 3-meter undetectable shift exists (the smallest security index on IEEE 118 is 3): the
    # env pays it (1 − α) · magnitude exactly; random 0/1 shifts of 117 states, trimmed to 3
    # meters, are nearly always seen
    assert ref["optimum"] == pytest.approx((1 - 0.05) * 0.05, rel=1e-12)
    assert "3 meters" in ref["optimum_kind"]
    assert 0.0 < ref["random"] < 0.1 * ref["optimum"]
    with pytest.raises(ValueError, match="budget=2: every undetectable shift on grid-ieee118"):
        references(2, "grid-ieee118")
    with pytest.raises(ValueError, match="too many to enumerate"):
        shift_payoffs(3, "grid-ieee118")


def test_ieee118_milp_reference_is_certified_and_held_by_the_box_shift_actions():
    ref = milp_reference(3, "grid-ieee118")
    # 108 of the 117 states have a min-cut security index above 3 (skipped, their best shift
    # is 0); of the 9 MILPs, bus 86's (state 85: meters 85, 86, 302) moves the most
    assert ref["skipped_states"] == 108 and ref["proved"]
    assert ref["milp_state"] == 85 and ref["milp_meters"] == [85, 86, 302]
    assert ref["milp_shift"] == pytest.approx(0.10393482094640001, rel=1e-9)
    assert ref["optimum"] == pytest.approx((1 - 0.05) * ref["milp_shift"], rel=1e-12)
    assert ref["bound"] == pytest.approx(ref["optimum"], rel=1e-12)
    assert ref["attained"]  # the MILP's c is a 0/1 direction: a box shift pays the optimum
    assert 0.0 <= ref["random"] < 0.01 * ref["optimum"]
    with pytest.raises(ValueError, match="action must be one of"):
        learned_attacker(3, 8, [0], action="free")


def test_the_table_shows_every_seed_and_the_game():
    attacker = {
        "algo": "torch-ppo", "scenario": "grid-ieee14", "budget": 3, "steps": 10,
        "learned": [0.0475, 0.0],
        "learned_mean": 0.02375, "learned_ci95": 0.3, "random": 1.7e-5, "optimum": 0.0475,
        "optimum_kind": "enumerated", "score": [1.0, 0.0], "train_seconds": [4.0, 5.0],
    }  # fmt: skip
    game = {
        "budget": 5, "protection": 2, "value": 0.02996, "gap": 1e-17,
        "protect_optimal_attack_concedes": 0.05, "protect_basic_concedes": 0.06,
        "unprotected": 0.12,
    }  # fmt: skip
    defender = {
        "steps": 8, "alpha": [0.001, 0.01], "concedes": [0.05095, 0.0595],
        "concedes_mean": 0.055225, "concedes_ci95": 0.05, "value": 0.05095,
        "train_seconds": [3.0, 4.0],
    }  # fmt: skip
    boxed = attacker | {
        "action": "box_shift", "scenario": "grid-ieee118", "learned": [0.0987, 0.0665],
        "learned_mean": 0.0826, "optimum": 0.0987, "a_max": 0.05, "bound": 0.0987,
        "milp_seconds": 8.2, "optimum_kind": "MILP, proved", "score": [1.0, 0.674],
    }  # fmt: skip
    table = format_rows([attacker, boxed], [game], [defender])
    assert (
        "| grid-ieee118 | torch-ppo | 3 | 0.05 | 10 | 0.0987, 0.0665 | 0.0826 ± 0.3 | 1.70e-05 "
        "| 0.0987 (0.0987; MILP, proved) | 8 | 100.0%, 67.4% | 4, 5 |"
    ) in table
    assert "| 8 | 0.001, 0.01 | 0.05095, 0.05950 | 0.05523 ± 0.05 | 0.05095 | 3, 4 |" in table
    row = (
        "| grid-ieee14 | torch-ppo | 3 | 10 | 0.0475, 0.0000 | 0.0238 ± 0.3 | 1.70e-05 "
        "| 0.0475 (enumerated) | 100.0%, 0.0% | 4, 5 |"
    )
    assert row in table
    assert "| 5 | 2 | 0.0300 (1.0e-17) | 0.0500 | 0.0600 | 0.1200 |" in table


def test_learned_attacker_torch_ppo_tiny_budget_and_bad_algo():
    row = learned_attacker(3, 256, [0], algo="torch-ppo")
    assert row["algo"] == "torch-ppo"
    assert {"learned", "score", "train_seconds", "optimum", "random"} <= row.keys()
    # the deterministic shift is played in the env: its payoff is one of the action space's
    # (0 when trimmed and seen for sure, at most the enumerated optimum)
    (value,) = row["learned"]
    assert np.isfinite(value) and 0.0 <= value <= row["optimum"] + 1e-12
    assert row["optimum"] == pytest.approx((1 - 0.05) * 0.05, rel=1e-12)
    assert row["score"] == [pytest.approx(value / row["optimum"])]
    assert 0.0 < row["train_seconds"][0] < 60.0
    with pytest.raises(ValueError, match=r"algo must be one of \['PPO', 'torch-ppo'\], got 'A2C'"):
        learned_attacker(3, 256, [0], algo="A2C")


def test_learned_protection_picks_the_best_meter_of_exact_payoffs():
    # synthetic exact payoffs: protecting meter 2 stops every attack, meter 1 halves the damage
    payoffs = [-0.08, -0.04, 0.0, -0.08]
    row = learned_protection(3, 1, 256, [0], payoffs=payoffs)
    assert {
        "meter", "concedes", "mix", "mix_concedes", "value", "gap", "payoffs", "best_meters",
        "train_seconds", "steps", "seeds", "budget", "protection",
    } <= row.keys()  # fmt: skip
    assert row["meter"] == [2] and row["concedes"] == [0.0]
    assert row["best_meters"] == [2] and row["payoffs"] == payoffs
    (mix,) = row["mix"]
    assert sum(mix.values()) == pytest.approx(1.0) and mix["2"] > 0.9
    # the game and the mix's exact score need the real estimation: skipped when injected
    assert row["value"] is None and row["mix_concedes"] == [None]
    table = format_rows([], [], None, [row])
    assert "| 3 | 1 | 256 | 2 | 0.0000 | - | - |" in table


def test_learned_protection_bad_input():
    with pytest.raises(ValueError, match="protection must be 1"):
        learned_protection(3, 2, 256, [0], payoffs=[0.0, -1.0])
    with pytest.raises(ValueError, match="steps must be an int >= 1"):
        learned_protection(3, 1, 0, [0], payoffs=[0.0, -1.0])
    with pytest.raises(ValueError, match="seeds must be a non-empty list"):
        learned_protection(3, 1, 256, [], payoffs=[0.0, -1.0])
    with pytest.raises(ValueError, match="payoffs must be a non-empty finite 1-d vector"):
        learned_protection(3, 1, 256, [0], payoffs=[0.0, float("nan")])
