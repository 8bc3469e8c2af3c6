"""Stored sensor-game payoff matrices: scoring with one equals scoring with the rebuilt game."""

from __future__ import annotations

import numpy as np
import pytest

import agents.registry as registry
import baselines.game
from agents.bench.score import score_policy
from baselines.game import MixedStrategyPolicy, payoff_matrix
from fdia_env import scenarios
from fdia_env.tasks import get, payoffs

TASK = "sensor-game/ch5-game-attacker-v0"


@pytest.fixture
def store(tmp_path, monkeypatch):
    """An empty payoff store in ``tmp_path`` in place of the package's, no game cached."""
    monkeypatch.setattr(payoffs, "_folder", lambda: tmp_path)
    monkeypatch.setattr(registry, "_GAMES", {})
    payoffs.manifest.cache_clear()
    yield tmp_path
    payoffs.manifest.cache_clear()


def _score(policy):
    registry._GAMES.clear()  # each score solves its game afresh (from the store or built)
    return score_policy(get(TASK), policy, seeds=(0, 1), episodes=3)


def test_a_stored_payoff_gives_the_score_of_the_rebuilt_game(store, monkeypatch):
    policy = MixedStrategyPolicy(np.array([0.5, 0.2, 0.1, 0.1, 0.05, 0.05, 0.0]), seed=0)
    built = _score(policy)
    sc = scenarios.get("ch5-game")
    payoffs.write_payoff(payoff_matrix(sc, 100.0), sc, 100.0, "independent", None)

    def refuse(*args, **kwargs):
        raise AssertionError("the stored payoff must be read, not rebuilt")

    monkeypatch.setattr(baselines.game, "payoff_matrix", refuse)
    cached = _score(policy)
    assert cached.extras["exploitability"] > 0.01  # a policy far from the equilibrium
    assert cached.extras == built.extras
    assert (cached.normalised, cached.per_seed) == (built.normalised, built.per_seed)


def test_the_stored_matrix_is_the_one_used(store):
    policy = MixedStrategyPolicy(np.full(7, 1 / 7), seed=0)
    sc = scenarios.get("ch5-game")
    L = payoff_matrix(sc, 100.0)
    payoffs.write_payoff(L, sc, 100.0, "independent", None)
    exact = _score(policy)
    assert exact.normalised == pytest.approx(0.0, abs=1e-12)  # uniform play scores 0
    payoffs.write_payoff(L * 2.0, sc, 100.0, "independent", None)  # another game's matrix
    assert _score(policy).extras["exploitability"] == pytest.approx(
        2.0 * exact.extras["exploitability"], rel=1e-9
    )


def test_a_store_serves_only_its_own_game_and_refuses_a_changed_file(store):
    sc = scenarios.get("ch5-game")
    L = payoff_matrix(sc, 100.0)
    path = payoffs.write_payoff(L, sc, 100.0, "independent", None)
    assert np.array_equal(payoffs.stored_payoff(sc, 100.0, "independent", None), L)
    assert payoffs.stored_payoff(sc, 50.0, "independent", None) is None
    assert payoffs.stored_payoff(sc, 100.0, "dependent", None) is None
    assert payoffs.stored_payoff(sc, 100.0, "independent", 2) is None
    assert payoffs.stored_payoff(scenarios.get("game-m10"), 100.0, "independent", None) is None
    np.save(path, L + 1e-9, allow_pickle=False)
    with pytest.raises(ValueError, match=r"payoff .*SHA-256"):
        payoffs.stored_payoff(sc, 100.0, "independent", None)


def test_the_stored_ieee118_matrix_matches_the_full_defenders_filter():
    """Row of the defender that keeps every meter: ``tr P + a² |W e_i|²`` for each attacked i."""
    from baselines.game.payoff import subset_masks
    from fdia_env.kalman import steady_state

    sc = scenarios.get("grid-ieee118")
    L = payoffs.stored_payoff(sc, 0.01, "independent", 1)
    assert L is not None and L.shape == (305, 304)
    system = sc.system
    masks = subset_masks(system.M, 1, "defender")
    row = int(np.flatnonzero(masks.all(axis=1))[0])
    _, P, W = steady_state(system, masks[row])
    attacked = np.argmax(subset_masks(system.M, 1, "attacker"), axis=1)
    expected = np.trace(P) + 0.01 * np.square(W[:, attacked]).sum(axis=0)
    np.testing.assert_allclose(L[row], expected, rtol=1e-10, atol=0.0)


def test_the_payoff_command_stores_the_game_and_verify_refuses_a_stale_matrix(store, capsys):
    from agents.bench.__main__ import main
    from agents.bench.references import sensor_game
    from fdia_env.tasks import spec

    assert main(["payoff", "--task", TASK]) == 0
    assert "wrote" in capsys.readouterr().out
    sc = scenarios.get("ch5-game")
    L = payoffs.stored_payoff(sc, 100.0, "independent", None)
    assert np.array_equal(L, payoff_matrix(sc, 100.0))
    stored = get(TASK).references
    # rebuilt == stored (an LP's value: to round-off on a CPU other than the one that stored it)
    assert sensor_game(spec(TASK)).game_value == pytest.approx(stored.game_value, rel=1e-12)
    payoffs.write_payoff(L * (1 + 1e-6), sc, 100.0, "independent", None)
    with pytest.raises(RuntimeError, match="stored payoff matrix differs"):
        sensor_game(spec(TASK))
    assert main(["payoff", "--task", "sparse/ch4-position-v0"]) == 2
    assert "must be a sensor-game task" in capsys.readouterr().err
