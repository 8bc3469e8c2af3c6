"""The security index's certified numbers: exact at every scale of H and every ``c_max``."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from baselines.stealth import budgeted_attack, security_index
from fdia_env.stealth import static_estimation


@pytest.fixture(scope="module")
def ieee14():
    return static_estimation("ieee14")


def _brute_indices(H, protected=()):
    """Security indices by enumerating meter sets with exact small-integer rank tests.

    State k is attackable on the meters A iff e_k is outside the row space of the rows off A.
    """
    m, n = H.shape
    free = [i for i in range(m) if i not in set(protected)]
    out = [np.inf] * n
    for k in range(n):
        e = np.eye(n)[k]
        for size in range(len(free) + 1):
            for chosen in itertools.combinations(free, size):
                rest = H[[i for i in range(m) if i not in chosen]]
                if np.linalg.matrix_rank(np.vstack([rest, e])) > np.linalg.matrix_rank(rest):
                    out[k] = float(size)
                    break
            if np.isfinite(out[k]):
                break
    return out


def _check(est, result):
    """Every reported attack is a = H c, c_k = 1, zero on the protected meters, index-sparse."""
    for k in range(est.n):
        if np.isinf(result.indices[k]):
            continue
        a, c = result.attacks[k], result.shifts[k]
        assert c[k] == pytest.approx(1.0)
        np.testing.assert_allclose(a, est.H @ c, atol=1e-9 * max(1.0, np.abs(a).max()))
        assert np.count_nonzero(a) == result.indices[k]
        assert not np.any(a[list(result.protected)])


@pytest.mark.parametrize("c_max", [0.5, 100.0, 1e6, 1e300])
def test_ieee14_indices_are_exact_for_every_c_max(ieee14, c_max):
    # the min cut is exact here (every flow and injection metered): states 0 and 6 need 5
    # and 3 meters. c_max = 1e6 gave 5 on state 6, 1e300 inf everywhere, both "certified"
    cut = security_index(ieee14, method="mincut", states=[0, 6])
    assert cut.indices[[0, 6]].tolist() == [5.0, 3.0]
    # on the grid model the cut certifies the bound; on its bare H the hitting-set loop does
    for est in (ieee14, static_estimation(ieee14.H)):
        result = security_index(est, c_max=c_max, states=[0, 6])
        assert result.indices[[0, 6]].tolist() == [5.0, 3.0]
        assert result.lower_bounds[[0, 6]].tolist() == [5.0, 3.0]
        assert result.meters_of(6) == cut.meters_of(6) == (6, 7, 32)


@pytest.mark.parametrize("c_max", [0.0, -1.0, float("inf"), float("nan")])
def test_c_max_must_be_finite_and_positive(ieee14, c_max):
    with pytest.raises(ValueError, match="c_max must be"):
        security_index(ieee14, c_max=c_max)


def _needs_big_c():
    """8x2 H: the 3-meter attacks need c = (1, 1000) or (0.001, 1); any other c needs 7."""
    return np.array(
        [[1000.0, -1.0]] * 5 + [[1.0, 0.0], [0.0, 1.0], [1.0, 1.0]],
    )


def test_sparsest_attack_needing_c_of_1000_is_found_with_the_default_c_max():
    H = _needs_big_c()
    assert _brute_indices(H) == [3.0, 3.0]
    result = security_index(H)  # c_max = 100 cut the attack on state 0 off: [7, 3]
    assert result.indices.tolist() == [3.0, 3.0]
    assert result.lower_bounds.tolist() == [3.0, 3.0]
    assert result.shifts[0].tolist() == pytest.approx([1.0, 1000.0])
    assert security_index(H, method="brute").indices.tolist() == [3.0, 3.0]
    _check(static_estimation(H), result)


@pytest.mark.parametrize("method", ["mincut", "binary"])
def test_zero_one_shift_methods_refuse_protected_meters(ieee14, method):
    # with meter 0 protected the min cut reported states 0 and 3 unattackable (bound inf),
    # while attacks on 9 meters that spare meter 0 exist
    with pytest.raises(ValueError, match="protected meters: use method='milp'"):
        security_index(ieee14, method=method, protected=[0])


def test_milp_attacks_states_the_cut_missed_with_a_protected_meter(ieee14):
    result = security_index(ieee14, protected=[0], states=[0, 3])
    assert result.indices[[0, 3]].tolist() == [9.0, 9.0]
    assert result.proved[[0, 3]].all()
    for k in (0, 3):
        a = result.attacks[k]
        assert a[0] == 0.0
        assert ieee14.is_stealthy(a)
        assert np.linalg.norm(ieee14.H @ result.shifts[k] - a) <= 1e-9 * np.abs(a).max()


def test_cut_certifies_nothing_without_full_measurement():
    # bus 0's injection unmetered: the 0/1 shifts still give attacks (upper bounds) but the
    # full-measurement theorem no longer applies, so the cut's bounds are the trivial 1
    from fdia_env.systems.grid import grid_model

    est = static_estimation(grid_model("ieee14", injections=list(range(1, 14))))
    cut = security_index(est, method="mincut")
    assert cut.indices[[0, 6, 12]].tolist() == [4.0, 3.0, 4.0]
    assert cut.lower_bounds.tolist() == [1.0] * 13 and not cut.proved.any()
    exact = security_index(est, states=[0, 6, 12])
    assert exact.indices[[0, 6, 12]].tolist() == exact.lower_bounds[[0, 6, 12]].tolist()
    assert np.all(exact.indices[[0, 6, 12]] <= cut.indices[[0, 6, 12]])


def test_budgeted_attack_with_a_huge_a_max_is_finite_and_linear(ieee14):
    # a_max = 1e300 ended in "HiGHS ... Model error"; the best shift is linear in a_max
    unit = budgeted_attack(ieee14, budget=3, a_max=1.0, target=6)
    huge = budgeted_attack(ieee14, budget=3, a_max=1e300, target=6)
    assert huge.meters == unit.meters == (6, 7, 32)
    assert huge.value == pytest.approx(1e300 * unit.value, rel=1e-9)
    assert np.all(np.isfinite(huge.a)) and huge.proved
    assert np.abs(huge.a).max() <= 1e300


def test_time_limit_keeps_a_verified_attack_and_a_valid_bound():
    H = _needs_big_c()
    stopped = security_index(H, time_limit=1e-9)
    assert np.all(stopped.lower_bounds <= [3.0, 3.0])
    assert np.all(stopped.indices >= 3.0)
    _check(static_estimation(H), stopped)


@st.composite
def _scaled_H(draw):
    m = draw(st.integers(3, 7))
    n = draw(st.integers(1, 3))
    base = np.array(
        draw(st.lists(st.sampled_from([-2, -1, 0, 0, 1, 3]), min_size=m * n, max_size=m * n)),
        dtype=np.float64,
    ).reshape(m, n)
    if draw(st.booleans()):  # a repeated meter
        base[-1] = base[0]
    if draw(st.booleans()):  # a meter that sees no state
        base[draw(st.integers(0, m - 1))] = 0.0
    assume(np.linalg.matrix_rank(base) == n and m > n)
    rows = 10.0 ** np.array(draw(st.lists(st.integers(-3, 3), min_size=m, max_size=m)))
    cols = 10.0 ** np.array(draw(st.lists(st.integers(-3, 3), min_size=n, max_size=n)))
    protected = draw(st.lists(st.integers(0, m - 1), max_size=2, unique=True))
    return base, rows[:, None] * base * cols[None, :], sorted(protected)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(_scaled_H())
def test_security_index_equals_brute_force_at_every_scale(case):
    # the index is invariant under scaling rows (meters) and columns (states): the exact
    # integer enumeration on the unscaled H is the truth for the scaled one
    base, H, protected = case
    est = static_estimation(H)
    for prot in ([], protected):
        truth = _brute_indices(base, prot)
        for method in ("milp", "brute"):
            result = security_index(est, method=method, protected=prot)
            assert result.indices.tolist() == truth, (method, prot)
            assert result.lower_bounds.tolist() == truth, (method, prot)
            _check(est, result)


@pytest.mark.parametrize("method", ["milp", "brute"])
@pytest.mark.parametrize("small", [1e-9, 1e-12, 1e-150])
def test_security_index_is_exact_with_meters_of_very_different_scales(method, small):
    # a meter whose row is far smaller than the others still reads every attack on its
    # state: state 0 of the 1-state H below needs both meters 0 and 1 (index 2), and with
    # meter 1 protected it has no undetectable attack (index inf)
    base = np.array([[-2.0], [2.0], [0.0], [0.0], [0.0]])
    H = base * np.array([[1.0], [small], [1.0], [1.0], [1.0]])
    est = static_estimation(H)
    for prot, truth in (([], [2.0]), ([1], [np.inf])):
        assert _brute_indices(base, prot) == truth
        result = security_index(est, method=method, protected=prot)
        assert result.indices.tolist() == truth, prot
        assert result.lower_bounds.tolist() == truth, prot
        _check(est, result)
    attack = security_index(est, method=method).attacks[0]
    np.testing.assert_array_equal(np.flatnonzero(attack), [0, 1])
    assert attack[1] == pytest.approx(2.0 * small)


@pytest.mark.parametrize("scale", [1e-100, 1e10, 1e100])
def test_budgeted_attack_is_invariant_under_scaling_a_meter_and_its_bound(scale):
    # scaling meter 0's row of H and its a_max alike leaves every attack as it is: the
    # shift of the 1-state H below is min(1/1, 1/1, 1/2, 1/2) = 0.5 on all four meters
    H = np.array([[1.0], [1.0], [2.0], [2.0]])
    D = np.array([scale, 1.0, 1.0, 1.0])
    attack = budgeted_attack(H * D[:, None], 4, a_max=D)
    assert attack.proved and attack.value == pytest.approx(0.5, rel=1e-9)

    # state 0 of this H needs 3 meters (0, 1 and 4): no attack on 2, however small meter 0's
    # row (and its bound) is
    H2 = np.array([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0], [0.0, 1.0], [1.0, 1.0]])
    D2 = np.array([1e-100, 1.0, 1.0, 1.0, 1.0])
    assert security_index(H2, method="brute").indices[0] == 3.0
    for budget in (1, 2):
        attack = budgeted_attack(H2 * D2[:, None], budget, a_max=D2, target=0)
        assert attack.value == 0.0 and attack.proved
