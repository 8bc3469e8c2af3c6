"""Exact stealthy-attack baselines (baselines.stealth): security index, attacks, protection."""

from __future__ import annotations

import importlib
import itertools

import numpy as np
import pytest
from scipy import optimize

from baselines.stealth import (
    basic_measurement_set,
    budgeted_attack,
    minimum_meter_attack,
    security_index,
    undetectable_attack,
)
from fdia_env.stealth import static_estimation


@pytest.fixture(scope="module")
def ieee14():
    return static_estimation("ieee14")


@pytest.fixture(scope="module")
def ieee14_milp(ieee14):
    return security_index(ieee14, method="milp")


def _check_attacks(est, result):
    for k in range(est.n):
        if np.isinf(result.indices[k]):
            assert not result.attacks[k].any()
            continue
        a, c = result.attacks[k], result.shifts[k]
        assert c[k] == pytest.approx(1.0)
        np.testing.assert_allclose(a, est.H @ c, atol=1e-9)
        assert est.is_stealthy(a)
        assert len(result.meters_of(k)) == result.indices[k]
        # the stored attack itself has exactly that many non-zeros (no rounding residue of
        # H c left on the other meters: the minimum cut's attacks had up to 8 on IEEE 14)
        assert np.count_nonzero(a) == result.indices[k]
        assert not set(result.meters_of(k)) & set(result.protected)


def test_security_index_of_ieee14_by_milp_mincut_and_exhaustive_search(ieee14, ieee14_milp):
    cut = security_index(ieee14, method="mincut")
    binary = security_index(ieee14, method="binary")  # every 0/1 shift of the 13 angles
    assert ieee14_milp.indices.tolist() == cut.indices.tolist() == binary.indices.tolist()
    # full measurement: the cut around the slack (its 2 lines, its and their 2 buses'
    # injections) bounds every index by 5; bus 8's radial transformer gives 3
    assert ieee14_milp.indices.tolist() == [5, 5, 5, 5, 5, 5, 3, 5, 5, 5, 5, 5, 5]
    for result in (ieee14_milp, cut, binary):
        _check_attacks(ieee14, result)
    assert ieee14_milp.weakest == 6
    assert [ieee14.meters[i] for i in ieee14_milp.meters_of(6)] == ["inj6", "inj7", "trafo3@6"]


def _random_sparse_H(seed, m, n):
    rng = np.random.default_rng(seed)
    while True:
        H = rng.choice([-1.0, 0.0, 0.0, 1.0, 2.0], size=(m, n))
        if np.linalg.matrix_rank(H) == n:
            return H


@pytest.mark.parametrize("seed", range(6))
def test_security_index_milp_equals_brute_force_on_random_small_H(seed):
    est = static_estimation(_random_sparse_H(seed, 9, 4))
    milp = security_index(est, method="milp")
    brute = security_index(est, method="brute")
    assert milp.indices.tolist() == brute.indices.tolist()
    _check_attacks(est, milp)
    _check_attacks(est, brute)


def test_milp_with_protected_meters(ieee14):
    protected = [0, 1, 4, 14, 15]  # the slack's injection and lines, two injections
    milp = security_index(ieee14, method="milp", protected=protected)
    assert np.all(milp.indices > 0) and milp.proved.all()
    # the protected flows of the slack's two lines pin the angles of their far ends (states
    # 0 and 3): no undetectable attack moves them
    assert np.flatnonzero(np.isinf(milp.indices)).tolist() == [0, 3]
    # a protected injection is only spared by a 0/1 shift that leaves its bus and all its
    # neighbours alone; a real shift can balance it (bus 2 against bus 3 around protected
    # bus 1): state 1 needs 12 meters, which no 0/1 shift reaches (the cut refuses them)
    assert milp.indices[1] == 12
    _check_attacks(ieee14, milp)


def test_protecting_a_basic_measurement_set_rules_out_every_undetectable_attack(ieee14):
    basic = basic_measurement_set(ieee14)
    assert len(basic) == ieee14.n
    assert np.linalg.matrix_rank(ieee14.H[list(basic)]) == ieee14.n
    assert undetectable_attack(ieee14, protected=basic) is None
    shielded = security_index(ieee14, method="milp", protected=basic)
    assert np.all(np.isinf(shielded.indices))
    # negative control: one meter fewer leaves an undetectable attack, sparing the others
    for dropped in (basic[0], basic[-1]):
        fewer = [i for i in basic if i != dropped]
        attack = undetectable_attack(ieee14, protected=fewer)
        assert attack is not None
        assert np.all(attack.a[fewer] == 0.0)
        assert np.abs(attack.c).max() > 0.1
        assert ieee14.is_stealthy(attack.a)
        index = security_index(ieee14, method="milp", protected=fewer)
        assert np.isfinite(index.indices).any()


def test_minimum_meter_attack(ieee14):
    attack = minimum_meter_attack(ieee14, method="mincut")
    assert (attack.value, attack.target) == (3.0, 6)
    assert [ieee14.meters[i] for i in attack.meters] == ["inj6", "inj7", "trafo3@6"]
    assert ieee14.is_stealthy(attack.a)
    on_zero = minimum_meter_attack(ieee14, target=0)
    assert on_zero.value == 5.0
    assert minimum_meter_attack(ieee14, protected=basic_measurement_set(ieee14)) is None


def test_budgeted_attack_on_the_radial_bus(ieee14):
    # state 6 is bus 7 (pandapower index), reached only through transformer 3 (b = 5.677 pu):
    # shifting it alone by c changes that flow and the two end injections by b c each
    b = ieee14.grid.network.b[18]
    assert ieee14.grid.network.branches[18] == ("trafo", 3)
    attack = budgeted_attack(ieee14, budget=3, a_max=0.5, target=6)
    assert attack.value == pytest.approx(0.5 / b, rel=1e-9)
    assert attack.meters == (6, 7, 32)
    assert ieee14.is_stealthy(attack.a)
    assert np.abs(attack.a).max() <= 0.5 * (1 + 1e-9)
    # two meters cannot hide any attack on it
    assert budgeted_attack(ieee14, budget=2, a_max=0.5, target=6).value == 0.0


def test_budgeted_attack_skips_states_whose_index_exceeds_the_budget(ieee14, ieee14_milp):
    # only state 6 has a security index <= 3: the pruned search solves its MILP alone and
    # finds the optimum over every state (0.5 / b of transformer 3, the doctest's 0.0881)
    assert np.flatnonzero(ieee14_milp.lower_bounds <= 3).tolist() == [6]
    pruned = budgeted_attack(ieee14, budget=3, a_max=0.5, indices=ieee14_milp)
    assert pruned.target == 6 and pruned.meters == (6, 7, 32) and pruned.proved
    assert pruned.value == pytest.approx(0.5 / ieee14.grid.network.b[18], rel=1e-9)
    # a budget below every index: every state skipped, the certified optimum is 0
    none = budgeted_attack(ieee14, budget=2, a_max=0.5, indices=ieee14_milp)
    assert none.value == 0.0 and none.bound == 0.0 and not none.a.any()
    with pytest.raises(ValueError, match="indices were computed with protected meters"):
        budgeted_attack(ieee14, budget=3, protected=[32], indices=ieee14_milp)
    with pytest.raises(ValueError, match="indices must be a SecurityIndex"):
        budgeted_attack(ieee14, budget=3, indices=[3.0] * 13)
    part = security_index(ieee14, method="mincut", states=[0, 6])
    with pytest.raises(ValueError, match="indices must cover every state"):
        budgeted_attack(ieee14, budget=3, indices=part)


def _budget_brute(est, budget, a_max, t):
    best = 0.0
    for size in range(1, budget + 1):
        for chosen in itertools.combinations(range(est.m), size):
            zero = np.setdiff1d(np.arange(est.m), chosen)
            Hc = est.H[list(chosen)]
            res = optimize.linprog(
                -np.eye(est.n)[t],
                A_ub=np.vstack([Hc, -Hc]),
                b_ub=np.full(2 * size, a_max),
                A_eq=est.H[zero] if zero.size else None,
                b_eq=np.zeros(zero.size) if zero.size else None,
                bounds=[(None, None)] * est.n,
            )
            if res.status == 0:
                best = max(best, -res.fun)
    return best


@pytest.mark.parametrize("seed", range(3))
def test_budgeted_attack_equals_brute_force_on_random_small_H(seed):
    est = static_estimation(_random_sparse_H(10 + seed, 8, 3))
    for budget in (3, 5):
        want = _budget_brute(est, budget, 1.0, 0)
        got = budgeted_attack(est, budget, a_max=1.0, target=0)
        assert got.value == pytest.approx(want, rel=1e-7, abs=1e-9)
        assert len(got.meters) <= budget
        if got.value > 0:
            assert est.is_stealthy(got.a)
            assert np.abs(got.a).max() <= 1.0 + 1e-9


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda e: budgeted_attack(e, budget=35), "budget must be <= 34"),
        (lambda e: budgeted_attack(e, budget=0), "budget must be >= 1"),
        (lambda e: budgeted_attack(e, budget=2, a_max=0.0), "a_max must be one positive"),
        (lambda e: budgeted_attack(e, budget=2, target=13), "target must be a state position"),
        (lambda e: security_index(e, protected=["inj99"]), "protected holds an unknown meter"),
        (lambda e: security_index(e, protected=[34]), "protected holds an unknown meter"),
        (lambda e: security_index(e, protected=[1.5]), "protected must hold meter positions"),
        (lambda e: security_index(e, method="lp"), "method must be one of"),
        (lambda e: security_index(e, method="brute"), "method 'brute' enumerates meter sets"),
        (lambda e: security_index(e, c_max=-1.0), "c_max must be a finite number > 0"),
        (lambda e: security_index(e, states=[20]), "states must be a state position"),
        (lambda e: security_index([[1.0], [2.0]], method="mincut"), "needs a grid model"),
        (
            lambda e: security_index([[1.0, 2.0], [2.0, 4.0], [3.0, 6.0]]),
            "estimation: H must have full",
        ),
    ],
)
def test_bad_input_names_the_parameter(ieee14, call, match):
    with pytest.raises(ValueError, match=match):
        call(ieee14)


def test_budgeted_attack_milp_prints_nothing(ieee14, capfd):
    # HiGHS' MIP solver writes "HighsMipSolverData::transformNewIntegerFeasibleSolution
    # tmpSolver.run();" from C++ to descriptor 1 on this solve (state 9, 6 meters)
    print("before", flush=True)
    attack = budgeted_attack(ieee14, budget=6, a_max=0.5, target=9)
    print("after", flush=True)
    out, err = capfd.readouterr()
    assert out == "before\nafter\n" and err == ""
    assert attack.meters == (5, 8, 10, 21, 24, 26)
    assert attack.value == pytest.approx(0.05784778534923338, rel=1e-6)


def _stopped_at_time_limit(real, dual_shift):
    """A ``milp`` that solves, then reports HiGHS' time-limit status with a weaker dual bound."""

    def milp(*args, **kwargs):
        res = real(*args, **kwargs)
        res.status = 1
        res.mip_dual_bound = res.fun - dual_shift
        return res

    return milp


def test_security_index_stopped_at_time_limit_is_not_reported_as_proved():
    est = static_estimation(_random_sparse_H(0, 9, 4))
    proved = security_index(est, method="milp")
    assert proved.proved.all()
    np.testing.assert_array_equal(proved.lower_bounds, proved.indices)
    stopped = security_index(est, method="milp", time_limit=1e-9)
    # the attack kept is verified and no sparser than the index; the bound no higher
    assert np.all(stopped.indices >= proved.indices)
    assert np.all(stopped.lower_bounds <= proved.indices)
    assert not stopped.proved[stopped.indices > 1].any()
    _check_attacks(est, stopped)


def test_budgeted_attack_stopped_at_time_limit_reports_its_upper_bound(monkeypatch):
    module = importlib.import_module("baselines.stealth.attack")

    est = static_estimation(_random_sparse_H(1, 9, 4))
    proved = budgeted_attack(est, budget=5, a_max=1.0, target=0)
    assert proved.value == pytest.approx(0.4)
    assert proved.proved and proved.bound == pytest.approx(proved.value)
    # cost is -c_t: a dual bound 0.25 lower is an upper bound 0.25 above the shift found
    monkeypatch.setattr(module, "milp", _stopped_at_time_limit(module.milp, 0.25))
    stopped = budgeted_attack(est, budget=5, a_max=1.0, target=0, time_limit=1.0)
    assert stopped.value == pytest.approx(proved.value)
    assert stopped.bound == pytest.approx(proved.value + 0.25, rel=1e-6)
    assert not stopped.proved
