"""Sparse-attack solvers (docs/math.md §4) against the literature values and each other."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from baselines.sparse import SOLVERS, dp, exhaustive, make_problem, sfs, sfs_ss
from fdia_env.systems import LinearSystem, Sensor, pv_sensor, tracking_system

# tr P[K+N|K+N] of the optimal ch4-position attack (docs/references.md §4 prints 0.0328 / 0.03279),
# cross-checked against an independent recursion (test_reference_value_from_first_principles).
CH4_VALUE = 0.03278559152906327
CH4_RTOL = 1e-12
HEURISTICS = {name: f for name, f in SOLVERS.items() if name != "exs"}


def rel(a: float, b: float) -> float:
    return abs(a - b) / abs(b)


def brute_force(problem) -> float:
    """Φ maximised over every exactly-c set, one plain recursion per batch of sets."""
    pairs = problem.pairs()
    sets = list(itertools.combinations(pairs, problem.budget))
    return float(problem.evaluate_masks(problem.masks(sets)).max())


# --- the literature's instance -------------------------------------------------------------


def test_reference_value_from_first_principles():
    # Independent of fdia_env.kalman: DARE by iteration, covariance-form updates per sensor.
    F = np.array([[1.0, 1.0], [0.0, 1.0]])
    Q = 0.02**2 * np.array([[0.25, 0.5], [0.5, 1.0]])
    H = np.array([[1.0, 0.0]])
    var = [0.2**2, 0.4**2, 0.5**2]

    def step(P, used):
        P = F @ P @ F.T + Q
        for i in used:
            S = H @ P @ H.T + var[i]
            W = P @ H.T / S
            P = P - W @ S @ W.T
        return P

    P = np.eye(2)
    for _ in range(5000):
        P = step(P, [0, 1, 2])
    attacked = {2: [0], 3: [0], 4: [0], 5: [0, 1]}
    for k in range(6):
        P = step(P, [i for i in range(3) if i not in attacked.get(k, [])])
    assert rel(np.trace(P), CH4_VALUE) < 1e-10


# EXS at N = 20 searches all 5,461,512 sets (M·N = 60, c = 5): about 0.6 s here.
@pytest.mark.parametrize(("name", "horizon"), [(name, N) for N in (6, 10, 20) for name in SOLVERS])
def test_every_solver_finds_the_literature_optimum(name, horizon):
    result = SOLVERS[name]("ch4-position", budget=5, horizon=horizon)
    assert rel(result.value, CH4_VALUE) < CH4_RTOL
    assert round(result.value, 4) == 0.0328
    N = horizon
    assert result.attacks == ((N - 4, 0), (N - 3, 0), (N - 2, 0), (N - 1, 0), (N - 1, 1))


def test_sfs_reproduces_the_literature_pick_order():
    result = sfs("ch4-position", budget=5, horizon=6)
    expected = np.array(
        [
            [0, 0, 5, 3, 2, 1],
            [0, 0, 0, 0, 0, 4],
            [0, 0, 0, 0, 0, 0],
        ]
    )
    np.testing.assert_array_equal(result.grid(), expected)
    assert result.order == ((5, 0), (4, 0), (3, 0), (5, 1), (2, 0))


def test_sfs_order_prefix_is_the_smaller_budget_answer():
    full = sfs("ch4-position", budget=5, horizon=6)
    for b in range(5):
        assert sfs("ch4-position", budget=b, horizon=6).order == full.order[:b]


def test_exhaustive_matches_brute_force_on_ch4():
    problem = make_problem("ch4-position", budget=3, horizon=4)
    result = exhaustive("ch4-position", budget=3, horizon=4)
    assert rel(result.value, brute_force(problem)) < 1e-13
    assert result.evaluations == 220


@pytest.mark.parametrize("case", [1, 2, 3])
def test_exhaustive_fast_path_equals_generic_path_on_pv_cases(case):
    fast = exhaustive(f"ch4-pv-case{case}", budget=5, horizon=6, objective="logdet")
    slow = exhaustive(f"ch4-pv-case{case}", budget=5, horizon=6, objective="logdet", fast=False)
    assert fast.attacks == slow.attacks
    assert rel(fast.value, slow.value) < 1e-12


@pytest.mark.parametrize("chunk_rows", [1, 7, 1000])
def test_exhaustive_chunking_does_not_change_the_answer(chunk_rows):
    ref = exhaustive("ch4-position", budget=4, horizon=5)
    got = exhaustive("ch4-position", budget=4, horizon=5, chunk_rows=chunk_rows)
    assert got.attacks == ref.attacks and got.value == ref.value


def test_zero_budget_and_full_budget():
    clean = make_problem("ch4-position", budget=0, horizon=3)
    for f in SOLVERS.values():
        assert f("ch4-position", budget=0, horizon=3).attacks == ()
        assert f("ch4-position", budget=0, horizon=3).value == clean.evaluate([])
        full = f("ch4-position", budget=6, horizon=2)
        assert full.attacks == tuple((k, i) for k in range(2) for i in range(3))


# --- bad input ----------------------------------------------------------------------------


@pytest.mark.parametrize("solver", list(SOLVERS.values()), ids=list(SOLVERS))
def test_budget_above_pair_count_is_rejected(solver):
    with pytest.raises(ValueError, match="budget"):
        solver("ch4-position", budget=19, horizon=6)


@pytest.mark.parametrize("solver", list(SOLVERS.values()), ids=list(SOLVERS))
def test_negative_budget_is_rejected(solver):
    with pytest.raises(ValueError, match="budget"):
        solver("ch4-position", budget=-1, horizon=6)


@pytest.mark.parametrize("solver", list(SOLVERS.values()), ids=list(SOLVERS))
def test_non_integer_budget_is_rejected(solver):
    with pytest.raises(ValueError, match="budget"):
        solver("ch4-position", budget=2.5, horizon=6)


@pytest.mark.parametrize("solver", list(SOLVERS.values()), ids=list(SOLVERS))
def test_horizon_below_one_is_rejected(solver):
    with pytest.raises(ValueError, match="horizon"):
        solver("ch4-position", budget=0, horizon=0)


@pytest.mark.parametrize("solver", list(SOLVERS.values()), ids=list(SOLVERS))
def test_unknown_objective_is_rejected(solver):
    with pytest.raises(ValueError, match="objective"):
        solver("ch4-position", budget=2, horizon=3, objective="max_eig")


def test_unknown_scenario_is_rejected():
    with pytest.raises(ValueError, match="unknown scenario"):
        sfs("ch4-nowhere", budget=2, horizon=3)


# --- random small problems ----------------------------------------------------------------


@st.composite
def small_problems(draw):
    """(system, budget, horizon, objective): tracking models with M <= 3, N <= 4, c <= 4."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    M = draw(st.integers(1, 3))
    N = draw(st.integers(1, 4))
    c = draw(st.integers(0, min(4, M * N)))
    if draw(st.booleans()):
        system = tracking_system(
            rng.uniform(0.01, 1.0), list(rng.uniform(0.05, 2.0, M)), T=rng.uniform(0.2, 2.0)
        )
        objective = draw(st.sampled_from(["trace", "logdet"]))
    else:
        sensors = [pv_sensor(*rng.uniform(0.1, 1.0, 2), rng.uniform(-0.8, 0.8)) for _ in range(M)]
        system = tracking_system(rng.uniform(0.001, 0.5), sensors=sensors)
        objective = "logdet"
    return system, c, N, objective


@st.composite
def scalar_problems(draw):
    """Scalar-state systems (n = 1) with scalar sensors: DP is exact there."""
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    M = draw(st.integers(1, 3))
    N = draw(st.integers(1, 4))
    c = draw(st.integers(0, min(4, M * N)))
    sensors = tuple(
        Sensor(H=[[rng.uniform(0.2, 2.0)]], R=[[rng.uniform(0.05, 3.0)]]) for _ in range(M)
    )
    system = LinearSystem(
        F=[[rng.uniform(-1.5, 1.5)]], Q=[[rng.uniform(0.01, 2.0)]], sensors=sensors
    )
    return system, c, N, draw(st.sampled_from(["trace", "logdet"]))


def at_least(a: float, b: float) -> bool:
    return a >= b - 1e-12 * max(abs(a), abs(b), 1e-300)


@settings(max_examples=40, deadline=None)
@given(small_problems())
def test_exhaustive_is_optimal_and_bounds_every_heuristic(args):
    system, c, N, objective = args
    best = exhaustive(system, c, N, objective)
    assert rel(best.value, brute_force(make_problem(system, c, N, objective))) < 1e-12
    assert len(best.attacks) == c
    for name, solver in HEURISTICS.items():
        result = solver(system, c, N, objective)
        assert len(set(result.attacks)) == c, name
        assert at_least(best.value, result.value), name


@settings(max_examples=40, deadline=None)
@given(small_problems())
def test_sfs_ss_is_never_worse_than_sfs(args):
    assert at_least(sfs_ss(*args).value, sfs(*args).value)


@settings(max_examples=40, deadline=None)
@given(scalar_problems())
def test_dp_equals_exhaustive_for_a_scalar_state(args):
    exact = exhaustive(*args)
    assert abs(dp(*args).value - exact.value) <= 1e-12 * max(abs(exact.value), 1.0)


@settings(max_examples=30, deadline=None)
@given(small_problems())
def test_exhaustive_fast_path_equals_generic_path(args):
    system, c, N, objective = args
    fast = exhaustive(system, c, N, objective)
    slow = exhaustive(system, c, N, objective, fast=False)
    assert abs(fast.value - slow.value) <= 1e-12 * max(abs(slow.value), 1.0)


@settings(max_examples=30, deadline=None)
@given(small_problems(), st.integers(0, 2**32 - 1))
def test_attacking_one_more_pair_never_lowers_the_objective(args, seed):
    system, _, N, objective = args
    problem = make_problem(system, 0, N, objective)
    rng = np.random.default_rng(seed)
    attacked = rng.random((N, system.M)) < 0.5
    free = np.argwhere(~attacked)
    if len(free) == 0:
        return
    more = attacked.copy()
    more[tuple(free[rng.integers(len(free))])] = True
    before, after = problem.evaluate_masks(np.stack([attacked, more]))
    assert at_least(after, before)


def test_generic_path_handles_a_three_state_system():
    F = np.array([[1.0, 1.0, 0.5], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]])
    sensors = (
        Sensor(H=[[1.0, 0.0, 0.0]], R=[[0.09]]),
        Sensor(H=[[1.0, 0.0, 0.0]], R=[[0.25]]),
        Sensor(H=[[0.0, 1.0, 0.0]], R=[[0.2]]),
    )
    system = LinearSystem(F=F, Q=0.01 * np.eye(3), sensors=sensors)
    result = exhaustive(system, 3, 3)
    assert rel(result.value, brute_force(make_problem(system, 3, 3))) < 1e-12
    for solver in HEURISTICS.values():
        assert at_least(result.value, solver(system, 3, 3).value)


# --- the reproduction script --------------------------------------------------------------


def test_reproduce_ch4_quick_writes_its_section(tmp_path, capsys):
    from experiments import reproduce

    output = tmp_path / "reproduction.md"
    output.write_text("# Title\n\n## Chapter 5: games\n\nkept\n")
    assert reproduce.main(["ch4", "--quick", "--output", str(output)]) == 0
    text = output.read_text()
    assert "## Chapter 5: games\n\nkept" in text
    assert "## Chapter 4: sparse attacks" in text
    assert "Identical: **yes**" in text
    assert (tmp_path / "figures" / "ch4_dp_vs_sfs.png").stat().st_size > 0
    assert "Table 2" in capsys.readouterr().out
    # rerunning replaces the section rather than appending a second one
    reproduce.main(["ch4", "--quick", "--output", str(output)])
    assert output.read_text().count("## Chapter 4") == 1


def test_a_solver_added_to_solvers_reaches_the_reproduction_tables(monkeypatch):
    """A new solver needs only its module and its SOLVERS entry: the tables label it."""
    from experiments.reproduce import ch4

    monkeypatch.setattr(ch4, "SOLVERS", {"sfs": sfs, "toy_greedy": sfs})
    rows = [line for line in ch4.ch4_table2(1, warmup=False).splitlines() if "TOY" in line]
    assert [row.split(" | ")[:2] for row in rows] == [
        ["| 18", "TOY-GREEDY"],
        ["| 30", "TOY-GREEDY"],
        ["| 60", "TOY-GREEDY"],
    ]
    assert all(row.endswith("| not in the literature | – |") for row in rows)
    assert ch4.literature_columns("sfs", 2, 0.249 / 2) == ("0.249", "2.0×")
    assert ch4.literature_columns("exs", 2, 1.0) == ("not feasible", "–")
    assert [ch4.solver_label(n) for n in ("exs", "sfs_ss", "dp")] == ["EXS", "SFS-SS", "DP"]
