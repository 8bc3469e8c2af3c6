"""The protection game (baselines.stealth.protection): double oracle vs an independent solver."""

from __future__ import annotations

import functools

import numpy as np
import pytest
from scipy import optimize

from baselines.stealth import (
    matrix_game,
    protection_exploitability,
    protection_game,
)
from fdia_env.stealth import static_estimation, stealth_attack_v0

# small H (random, sparse) whose games have mixed equilibria: (shape, seed) → game value
CASES = [((8, 3), 0), ((8, 3), 15), ((9, 4), 18)]


def _H(shape, seed):
    return np.random.default_rng(seed).choice([-1.0, 0.0, 0.0, 0.0, 1.0, 2.0], size=shape)


def _minimax(L):
    """Von Neumann's LP, written out here: the defender (rows) minimises the attacker's payoff."""
    r, c = L.shape
    res = optimize.linprog(
        np.r_[np.zeros(r), 1.0],
        A_ub=np.c_[L.T, -np.ones(c)],
        b_ub=np.zeros(c),
        A_eq=np.r_[np.ones(r), 0.0][None],
        b_eq=[1.0],
        bounds=[(0.0, None)] * r + [(None, None)],
        method="highs",
    )
    assert res.status == 0
    return float(res.fun)


@functools.cache
def _solve(case):
    est = static_estimation(_H(*case))
    return est, protection_game(est, budget=4, protection=1, a_max=1.0)


@pytest.fixture(scope="module", params=CASES, ids=lambda c: f"{c[0][0]}x{c[0][1]}-seed{c[1]}")
def solved(request):
    return _solve(request.param)


@pytest.fixture(scope="module")
def first():
    return _solve(CASES[0])


def test_double_oracle_equals_the_whole_matrix_game_solved_by_lp(solved):
    est, game = solved
    rows, _columns, L = matrix_game(est, 4, 1, a_max=1.0)
    value = _minimax(L)
    assert value > 0.1  # a real mixed game, not the trivial 0
    assert game.value == pytest.approx(value, abs=1e-9)
    assert game.gap <= 1e-6 * game.value and game.lower <= value + 1e-9 <= game.upper + 2e-9
    assert len(game.defender) >= 2 and len(game.attacks) >= 2  # mixed on both sides
    # the double oracle's strategies are optimal in the WHOLE game: the defender's mix concedes
    # at most the value to every attack, the attacker's mix gets at least it against every set
    x = np.array([game.defender.get(p, 0.0) for p in rows])
    assert np.max(x @ L) <= value + 1e-9
    for attack, prob in zip(game.attacks, game.attack_probs, strict=True):
        assert prob > 0 and est.is_stealthy(attack.a) and len(attack.meters) <= 4
        assert np.max(np.abs(attack.a)) <= 1.0 + 1e-9
        assert attack.value == pytest.approx(np.max(np.abs(est.estimate_shift(attack.a))))
    against = [
        sum(
            q * k.value * (not set(p) & set(k.meters))
            for k, q in zip(game.attacks, game.attack_probs, strict=True)
        )
        for p in rows
    ]
    assert min(against) >= value - 1e-9


def test_exploitability_scores_protections_against_the_game_value(first):
    est, game = first
    rows, _columns, L = matrix_game(est, 4, 1, a_max=1.0)
    at_equilibrium, _ = protection_exploitability(est, game.defender, 4, a_max=1.0)
    assert at_equilibrium == pytest.approx(game.value, abs=1e-9)
    for j in (0, len(rows) - 1):  # a pure protection concedes its row's best column
        conceded, attack = protection_exploitability(est, rows[j], 4, a_max=1.0)
        assert conceded == pytest.approx(np.max(L[j]), abs=1e-9) and conceded > game.value
        assert not set(attack.meters) & set(rows[j])
    bits = np.zeros(est.m, dtype=np.int8)
    bits[list(rows[0])] = 1  # the same protection as a 0/1 vector
    assert protection_exploitability(est, bits, 4, a_max=1.0)[0] == pytest.approx(np.max(L[0]))


def test_equilibrium_policies_play_in_the_env(first):
    est, game = first
    attacker, defender = game.policy("attacker", seed=0), game.policy("defender", seed=0)
    acts, _ = attacker.predict(np.zeros((400, 3)))
    sets, _ = defender.predict(np.zeros((400, 3)))
    assert acts.shape == (400, est.m) and acts.dtype == np.float32
    assert sets.shape == (400, est.m) and set(sets.sum(axis=1)) == {1}
    # every attack of the support, played in the env on meters the defender left alone, pays
    # its damage whenever the test does not false-alarm: (1 − α) · |c|_∞ in expected dynamics
    for attack in game.attacks:
        env = stealth_attack_v0.parallel_env(
            est, budget=4, action="free", a_max=1.0, dynamics="expected"
        )
        env.reset(seed=0)
        _, rewards, *_ = env.step({"attacker": (attack.a / 1.0).astype(np.float32)})
        assert rewards["attacker"] == pytest.approx((1 - est.alpha) * attack.value, rel=1e-6)
    freq = {tuple(np.flatnonzero(s)): 0 for s in sets}
    for s in sets:
        freq[tuple(np.flatnonzero(s))] += 1
    for meters, p in game.defender.items():
        assert abs(freq.get(meters, 0) / 400 - p) < 0.1


def test_no_undetectable_attack_on_the_budget_is_worth_zero():
    game = protection_game(_H((8, 3), 0), budget=1, protection=1, a_max=1.0)
    assert game.value == game.upper == game.gap == 0.0 and game.attacks == ()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"budget": 0}, "budget"),
        ({"budget": 9}, "budget"),
        ({"protection": 9}, "protection"),
        ({"protection": -1}, "protection"),
        ({"a_max": -1.0}, "a_max"),
        ({"tol": 0.0}, "tol"),
        ({"max_iter": 0}, "max_iter"),
    ],
)
def test_bad_input_names_the_parameter(kwargs, match):
    args = {"budget": 3, "protection": 1, **kwargs}
    with pytest.raises(ValueError, match=match):
        protection_game(_H((8, 3), 0), **args)


@pytest.mark.parametrize(
    ("protection", "match"),
    [({(0,): 0.5}, "sum to 1"), ([99], "unknown meter"), ({(0,): -1.0, (1,): 2.0}, ">= 0")],
)
def test_bad_protection_names_the_parameter(protection, match):
    with pytest.raises(ValueError, match=rf"protection.*{match}"):
        protection_exploitability(_H((8, 3), 0), protection, 3, a_max=1.0)
