"""The hard benchmark tasks on the IEEE grids: graded hard, stored optima checked independently."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import linprog

from fdia_env import tasks
from fdia_env.tasks.task import HEURISTIC_HARD, RANDOM_HARD

COVARIANCE = ["covariance/ieee14-v0", "covariance/ieee14-logdet-v0"]
GAMES = [
    "sensor-game/ieee14-strong-k1-attacker-v0",
    "sensor-game/ieee30-strong-attacker-v0",
    "sensor-game/dc-ieee14-50-strong-attacker-v0",
]
STEALTH = [
    "stealth/ieee14-box-b12-v0",
    "stealth/ieee14-box-b8-protected-v0",
    "stealth/ieee14-box-b12-protected-v0",
]
GRID = [*COVARIANCE, *GAMES, *STEALTH]


@pytest.mark.parametrize("name", GRID)
def test_the_grid_task_is_graded_hard_with_a_proved_optimum(name):
    task = tasks.get(name)
    refs = task.references
    assert task.env_kwargs["scenario"] in ("grid-ieee14", "grid-ieee30", "dc-ieee14-50")
    assert task.difficulty == "hard"
    assert refs.optimum.certified and refs.optimum.gap == 0.0
    assert refs.random_ratio <= RANDOM_HARD
    assert refs.heuristic_score <= HEURISTIC_HARD
    for raw in refs.heuristics.values():  # no heuristic beats the proved optimum
        assert raw <= refs.optimum.value * (1 + 1e-12)


def test_the_trace_optimum_is_the_top_eigenvalue_of_the_gain():
    """tr(P + W Σ W') under tr Σ = a² is largest at a² v v', v the top singular vector of W."""
    from baselines.covariance.problem import make_problem

    task = tasks.get("covariance/ieee14-v0")
    kw = task.env_kwargs
    problem = make_problem(kw["scenario"], kw["power"])
    assert np.allclose(problem.weight, np.eye(problem.weight.shape[0]))  # one scalar per meter
    top = np.linalg.svd(problem.W, compute_uv=False)[0]
    closed_form = float(np.trace(problem.P)) + kw["power"] * top**2
    # the stored value is the optimal Σ played in the env through its float32 action
    assert task.references.optimum.value == pytest.approx(closed_form, rel=1e-6)


def test_the_log_det_optimum_meets_its_optimality_conditions():
    """Water-filling's KKT residuals vanish (a certificate: log det is concave in Σ)."""
    from baselines.covariance import det_optimal
    from baselines.covariance.determinant import kkt_residuals

    task = tasks.get("covariance/ieee14-logdet-v0")
    kw = task.env_kwargs
    best = det_optimal(kw["scenario"], kw["power"])
    residuals = kkt_residuals(best)
    checks = (residuals.power, residuals.psd, residuals.stationarity, residuals.dual)
    assert max(checks) < 1e-7 and residuals.multiplier > 0
    problem_value = float(np.linalg.slogdet(best.P + best.W @ best.sigma @ best.W.T)[1])
    assert task.references.optimum.value == pytest.approx(problem_value, abs=1e-5)


def _lp_value(L: np.ndarray) -> float:
    """max_y min_D (L y)_D over mixed y: scipy's LP written here, apart from baselines.game."""
    m, n = L.shape
    scale = float(np.abs(L).max())
    c = np.zeros(n + 1)
    c[-1] = -1.0  # maximise v
    A_ub = np.hstack([-L / scale, np.ones((m, 1))])  # v <= (L y)_D / scale for every row D
    A_eq = np.hstack([np.ones((1, n)), np.zeros((1, 1))])
    bounds = [(0, None)] * n + [(None, None)]
    res = linprog(c, A_ub=A_ub, b_ub=np.zeros(m), A_eq=A_eq, b_eq=[1.0], bounds=bounds)
    assert res.status == 0
    return float(res.x[-1]) * scale


@pytest.mark.parametrize("name", GAMES)
def test_the_game_value_is_the_lp_value_and_the_payoffs_are_the_envs(name):
    from baselines.game import payoff_matrix
    from fdia_env.sensor_game_v0 import parallel_env

    task = tasks.get(name)
    kw = task.env_kwargs
    L = payoff_matrix(kw["scenario"], kw["power"], "independent", kw["max_subset_size"])
    assert task.references.game_value == pytest.approx(_lp_value(L), rel=1e-7)
    env = parallel_env(**kw)
    rng = np.random.default_rng(0)
    for d, a in zip(
        rng.integers(L.shape[0], size=4), rng.integers(L.shape[1], size=4), strict=True
    ):
        env.reset(seed=0)
        _, rewards, *_ = env.step({"defender": int(d), "attacker": int(a)})
        assert rewards["attacker"] == pytest.approx(L[d, a], rel=1e-9)
    env.close()


def _box_shift_returns(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every box shift's expected return, from H, R and scipy's χ² laws alone.

    Pattern ``bits`` injects ``a = s H bits`` with ``s = a_max / max |H bits|``, protected
    meters zeroed, only the ``budget`` largest ``|a_i|`` kept (ties: the lower position); the
    χ² test on the WLS residual alarms with ``P[χ²_{m−n}(λ) > τ]``, ``λ = |R^{-1/2}(I − H K) a|²``
    (α where the residual is zero), and the return is ``(1 − p) |K a|_∞``.

    Returns:
        ``(bits, returns, undetectable)`` over the 2^n − 1 non-empty patterns.
    """
    from scipy.stats import chi2, ncx2

    from fdia_env.stealth import static_estimation

    kw = tasks.get(name).env_kwargs
    est = static_estimation(kw["scenario"])
    H, R, n, m = est.H, est.R, est.n, est.m
    bits = ((np.arange(1, 2**n)[:, None] >> np.arange(n)) & 1).astype(float)
    a = bits @ H.T
    a *= kw["a_max"] / np.abs(a).max(axis=1, keepdims=True)
    a[:, [list(est.meters).index(p) for p in kw.get("protected", [])]] = 0.0
    a[np.abs(a) <= 1e-12 * np.abs(a).max(axis=1, keepdims=True)] = 0.0
    drop = np.argsort(-np.abs(a), axis=1, kind="stable")[:, kw["budget"] :]
    np.put_along_axis(a, drop, 0.0, axis=1)
    Rinv = np.linalg.inv(R)
    K = np.linalg.solve(H.T @ Rinv @ H, H.T @ Rinv)
    white = (a - a @ (H @ K).T) / np.sqrt(np.diag(R))
    lam = (white**2).sum(axis=1)
    size = np.sqrt(((a / np.sqrt(np.diag(R))) ** 2).sum(axis=1))
    undetectable = np.sqrt(lam) <= 1e-9 * size
    tau = chi2.isf(est.alpha, m - n)
    p = np.where(undetectable, est.alpha, ncx2.sf(tau, m - n, np.maximum(lam, 1e-300)))
    return bits, (1 - p) * np.abs(a @ K.T).max(axis=1), undetectable


@pytest.mark.parametrize("name", STEALTH)
def test_the_stealth_optimum_equals_an_exhaustive_search_written_apart_from_the_env(name):
    task = tasks.get(name)
    refs = task.references
    bits, returns, undetectable = _box_shift_returns(name)
    best = int(returns.argmax())
    assert refs.optimum.value == pytest.approx(returns[best], rel=1e-9)
    states = np.flatnonzero(bits[best])
    assert len(states) >= 4  # a group of states: no single-state shift reaches it
    single = returns[bits.sum(axis=1) == 1].max()
    assert refs.heuristics["best single-state shift"] == pytest.approx(single, rel=1e-9)
    assert single < returns[best]
    with task.make_env() as env:  # played in the env, the pattern pays it
        env.reset(seed=0)
        _, reward, *_ = env.step(bits[best].astype(np.int8))
    assert reward == pytest.approx(refs.optimum.value, rel=1e-12)
    if name == "stealth/ieee14-box-b8-protected-v0":  # the best attack is seen now and then:
        assert not undetectable[best]  # every undetectable one pays at most a single shift's
        assert returns[undetectable].max() == pytest.approx(single, rel=1e-9)
    else:
        assert undetectable[best]


def test_protecting_the_7_8_flow_meter_blocks_the_best_single_state_shift():
    """Unprotected, bus 8's three meters give the best single-state shift; protected, not."""
    open_ = tasks.get("stealth/ieee14-box-b12-v0").references
    guarded = tasks.get("stealth/ieee14-box-b12-protected-v0").references
    assert guarded.optimum.value == pytest.approx(open_.optimum.value, rel=1e-12)
    assert (
        guarded.heuristics["best single-state shift"] < open_.heuristics["best single-state shift"]
    )
