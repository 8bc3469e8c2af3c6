"""experiments.results.game: PSRO, learned best responses, against the exact M = 10 sensor game."""

import json

import numpy as np
import pytest

from baselines.game import payoff_matrix, solve_double_oracle, solve_zero_sum
from experiments.results import game, run_table
from fdia_env import scenarios
from fdia_env.attacks.subsets import subsets
from fdia_env.kalman import steady_state

M10_VALUE = 2.95636290261434  # the LP value of game-m10 (independent rule, a² = 100)


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    """The quick table: 3 PSRO iterations on game-m10, 2,048 PPO steps per best response."""
    out = tmp_path_factory.mktemp("game")
    table = run_table("game", quick=True, seed=0, out=out)
    (row,) = json.loads((out / "game.json").read_text())
    return table, row, out


def test_game_m10_preset_is_ten_position_sensors_in_the_ch5_setting():
    sc = scenarios.get("game-m10")
    ch5 = scenarios.get("ch5-game")
    assert sc.system.M == 10 and sc.power == 100.0 and sc.attack_step == 100
    np.testing.assert_allclose(np.sqrt(sc.system.R.diagonal()), 3.0 + 0.5 * np.arange(10))
    for name in ("F", "Q", "x0", "P0"):
        np.testing.assert_array_equal(getattr(sc.system, name), getattr(ch5.system, name))


def test_game_m10_payoff_entries_match_per_subset_riccati_solutions():
    """L[D, A] = tr P_D + a² |W_D e_i|², i the smallest-σ sensor of A, if i ∈ D (docs/math.md §5).

    The matrix comes from one batched fixed-point iteration over the 1,023 subsets; here each
    entry is rebuilt from its own DARE solve.
    """
    system = scenarios.get("game-m10").system
    L = payoff_matrix("game-m10")
    assert L.shape == (1023, 1023)
    names = subsets(10)
    assert names[1022] == tuple(range(10))
    picked = (1022, names.index(tuple(range(2, 10))), names.index((5,)))
    rows = {j: np.isin(np.arange(10), names[j]) for j in picked}
    for r, mask in rows.items():
        _, P, W = steady_state(system, mask)
        for c in (0, 1, 2, names.index((2, 5)), names.index((7, 8, 9))):
            i = min(names[c])  # σ grows with the index: the smallest-σ sensor of A
            expected = np.trace(P) + (100.0 * W[:, i] @ W[:, i] if mask[i] else 0.0)
            assert L[r, c] == pytest.approx(expected, rel=1e-10)


def test_game_m10_lp_value_equals_the_double_oracle_value():
    L = payoff_matrix("game-m10")
    value = solve_zero_sum(L)[2]
    do = solve_double_oracle("game-m10")
    assert value == pytest.approx(M10_VALUE, rel=1e-9)
    assert do.value == pytest.approx(value, rel=1e-9)
    assert do.gap <= 1e-9 * value
    # the double oracle's strategies are an equilibrium of the full matrix, checked on it
    xd, yd = do.strategy("defender"), do.strategy("attacker")
    assert (xd @ L).max() <= value * (1 + 1e-9)
    assert (L @ yd).min() >= value * (1 - 1e-9)
    assert do.iterations == 7 and (len(do.defender), len(do.attacker)) == (4, 4)


def test_quick_psro_meta_game_is_the_exact_matrix_on_the_learned_actions(quick):
    _, row, _ = quick
    assert row["scenario"] == "game-m10" and row["strategies"] == [1023, 1023]
    assert len(row["history"]) == 3
    assert [len(row["populations"][s]) for s in ("defender", "attacker")] == [3, 3]
    # the empirical meta-game (learned policies played in the env) holds L's exact entries
    assert row["meta_max_abs_error"] <= 1e-9 * M10_VALUE
    assert row["lp_value"] == pytest.approx(M10_VALUE, rel=1e-9)
    assert row["lp_do_relative_difference"] <= 1e-9


def test_quick_psro_exploitability_falls_by_half_or_more(quick):
    """At seed 0 the relative NashConv falls from 130 % after iteration 1 to 42 % after 3."""
    _, row, _ = quick
    hist = row["history"]
    for h in hist:  # re-scored on the matrix: the self-play's own NashConv agrees
        assert h["nash_conv"] == pytest.approx(h["selfplay_nash_conv"], rel=1e-9, abs=1e-12)
        assert h["relative_nash_conv"] == pytest.approx(h["nash_conv"] / M10_VALUE, rel=1e-12)
        assert h["defender"] >= -1e-9 and h["attacker"] >= -1e-9
        assert h["br_gap_attacker"] >= -1e-9 and h["br_gap_defender"] >= -1e-9
    assert hist[-1]["relative_nash_conv"] <= 0.5 * hist[0]["relative_nash_conv"]
    assert row["best_relative_nash_conv"] == min(h["relative_nash_conv"] for h in hist)


def test_quick_table_and_plot_are_written(quick):
    table, _, out = quick
    assert "| game-m10 | 1023 × 1023 |" in table
    assert "3 × 2048 (PPO)" in table  # sampled rewards on game-m10 (its default)
    png = out / "results_game_game_m10.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_psro_setting_names_a_bad_parameter():
    with pytest.raises(ValueError, match="iterations must be >= 1"):
        game.PsroSetting("game-m10", 0, 100)
    with pytest.raises(ValueError, match="steps must be an integer"):
        game.PsroSetting("game-m10", 1, 1.5)
    with pytest.raises(ValueError, match="algo must be one of PPO, A2C, DQN"):
        game.PsroSetting("game-m10", 1, 100, "SAC")
    with pytest.raises(TypeError, match="scenario must be a preset name"):
        game.PsroSetting(10, 1, 100)


def test_psro_against_exact_refuses_bad_input_before_training():
    with pytest.raises(TypeError, match="setting must be a PsroSetting"):
        game.psro_against_exact("game-m10")
    with pytest.raises(ValueError, match="seed must be >= 0"):
        game.psro_against_exact(game.PsroSetting("game-m10", 1, 10), seed=-1)
    with pytest.raises(ValueError, match="unknown scenario 'nope'"):
        game.psro_against_exact(game.PsroSetting("nope", 1, 10))


def test_the_table_runs_some_rows_and_names_an_unknown_one():
    with pytest.raises(ValueError, match="games must be some of game-m10, got \\['grid-ieee14'\\]"):
        game.run(quick=True, games=["grid-ieee14"])  # the quick run has no grid row
    with pytest.raises(ValueError, match="games must be some of game-m10, got \\[\\]"):
        game.run(quick=True, games=[])
    with pytest.raises(SystemExit):  # argparse names the choices
        game.main(["--games", "nope"])
