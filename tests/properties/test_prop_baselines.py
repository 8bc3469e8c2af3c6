"""Property: every public baseline function returns sane numbers or names a parameter.

Each public function of ``baselines.sparse``, ``baselines.covariance``, ``baselines.game`` and
``baselines.detection`` gets arbitrary arguments (valid tiny problems mixed with edge numbers and
wrong types). Either the result is sane (every number finite, every covariance symmetric PSD,
every mixed strategy on the simplex), or the call raises ``ValueError``/``TypeError`` naming one
of the parameters passed.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from hypothesis import example, given
from hypothesis import strategies as st
from prop_support import (
    assert_psd,
    assert_simplex,
    kwargs_of,
    matrix_values,
    outcome,
    pd_matrices,
    prop_settings,
    small_matrices,
)

import baselines.covariance as cov
import baselines.detection as det
import baselines.game as game
import baselines.sparse as sparse
from fdia_env import scenarios

pytestmark = pytest.mark.filterwarnings("ignore")

# fields that are covariances (checked PSD) and fields that may be infinite by design
PSD_FIELDS = {"sigma", "P", "Pxx", "Pww", "Pbb", "Pzz0", "Pzz1", "R", "covariance", "weight"}
MAY_BE_INFINITE = {"threshold"}
STRATEGY_FIELDS = {"x", "y"}


def assert_sane(value: Any, where: str = "result", depth: int = 0) -> None:
    """Every number finite, covariances PSD, mixed strategies on the simplex (recursively)."""
    if depth > 4 or value is None or isinstance(value, str | bool):
        return
    name = where.rsplit(".", 1)[-1]
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        for field in dataclasses.fields(value):
            if field.name not in ("original", "problem", "info"):
                assert_sane(getattr(value, field.name), f"{where}.{field.name}", depth + 1)
        return
    if isinstance(value, dict):
        for key, item in value.items():
            assert_sane(item, f"{where}[{key!r}]", depth + 1)
        return
    if isinstance(value, tuple | list):
        for i, item in enumerate(value):
            assert_sane(item, f"{where}[{i}]", depth + 1)
        return
    if isinstance(value, int | float | np.number | np.ndarray):
        arr = np.asarray(value)
        if arr.dtype.kind not in "biuf":
            return
        if name in MAY_BE_INFINITE:
            assert not np.any(np.isnan(arr)), f"{where} is NaN: {value}"
            return
        assert np.all(np.isfinite(arr)), f"{where} not finite: {value}"
        if name in PSD_FIELDS and arr.ndim >= 2 and arr.shape[-1] == arr.shape[-2]:
            assert_psd(arr, where, rtol=1e-7)
        if name in STRATEGY_FIELDS and arr.ndim == 1:
            assert_simplex(arr, where)


# --- valid tiny inputs ------------------------------------------------------------------------
SPARSE_SCENARIOS = ["ch4-position", "ch2-position", "ch4-pv-case1"]
sparse_system = st.one_of(
    st.sampled_from(SPARSE_SCENARIOS),
    st.sampled_from(SPARSE_SCENARIOS).map(lambda n: scenarios.get(n).system),
)
objective = st.sampled_from(["trace", "logdet"])
power = st.one_of(st.none(), st.floats(1e-6, 1e12), st.sampled_from([1.0, 100.0, 3000.0]))


def _sparse_params() -> dict:
    return {
        "system_or_scenario": sparse_system,
        "budget": st.integers(0, 3),
        "horizon": st.integers(1, 3),
        "objective": objective,
    }


COV_SCENARIOS = ["ch2-position", "ch2-pv-1", "ch2-pv-2", "ch4-position"]
cov_system = st.sampled_from(COV_SCENARIOS)
game_system = st.sampled_from(["ch5-game", "ch2-position", "ch4-position"])
payoffs = st.one_of(
    st.sampled_from(["ch5-game", "ch2-position"]).map(game.payoff_matrix),
    small_matrices(4, 4),
)


@st.composite
def sigmas_for(draw, nz: int, k: int | None = None) -> np.ndarray:
    """PSD (nz, nz) matrices, or a (k, nz, nz) stack."""
    if k is None:
        return draw(pd_matrices(nz))
    return np.stack([draw(pd_matrices(nz)) for _ in range(k)])


static = det.static_problem("ch3-static", 100.0)
problems = st.one_of(
    st.builds(det.static_problem, st.just("ch3-static"), st.floats(1e-3, 1e6)),
    st.builds(det.tracking_problem, st.just("ch3-tracking"), st.floats(1e-3, 1e6)),
)
detectors = st.one_of(
    problems.map(det.obdd), problems.map(det.obdi), problems.map(det.cbd), problems.map(det.csd)
)

# name -> (function, {parameter: valid strategy}, required parameters)
FUNCTIONS: dict[str, tuple[Callable, dict, tuple[str, ...]]] = {
    # sparse
    "sparse.exhaustive": (sparse.exhaustive, _sparse_params(), ("system_or_scenario",)),
    "sparse.sfs": (sparse.sfs, _sparse_params(), ("system_or_scenario",)),
    "sparse.sbs": (sparse.sbs, _sparse_params(), ("system_or_scenario",)),
    "sparse.sfs_ss": (sparse.sfs_ss, _sparse_params(), ("system_or_scenario",)),
    "sparse.dp": (sparse.dp, _sparse_params(), ("system_or_scenario",)),
    "sparse.make_problem": (
        sparse.make_problem,
        _sparse_params(),
        ("system_or_scenario", "budget", "horizon"),
    ),
    # covariance
    "covariance.trace_optimal": (
        cov.trace_optimal,
        {
            "system_or_scenario": cov_system,
            "power": power,
            "structure": st.sampled_from(["full", "diagonal"]),
            "weight": st.one_of(st.none(), matrix_values()),
        },
        ("system_or_scenario",),
    ),
    "covariance.det_optimal": (
        cov.det_optimal,
        {
            "system_or_scenario": cov_system,
            "power": power,
            "weight": st.one_of(st.none(), matrix_values()),
        },
        ("system_or_scenario",),
    ),
    "covariance.independent_position_rule": (
        cov.independent_position_rule,
        {"system_or_scenario": cov_system, "power": power},
        ("system_or_scenario",),
    ),
    "covariance.dependent_position_rule": (
        cov.dependent_position_rule,
        {"system_or_scenario": cov_system, "power": power},
        ("system_or_scenario",),
    ),
    "covariance.pv_single_sensor_rule": (
        cov.pv_single_sensor_rule,
        {"system_or_scenario": cov_system, "power": power},
        ("system_or_scenario",),
    ),
    "covariance.multi_shot": (
        cov.multi_shot,
        {
            "system_or_scenario": cov_system,
            "power": power,
            "horizon": st.integers(1, 4),
            "weights": st.one_of(st.none(), st.lists(st.floats(0, 2), min_size=1, max_size=4)),
            "power_mode": st.sampled_from(["budget", "per_step"]),
        },
        ("system_or_scenario", "power", "horizon"),
    ),
    "covariance.equivalent_sensor": (
        cov.equivalent_sensor,
        {"system_or_scenario": cov_system},
        ("system_or_scenario",),
    ),
    "covariance.evaluate": (
        cov.evaluate,
        {
            "system_or_scenario": st.just("ch2-position"),
            "sigma": st.one_of(sigmas_for(2), matrix_values()),
            "objective": objective,
        },
        ("system_or_scenario", "sigma"),
    ),
    "covariance.water_filling": (
        cov.water_filling,
        {
            "xi": st.lists(st.floats(1e-6, 1e6), min_size=1, max_size=4).map(np.array),
            "power": st.floats(1e-6, 1e6),
        },
        ("xi", "power"),
    ),
    "covariance.recursion_objective": (
        cov.recursion_objective,
        {"system_or_scenario": st.just("ch2-position"), "sigmas": sigmas_for(2, 2)},
        ("system_or_scenario", "sigmas"),
    ),
    "covariance.make_problem": (
        cov.make_problem,
        {"system_or_scenario": cov_system, "power": power},
        ("system_or_scenario",),
    ),
    # game
    "game.payoff_matrix": (
        game.payoff_matrix,
        {
            "system_or_scenario": game_system,
            "power": power,
            "allocation": st.sampled_from(["independent", "dependent"]),
        },
        ("system_or_scenario",),
    ),
    "game.solve_zero_sum": (game.solve_zero_sum, {"L": payoffs}, ("L",)),
    "game.solve_bayesian": (
        game.solve_bayesian,
        {
            "matrices": st.lists(
                st.sampled_from(["ch5-game"]).map(game.payoff_matrix), min_size=1, max_size=2
            ),
            "priors": st.lists(st.floats(0, 1), min_size=1, max_size=2),
            "attacker": st.sampled_from(["uninformed", "informed"]),
        },
        ("matrices", "priors"),
    ),
    "game.solve_double_oracle": (
        game.solve_double_oracle,
        {
            "system_or_scenario": game_system,
            "power": power,
            "allocation": st.sampled_from(["independent", "dependent"]),
            "tol": st.floats(1e-12, 1e-3),
            "max_iter": st.integers(1, 50),
        },
        ("system_or_scenario",),
    ),
    "game.strategy_bounds": (
        game.strategy_bounds,
        {"L": payoffs, "player": st.sampled_from(["defender", "attacker"])},
        ("L",),
    ),
    "game.attack_covariance": (
        game.attack_covariance,
        {
            "system": st.just(scenarios.get("ch5-game").system),
            "subset": st.lists(st.integers(0, 2), min_size=1, max_size=3, unique=True),
            "power": st.floats(1e-6, 1e12),
            "allocation": st.sampled_from(["independent", "dependent"]),
        },
        ("system", "subset", "power"),
    ),
    # detection
    "detection.static_problem": (
        det.static_problem,
        {
            "scenario": st.just("ch3-static"),
            "power": st.floats(1e-6, 1e12),
            "Pbb": st.one_of(st.none(), pd_matrices(2)),
            "p1": st.one_of(st.none(), st.floats(0, 1)),
        },
        (),
    ),
    "detection.tracking_problem": (
        det.tracking_problem,
        {
            "scenario": st.just("ch3-tracking"),
            "power": st.floats(1e-6, 1e12),
            "Pbb": st.one_of(st.none(), pd_matrices(2)),
            "p1": st.one_of(st.none(), st.floats(0, 1)),
        },
        (),
    ),
    "detection.obdd": (det.obdd, {"problem": problems}, ("problem",)),
    "detection.obdi": (det.obdi, {"problem": problems}, ("problem",)),
    "detection.cbd": (det.cbd, {"problem": problems}, ("problem",)),
    "detection.csd": (
        det.csd,
        {"problem": problems, "level": st.floats(0, 1)},
        ("problem",),
    ),
    "detection.mmse": (det.mmse, {"problem": problems}, ("problem",)),
    "detection.bayes_cost": (
        det.bayes_cost,
        {"detector": detectors, "truth": st.one_of(st.none(), problems)},
        ("detector",),
    ),
    "detection.expected_mse": (
        det.expected_mse,
        {"detector": detectors, "truth": st.one_of(st.none(), problems)},
        ("detector",),
    ),
    "detection.detection_probabilities": (
        det.detection_probabilities,
        {"detector": detectors},
        ("detector",),
    ),
    "detection.c2_optimal_pbb": (
        det.c2_optimal_pbb,
        {
            "Pxx": pd_matrices(2),
            "H": st.just(np.eye(2)),
            "Pww": pd_matrices(2),
            "power": st.floats(1e-6, 1e12),
        },
        ("Pxx", "H", "Pww", "power"),
    ),
    "detection.gchisq_sf": (
        det.gchisq_sf,
        {
            "x": st.floats(0, 1e3),
            "weights": st.lists(st.floats(-10, 10), min_size=1, max_size=3).map(np.array),
        },
        ("x", "weights"),
    ),
    "detection.quadratic_form_weights": (
        det.quadratic_form_weights,
        {"A": pd_matrices(2), "cov": pd_matrices(2)},
        ("A", "cov"),
    ),
}

# parameters a message may name although not passed: required when the scenario has no default
IMPLIED = {"sparse": ("budget", "horizon"), "covariance": ("power",), "game": ("power",)}


def _check_call(name: str, kwargs: dict) -> None:
    func = FUNCTIONS[name][0]
    names = [*kwargs, *IMPLIED.get(name.split(".")[0], ())]
    built, result = outcome(lambda: func(**kwargs), names)
    if built:
        assert_sane(result, name)


def _params(name: str):
    return kwargs_of(FUNCTIONS[name][1], required=FUNCTIONS[name][2])


@pytest.mark.parametrize("name", sorted(FUNCTIONS))
@prop_settings(12)
@given(data=st.data())
def test_baseline_returns_sane_numbers_or_names_a_parameter(name, data):
    _check_call(name, data.draw(_params(name), label="kwargs"))


@example(static)
@prop_settings(5)
@given(problem=problems)
def test_detection_problem_covariances_are_psd(problem):
    assert_sane(problem, "problem")
