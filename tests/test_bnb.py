"""Branch and bound (baselines.sparse.bnb) and its provable bound (baselines.sparse.bound)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from conftest import attacker_return

from baselines.sparse import bnb as bnb_module
from baselines.sparse import (
    branch_and_bound,
    exhaustive,
    make_problem,
    sfs,
    sfs_ss,
    upper_bound,
)
from baselines.sparse import split as split_module
from baselines.sparse.bnb import _Search
from baselines.sparse.bound import allocation_bound, brute_force_optimum
from baselines.sparse.split import split_bound
from baselines.sparse.testbeds import dc_grid14, mixed_tracking
from fdia_env import scenarios, sparse_attack_v0
from fdia_env.kalman import information_update, predict_cov
from fdia_env.systems import LinearSystem, Sensor

CH4_VALUE = 0.03278559152906327  # tests/test_sparse_solvers.py: the literature's optimum
VALUE_RTOL = 1e-9


def close(a: float, b: float, rtol: float = VALUE_RTOL) -> bool:
    return abs(a - b) <= rtol * max(abs(a), abs(b), 1e-300)


def bound_holds(bound: float, optimum: float) -> bool:
    """The validity check applied to every bound: at least the optimum (rounding allowed)."""
    return bound >= optimum - 1e-10 * max(abs(optimum), 1.0)


def random_system(rng: np.random.Generator) -> tuple[LinearSystem, int, int, str]:
    """A random instance with M·N <= 30: random F, Q (sometimes singular), vector or scalar
    sensors, and repeated sensors (exact ties between attack sets)."""
    n = int(rng.integers(1, 4))
    M = int(rng.integers(1, 6))
    F = rng.normal(size=(n, n))
    F *= rng.uniform(0.5, 1.2) / max(np.abs(np.linalg.eigvals(F)).max(), 1e-9)
    A = rng.normal(size=(n, n))
    Q = A @ A.T * rng.uniform(0.01, 1.0) + (0.0 if rng.random() < 0.3 else 1e-3) * np.eye(n)
    sensors: list[Sensor] = []
    for _ in range(M):
        if sensors and rng.random() < 0.25:
            sensors.append(sensors[-1])  # a tie
            continue
        nz = int(rng.integers(1, min(n, 2) + 1))
        B = rng.normal(size=(nz, nz))
        sensors.append(Sensor(H=rng.normal(size=(nz, n)), R=B @ B.T + 0.1 * np.eye(nz)))
    N = int(rng.integers(1, 30 // M + 1))
    c = int(rng.integers(0, min(4, M * N) + 1))
    objective = "trace" if rng.random() < 0.5 else "logdet"
    return LinearSystem(F=F, Q=Q, sensors=tuple(sensors)), c, N, objective


def play(result, scenario, budget, horizon, objective) -> float:
    env = sparse_attack_v0.parallel_env(
        scenario=scenario,
        budget=budget,
        horizon=horizon,
        objective=objective,
        reward_mode="terminal",
    )
    return attacker_return(env, result.policy())


# --- equal to EXS -------------------------------------------------------------------------


@pytest.mark.parametrize("horizon", [6, 10])
def test_bnb_equals_exhaustive_on_ch4_position(horizon):
    result = branch_and_bound("ch4-position", budget=5, horizon=horizon)
    best = exhaustive("ch4-position", budget=5, horizon=horizon)
    assert close(result.value, best.value)
    assert close(result.value, CH4_VALUE, 1e-12)
    assert result.proved_optimal and result.gap == 0.0 and result.upper_bound == result.value


@pytest.mark.parametrize("case", [1, 2, 3])
def test_bnb_equals_exhaustive_on_pv_cases_with_det_objective(case):
    name = f"ch4-pv-case{case}"
    result = branch_and_bound(name, 5, 6, "logdet")
    best = exhaustive(name, 5, 6, "logdet")
    assert close(result.value, best.value)
    assert result.proved_optimal and result.nodes > 1  # proved by search, not at the root
    assert bound_holds(upper_bound(name, 5, 6, "logdet"), best.value)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_bnb_equals_exhaustive_on_ch4_random(seed):
    sc = scenarios.get("ch4-random", seed=seed)
    result = branch_and_bound(sc, budget=4, horizon=6)
    best = exhaustive(sc, budget=4, horizon=6)
    assert close(result.value, best.value)
    assert bound_holds(upper_bound(sc, 4, 6), best.value)


def test_bnb_proves_the_ch4_position_optimum_at_size_60():
    result = branch_and_bound("ch4-position", budget=5, horizon=20)
    assert result.proved_optimal and result.gap == 0.0
    assert close(result.value, CH4_VALUE, 1e-12)
    assert result.attacks == ((16, 0), (17, 0), (18, 0), (19, 0), (19, 1))


def test_bnb_equals_exhaustive_and_bound_holds_on_200_random_instances():
    rng = np.random.default_rng(2024)
    objectives = set()
    for trial in range(200):
        system, c, N, objective = random_system(rng)
        objectives.add(objective)
        best = exhaustive(system, c, N, objective).value
        # debug mode checks every child bound against its subtree's brute-force optimum (the
        # tree search alone, without the split bound that often proves the optimum at the root)
        tree = branch_and_bound(system, c, N, objective, debug=system.M * N <= 8, split=False)
        result = branch_and_bound(system, c, N, objective)
        for r in (tree, result):
            assert close(r.value, best), (trial, r.value, best)
            assert r.proved_optimal, trial
        assert bound_holds(upper_bound(system, c, N, objective), best), trial
    assert objectives == {"trace", "logdet"}


def test_allocation_bound_is_the_optimum_for_position_sensors():
    sc = scenarios.get("ch4-random", seed=3)
    problem = make_problem(sc, 4, 5)
    bound, pairs = allocation_bound(problem)
    assert pairs is not None and len(pairs) == 4
    assert close(problem.evaluate(pairs), bound, 1e-12)
    assert close(bound, exhaustive(sc, 4, 5).value, 1e-12)


# --- the check can fail -------------------------------------------------------------------


def submodular_bound(problem) -> float:
    """Φ(∅) + the c largest single-pair gains: valid only if Φ were submodular (it is not)."""
    base = problem.evaluate([])
    gains = sorted((problem.evaluate([q]) - base for q in problem.pairs()), reverse=True)
    return base + sum(gains[: problem.budget])


def test_bound_check_catches_invalid_bounds():
    # ch4-position: dropping the same sensor at consecutive steps interacts (super-additive),
    # so the submodularity bound falls below the optimum, and so does the exact bound − ε.
    problem = make_problem("ch4-position", 5, 6)
    best = exhaustive("ch4-position", 5, 6).value
    assert not bound_holds(submodular_bound(problem), best)
    assert submodular_bound(problem) < best * (1 - 1e-3)
    tight = upper_bound("ch4-position", 5, 6)
    assert bound_holds(tight, best)
    assert not bound_holds(tight - 1e-6 * abs(tight), best)


def test_debug_mode_raises_on_an_invalid_node_bound(monkeypatch):
    real = bnb_module.child_bounds

    def too_low(*args, **kwargs):
        return real(*args, **kwargs) * 0.5  # trace values are positive: halving breaks them

    monkeypatch.setattr(bnb_module, "child_bounds", too_low)
    system = mixed_tracking(3, seed=1)
    with pytest.raises(RuntimeError, match="invalid bound"):
        branch_and_bound(system, 2, 2, debug=True, split=False)


# --- the split bound (last step exact, head by a concave tangent) ---------------------------


def test_split_bound_holds_and_its_incumbent_is_feasible_on_200_random_instances():
    rng = np.random.default_rng(11)
    tight = 0
    for trial in range(200):
        system, c, N, objective = random_system(rng)
        problem = make_problem(system, c, N, objective)
        best = exhaustive(system, c, N, objective).value
        cut = split_bound(problem)
        assert bound_holds(cut.bound, best), (trial, cut.bound, best)
        if cut.pairs is not None:  # exactly c pairs of the last step, value exact
            assert len(cut.pairs) == c and all(k == N - 1 for k, _ in cut.pairs)
            assert close(problem.evaluate(cut.pairs), cut.value, 1e-9)
            assert cut.value <= best + 1e-10 * max(abs(best), 1.0)
        tight += bool(np.isfinite(cut.bound) and close(cut.bound, best, 1e-6))
    assert tight >= 20  # the bound is not vacuous: it proves many optima at the root


def test_split_bound_check_fails_without_its_head_term(monkeypatch):
    # Dropping the tangent term (earlier drops assumed worthless) undercuts the optimum where
    # the best attack spends pairs before the last step: ch4-position drops sensor 0 at the
    # last four steps. The validity check must catch it.
    problem = make_problem("ch4-position", 5, 6)
    best = exhaustive("ch4-position", 5, 6).value
    assert bound_holds(split_bound(problem).bound, best)
    monkeypatch.setattr(split_module._Split, "window", lambda self, t, W, *a: np.zeros(len(W)))
    assert not bound_holds(split_bound(problem).bound, best)


@pytest.mark.parametrize("objective", ["trace", "logdet"])
def test_split_bound_equals_exhaustive_on_a_42_pair_meter_grid(objective):
    # 14 injection meters of the DC IEEE 14-bus model over N = 3, c = 4: C(42, 4) = 111,930
    # sets for EXS. The optimum drops four meters at the last step, which is the split bound's
    # incumbent; for log det the bound proves it at the root (trace: 29 % above, the tree
    # search closes the rest).
    system = dc_grid14(14)
    best = exhaustive(system, 4, 3, objective)
    cut = split_bound(make_problem(system, 4, 3, objective))
    assert bound_holds(cut.bound, best.value)
    assert close(cut.value, best.value)
    result = branch_and_bound(system, 4, 3, objective)
    assert result.proved_optimal and close(result.value, best.value)
    if objective == "logdet":
        assert result.nodes == 1  # proved at the root


@pytest.mark.parametrize("objective", ["trace", "logdet"])
@pytest.mark.parametrize("system", [dc_grid14(14), mixed_tracking(6)], ids=["grid", "tracking"])
def test_split_step_values_equal_the_objective_of_the_dropped_posteriors(system, objective):
    # the split bound scores the sets of its last step with b×b algebra only (tr(A⁻¹ K_DD),
    # −log det A): the same Φ as the (n, n) posteriors it no longer forms there
    from baselines.sparse.bound import measurement_factors
    from fdia_env.kalman import objective as phi

    problem = make_problem(system, 3, 3, objective)
    step = split_module._Split(problem, measurement_factors(problem), None).step(2)
    rng = np.random.default_rng(0)
    for b in range(4):
        sets = np.sort([rng.choice(problem.M, b, replace=False) for _ in range(64)], axis=1)
        sets = sets.astype(np.intp).reshape(64, b)
        want = phi(step.drop(sets), objective)
        np.testing.assert_allclose(step.values(sets, objective), want, rtol=1e-12, atol=0)


def test_split_bound_proves_the_300_pair_meter_level_grid_instance_at_the_root():
    # The target: prove 50 meters of the DC IEEE 14-bus model over N = 6 (300 pairs, c = 5,
    # C(300, 5) ≈ 2·10¹⁰ sets). SFS-SS stops 1.5 % short; the split bound proves the optimum.
    system = dc_grid14(50)
    result = branch_and_bound(system, 5, 6, time_limit=120)
    assert result.proved_optimal and result.nodes == 1
    assert result.attacks == ((5, 6), (5, 7), (5, 13), (5, 27), (5, 47))
    heuristic = sfs_ss(system, 5, 6).value
    assert result.value > heuristic * 1.01
    assert close(result.value, make_problem(system, 5, 6).evaluate(list(result.attacks)))


def test_split_bound_proves_the_grid_ieee14_preset_against_the_reference_recursion():
    # pandapower's IEEE 14-bus case, meter level (34 meters, N = 6: 204 pairs): the optimum
    # blanks five meters at the last step. Independent check: the filter's own information
    # update (no Woodbury) for every 5-subset of the last step, from the nominal posterior.
    pytest.importorskip("pandapower")
    result = branch_and_bound("grid-ieee14", 5, 6, time_limit=120)
    assert result.proved_optimal and result.nodes == 1
    problem = make_problem("grid-ieee14", 5, 6)
    sys = problem.system
    P = problem.P_start
    for _ in range(5):
        P = information_update(predict_cov(P, sys.F, sys.Q), sys.J, np.ones(sys.M, dtype=bool))
    used = np.ones((math.comb(sys.M, 5), sys.M), dtype=bool)
    for row, s in enumerate(itertools.combinations(range(sys.M), 5)):
        used[row, list(s)] = False
    last = information_update(predict_cov(P, sys.F, sys.Q)[None], sys.J, used)
    assert close(result.value, float(np.trace(last, axis1=1, axis2=2).max()), 1e-10)


# --- the mixed (tail-enumeration) bound ----------------------------------------------------


def only_mixed_bound(monkeypatch) -> None:
    """Switch the smoother bound off (+inf), so that debug mode checks the mixed bound alone."""
    monkeypatch.setattr(bnb_module, "child_bounds", lambda *a, **k: np.full_like(a[1].a, np.inf))


@pytest.mark.parametrize(
    ("system", "budget", "horizon", "objective"),
    [
        (dc_grid14(14), 2, 4, "trace"),
        (dc_grid14(14), 2, 4, "logdet"),
        (mixed_tracking(3, seed=2), 3, 4, "trace"),  # 2-row sensors: block Woodbury
        (mixed_tracking(3, seed=2), 3, 5, "logdet"),
    ],
)
def test_mixed_bound_alone_holds_at_every_node(monkeypatch, system, budget, horizon, objective):
    # every child bound of the search, at head steps (table) and at the last two steps
    # (enumeration), against its subtree's brute-force optimum
    only_mixed_bound(monkeypatch)
    result = branch_and_bound(system, budget, horizon, objective, debug=True, split=False)
    assert result.proved_optimal
    assert close(result.value, exhaustive(system, budget, horizon, objective).value)


def test_mixed_bound_alone_holds_on_random_instances(monkeypatch):
    only_mixed_bound(monkeypatch)
    rng = np.random.default_rng(7)
    checked = 0
    while checked < 25:
        system, c, N, objective = random_system(rng)
        if N < 3 or system.M * N > 10 or c == 0:
            continue
        result = branch_and_bound(system, c, N, objective, debug=True, split=False)
        assert close(result.value, exhaustive(system, c, N, objective).value), checked
        checked += 1


def test_mixed_bound_is_exact_at_the_last_step_so_the_check_catches_any_undercut(monkeypatch):
    # At the last two steps the mixed bound is the subtree optimum (+ 1e-9 relative); lowering
    # it by 1e-6 relative makes it invalid somewhere and debug mode must say so.
    only_mixed_bound(monkeypatch)
    real = bnb_module.tail_child_bounds

    def undercut(*args, **kwargs):
        b = real(*args, **kwargs)
        return np.where(np.isfinite(b), b - 1e-6 * np.abs(b), b)

    monkeypatch.setattr(bnb_module, "tail_child_bounds", undercut)
    with pytest.raises(RuntimeError, match="invalid bound"):
        branch_and_bound(dc_grid14(14), 2, 3, debug=True, split=False)


def test_tail_table_is_monotone_and_exact_at_the_nominal_posterior():
    problem = make_problem(mixed_tracking(6, seed=3), 4, 3)
    search = _Search(problem, 64, None, False)
    table = search.table
    sigma = np.array([0.0, 1e-3, 0.1, 1.0, 10.0])
    values = np.stack([table.lookup(sigma, np.full(5, b)) for b in range(4)])
    assert np.all(np.diff(values, axis=0) >= 0)  # more drops never lower Φ
    assert np.all(np.diff(values, axis=1) >= 0)  # a larger prior never lowers Φ
    # σ = 0, b drops over the last two steps: the exact optimum with every pair before free of
    # attack, by enumeration over the reference recursion (N = 3: steps 1 and 2)
    pairs = [(k, i) for k in (1, 2) for i in range(6)]
    for b in range(4):
        best = max(problem.evaluate(list(s)) for s in itertools.combinations(pairs, b))
        assert close(values[b, 0], best, 2e-9)
    # σ above the grid: no bound
    assert table.lookup(np.array([1e9]), np.array([1]))[0] == np.inf


@pytest.mark.parametrize("objective", ["trace", "logdet"])
def test_mixed_bound_proves_a_42_pair_grid_instance_equal_to_exhaustive(objective):
    system = dc_grid14(14)
    result = branch_and_bound(system, 3, 3, objective, split=False)
    assert result.proved_optimal
    assert close(result.value, exhaustive(system, 3, 3, objective).value)
    old = branch_and_bound(system, 3, 3, objective, mixed_bound=False, split=False)
    assert close(old.value, result.value) and result.nodes < old.nodes


def test_mixed_bound_certifies_the_84_pair_grid_instance():
    # dc-ieee14-14, N = 6, c = 5: 3·10⁷ sets; the optimum blanks meters 10..14 at the last
    # step. Independent check: the best 5-subset of the last step by the reference recursion.
    system = dc_grid14(14)
    result = branch_and_bound(system, 5, 6)
    assert result.proved_optimal and result.gap == 0.0
    problem = make_problem(system, 5, 6)
    masks = problem.masks([[(5, i) for i in s] for s in itertools.combinations(range(14), 5)])
    assert close(result.value, float(problem.evaluate_masks(masks).max()), 1e-12)
    assert result.value > sfs_ss(system, 5, 6).value * (1 + 1e-3)  # beats the heuristics


def test_brute_force_helper_matches_exhaustive():
    problem = make_problem("ch4-pv-case1", 3, 3, "logdet")
    value = brute_force_optimum(problem, [], problem.pairs(), 3)
    assert close(value, exhaustive("ch4-pv-case1", 3, 3, "logdet").value, 1e-12)


# --- time limit, certificate ---------------------------------------------------------------


def test_time_limit_returns_the_incumbent_with_a_valid_certified_gap():
    system = dc_grid14(14)
    best = exhaustive(system, 3, 2).value  # 28 pairs
    result = branch_and_bound(system, 3, 2, time_limit=0)
    assert not result.proved_optimal
    assert bound_holds(result.upper_bound, best)
    assert result.value <= best * (1 + 1e-12)
    assert 0.0 <= result.gap <= 1.0
    assert result.gap == result.gap_to(result.upper_bound)
    assert result.seconds >= 0 and result.nodes >= 1


def test_bnb_certifies_a_300_pair_instance():
    result = branch_and_bound(mixed_tracking(50), 5, 6, time_limit=120)
    assert result.proved_optimal
    assert result.value >= sfs_ss(mixed_tracking(50), 5, 6).value * (1 - 1e-12)


def test_gap_to_is_relative_in_natural_units():
    r = sfs("ch4-position", 5, 6)
    assert math.isclose(r.gap_to(2 * r.value), 0.5)
    assert r.gap_to(r.value) == 0.0
    assert r.gap_to(math.inf) == 1.0
    d = sfs("ch4-pv-case1", 5, 6, "logdet")
    assert math.isclose(d.gap_to(d.value + math.log(4.0)), 0.75)  # det is 1/4 of the bound's
    with pytest.raises(ValueError, match="bound"):
        r.gap_to("1.0")
    with pytest.raises(ValueError, match="bound"):
        r.gap_to(math.nan)


def test_other_solvers_carry_no_certificate():
    r = exhaustive("ch4-position", 5, 6)
    assert r.upper_bound is None and r.gap is None and r.proved_optimal is None
    assert r.nodes is None and r.seconds is None


# --- the policy -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("scenario", "budget", "horizon", "objective"),
    [("ch4-position", 5, 10, "trace"), ("ch4-pv-case3", 5, 6, "logdet")],
)
def test_policy_replays_the_certified_value_in_the_env(scenario, budget, horizon, objective):
    result = branch_and_bound(scenario, budget, horizon, objective)
    ret = play(result, scenario, budget, horizon, objective)
    assert abs(ret - result.value) <= 1e-12 * abs(result.value)


def test_policy_replays_the_value_on_a_custom_system():
    system = mixed_tracking(4, seed=5)
    result = branch_and_bound(system, 3, 4)
    ret = play(result, system, 3, 4, "trace")
    assert abs(ret - result.value) <= 1e-12 * abs(result.value)


# --- bad input ------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"budget": 19}, "budget"),
        ({"budget": -1}, "budget"),
        ({"budget": 2.5}, "budget"),
        ({"horizon": 0}, "horizon"),
        ({"objective": "max"}, "objective"),
        ({"time_limit": -1.0}, "time_limit"),
        ({"time_limit": "10"}, "time_limit"),
        ({"time_limit": math.nan}, "time_limit"),
        ({"time_limit": True}, "time_limit"),
        ({"chunk": 0}, "chunk"),
        ({"mixed_bound": 1}, "mixed_bound"),
        ({"split": "yes"}, "split must be True or False"),
    ],
)
def test_bad_input_names_the_parameter(kwargs, match):
    args = {"budget": 5, "horizon": 6} | kwargs
    with pytest.raises(ValueError, match=match):
        branch_and_bound("ch4-position", **args)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"budget": 19}, "budget"), ({"objective": "max"}, "objective"), ({"horizon": 0}, "horizon")],
)
def test_upper_bound_bad_input_names_the_parameter(kwargs, match):
    args = {"budget": 5, "horizon": 6} | kwargs
    with pytest.raises(ValueError, match=match):
        upper_bound("ch4-position", **args)
