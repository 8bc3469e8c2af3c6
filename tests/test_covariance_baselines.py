"""Closed-form attack covariances (docs/math.md §2): literature values, optima, special cases.

The numerical oracle maximises over every admissible Σ with the exact power: a square factor L,
``Σ̃ = a² L L' / ‖L‖_F²`` (PSD with trace a², every such matrix reachable) and
``Σ = Ω^{-1/2} Σ̃ Ω^{-1/2}``, by L-BFGS from many random starts, with the analytic gradient
``(2a²/s) (G L − (tr(L' G L)/s) L)``, ``s = ‖L‖_F²``, G the objective's gradient in Σ̃.
"""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest
import scipy.linalg
import scipy.optimize
from conftest import attacker_return, random_pd
from hypothesis import given, settings
from hypothesis import strategies as st

import fdia_env  # noqa: F401  (registers the Gymnasium ids)
from baselines.covariance import (
    CovariancePolicy,
    dependent_position_rule,
    det_optimal,
    equivalent_sensor,
    evaluate,
    independent_position_rule,
    kkt_residuals,
    multi_shot,
    pv_single_sensor_rule,
    recursion_objective,
    trace_optimal,
    water_filling,
)
from fdia_env import covariance_attack_v0, scenarios
from fdia_env.attacks.covariance import CovarianceAttack
from fdia_env.kalman import steady_state
from fdia_env.systems import LinearSystem, Sensor, power_weight, pv_sensor, tracking_system

RTOL = 1e-6  # closed form against the numerical optimum
EXACT = 1e-10  # two closed forms of the same thing
HYP = settings(max_examples=30, deadline=None, derandomize=True)

# --- random problems ------------------------------------------------------------------------


@st.composite
def systems(draw) -> LinearSystem:
    """Tracking systems (position and position+velocity sensors) or general systems (n ≤ 3).

    The entries come from a numpy Generator seeded by hypothesis; Q is positive definite so the
    steady-state P is too (the determinant objective needs P⁻¹).
    """
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    if draw(st.booleans()):
        n_pos, n_pv = rng.integers(0, 3), rng.integers(0, 3)
        n_pos = max(n_pos, 1 - n_pv)
        sensors = [
            pv_sensor(rng.uniform(0.2, 3.0), rng.uniform(0.2, 3.0), rng.uniform(-0.8, 0.8))
            for _ in range(n_pv)
        ]
        return tracking_system(
            rng.uniform(0.05, 2.0),
            list(rng.uniform(0.2, 3.0, size=n_pos)),
            T=rng.uniform(0.2, 2.0),
            sensors=sensors,
        )
    n = int(rng.integers(1, 4))
    U, _ = np.linalg.qr(rng.standard_normal((n, n)))
    V, _ = np.linalg.qr(rng.standard_normal((n, n)))
    F = (U * rng.uniform(0.3, 1.1, n)) @ V.T
    dims = rng.integers(1, 3, size=rng.integers(1, 4))
    sensors = tuple(Sensor(rng.standard_normal((d, n)), random_pd(rng, d, 0.1, 5.0)) for d in dims)
    return LinearSystem(F=F, Q=random_pd(rng, n, 0.05, 2.0), sensors=sensors)


@st.composite
def problems(draw) -> tuple[LinearSystem, float, np.ndarray | None]:
    """A system, a power a² in [1e-2, 1e4] and a weight Ω (the default or a random SPD one)."""
    system = draw(systems())
    power = 10.0 ** draw(st.floats(-2.0, 4.0))
    weight = None
    if draw(st.booleans()):
        rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
        weight = random_pd(rng, system.nz, 0.2, 5.0)
    return system, power, weight


def inv_sqrt(A: np.ndarray) -> np.ndarray:
    w, V = np.linalg.eigh(A)
    return (V / np.sqrt(w)) @ V.T


def numerical_max(objective, d: int, power: float, mask: np.ndarray, seed: int, starts: int):
    """max over L of ``objective(Σ̃)`` with ``Σ̃ = a² L L' / ‖L‖²``, L restricted to ``mask``.

    ``objective(St) -> (value, G)`` returns the value and its gradient in Σ̃.
    """
    rng = np.random.default_rng(seed)

    def neg(x):
        L = np.where(mask, x.reshape(d, d), 0.0)
        s = np.sum(L * L)
        value, G = objective(power * L @ L.T / s)
        GL = G @ L
        grad = (2.0 * power / s) * (GL - (np.sum(L * GL) / s) * L)
        return -value, -np.where(mask, grad, 0.0).ravel()

    best = -np.inf
    for _ in range(starts):
        res = scipy.optimize.minimize(
            neg,
            rng.standard_normal(d * d),
            jac=True,
            method="L-BFGS-B",
            options={"maxiter": 10_000, "ftol": 1e-16, "gtol": 1e-12},
        )
        best = max(best, -res.fun)
    return best


def block_mask(system: LinearSystem, structure: str) -> np.ndarray:
    if structure == "full":
        return np.ones((system.nz, system.nz), dtype=bool)
    return system.row_sensor[:, None] == system.row_sensor[None, :]


def weight_inv_half(system: LinearSystem, weight, structure: str) -> np.ndarray:
    """Ω^{-1/2}, or blockdiag(Ω_ii^{-1/2}) for block-diagonal Σ (only Ω's blocks count then)."""
    omega = power_weight(system) if weight is None else weight
    if structure == "full":
        return inv_sqrt(omega)
    blocks = [
        inv_sqrt(omega[system.sensor_slice(i), system.sensor_slice(i)]) for i in range(system.M)
    ]
    return scipy.linalg.block_diag(*blocks)


# --- literature values (docs/references.md §2) -------------------------------------------

# ch2-position (σ_w² = 3, 4, σ_v² = 0.25, a² = 3000): full precision, cross-checked below by a
# plain Riccati iteration written out in this file.
CH2_TRACE_P = 1.4546379311584543
CH2_STRATEGIES = {  # name: (Σ, tr(P + W Σ W'), literature)
    "independent, all on sensor 1": (np.diag([3000.0, 0.0]), 390.8336491672481, 390.8),
    "independent, all on sensor 2": (np.diag([0.0, 3000.0]), 220.48033175145886, 220.5),
    "independent, equal split": (np.diag([1500.0, 1500.0]), 305.6569904593535, 305.7),
    "dependent, correlation-1 rule": (
        np.outer([np.sqrt(1920.0), np.sqrt(1080.0)], [np.sqrt(1920.0), np.sqrt(1080.0)]),
        609.8593429875485,
        609.9,
    ),
    "dependent, equal split": (np.full((2, 2), 1500.0), 597.6912488864207, 597.7),
}


def riccati_by_hand(system: LinearSystem, steps: int = 2000) -> tuple[np.ndarray, np.ndarray]:
    """Steady ``P[k|k]`` and gain by iterating the covariance-form filter from the prior."""
    P = np.eye(system.n)
    for _ in range(steps):
        Pp = system.F @ P @ system.F.T + system.Q
        S = system.H @ Pp @ system.H.T + system.R
        W = Pp @ system.H.T @ np.linalg.inv(S)
        P = Pp - W @ S @ W.T
    return P, W


def test_ch2_position_steady_state_matches_an_independent_riccati_iteration():
    system = scenarios.get("ch2-position").system
    P_hand, W_hand = riccati_by_hand(system)
    _, P, W = steady_state(system)
    np.testing.assert_allclose(P, P_hand, rtol=1e-12)
    np.testing.assert_allclose(W, W_hand, rtol=1e-12)
    assert np.trace(P_hand) == pytest.approx(CH2_TRACE_P, rel=1e-12)
    assert round(CH2_TRACE_P, 3) == 1.455
    for sigma, value, _ in CH2_STRATEGIES.values():
        assert np.trace(P_hand + W_hand @ sigma @ W_hand.T) == pytest.approx(value, rel=1e-12)


@pytest.mark.parametrize("name", list(CH2_STRATEGIES))
def test_ch2_position_strategies_match_the_literature(name):
    sigma, value, literature = CH2_STRATEGIES[name]
    result = evaluate("ch2-position", sigma)
    assert result.value == pytest.approx(value, rel=1e-12)
    assert round(result.value, 1) == literature
    assert result.power == pytest.approx(3000.0, rel=1e-12)


def test_ch2_position_rules_and_optima_match_the_literature():
    independent = independent_position_rule("ch2-position")
    dependent = dependent_position_rule("ch2-position")
    full = trace_optimal("ch2-position")
    diagonal = trace_optimal("ch2-position", structure="diagonal")
    assert independent.value == pytest.approx(390.8336491672481, rel=1e-12)
    assert diagonal.value == pytest.approx(independent.value, rel=EXACT)
    # σ_b1² = 1920, σ_b2² = 1080, correlation 1: the optimum over every covariance of power a²
    np.testing.assert_allclose(dependent.variances, [1920.0, 1080.0], rtol=1e-12)
    assert dependent.correlation[0, 1] == pytest.approx(1.0, abs=1e-12)
    assert dependent.value == pytest.approx(609.8593429875485, rel=1e-12)
    assert full.value == pytest.approx(dependent.value, rel=EXACT)
    np.testing.assert_allclose(full.sigma, dependent.sigma, rtol=EXACT, atol=EXACT * 3000)
    assert np.trace(full.P) == pytest.approx(CH2_TRACE_P, rel=1e-12)


def test_ch2_pv_optima_are_pinned():
    # ch2-pv-1 and ch2-pv-2 (a² = 3000): trace and determinant optima, pinned after the
    # numerical cross-check below agreed; the determinant optimum's correlation is near 0.01,
    # not the 0.063 the literature prints.
    pv1_trace, pv1_det = trace_optimal("ch2-pv-1"), det_optimal("ch2-pv-1")
    assert pv1_trace.value == pytest.approx(805.5510194278456, rel=1e-10)
    np.testing.assert_allclose(pv1_trace.variances, [2738.43530222, 261.56469778], rtol=1e-9)
    assert pv1_det.value == pytest.approx(7.9246193882094005, rel=1e-10)
    np.testing.assert_allclose(pv1_det.variances, [1522.31388509, 1477.68611491], rtol=1e-9)
    assert pv1_det.correlation[0, 1] == pytest.approx(0.00931052, rel=1e-6)
    pv2_trace, pv2_det = trace_optimal("ch2-pv-2"), det_optimal("ch2-pv-2")
    assert pv2_trace.value == pytest.approx(487.5518316900647, rel=1e-10)
    np.testing.assert_allclose(
        pv2_trace.variances, [1685.36413125, 223.54789325, 948.01732383, 143.07065168], rtol=1e-9
    )
    assert pv2_det.value == pytest.approx(7.471109308925392, rel=1e-10)


@pytest.mark.parametrize("name", ["ch2-position", "ch2-pv-1", "ch2-pv-2"])
def test_ch2_closed_forms_equal_the_numerical_optimum(name):
    system = scenarios.get(name).system
    for structure in ("full", "diagonal"):
        check_trace_against_numerical(system, 3000.0, None, structure, seed=0)
    check_det_against_numerical(system, 3000.0, None, seed=0)


# --- closed forms against the numerical optimum ----------------------------------------------


def check_trace_against_numerical(system, power, weight, structure, seed, starts=4):
    result = trace_optimal(system, power, structure=structure, weight=weight)
    _, P, W = steady_state(system)
    Oi = weight_inv_half(system, weight, structure)
    Wt = W @ Oi
    A = Wt.T @ Wt

    def objective(St):
        return np.trace(P) + np.sum(A * St), A

    best = numerical_max(objective, system.nz, power, block_mask(system, structure), seed, starts)
    assert result.value == pytest.approx(best, rel=RTOL)
    assert result.value >= best - RTOL * abs(best)
    omega = power_weight(system) if weight is None else weight
    assert np.trace(omega @ result.sigma) == pytest.approx(power, rel=1e-10)
    assert np.linalg.eigvalsh(result.sigma).min() >= -1e-10 * power
    if structure == "diagonal":
        off = ~block_mask(system, "diagonal")
        assert np.all(result.sigma[off] == 0.0)


def check_det_against_numerical(system, power, weight, seed, starts=4):
    result = det_optimal(system, power, weight=weight)
    _, P, W = steady_state(system)
    omega = power_weight(system) if weight is None else weight
    Wt = W @ inv_sqrt(omega)

    def objective(St):
        M = P + Wt @ St @ Wt.T
        G = Wt.T @ np.linalg.solve(M, Wt)
        return np.linalg.slogdet(M)[1], 0.5 * (G + G.T)

    best = numerical_max(objective, system.nz, power, block_mask(system, "full"), seed, starts)
    assert result.value == pytest.approx(best, abs=RTOL * max(1.0, abs(best)))
    assert result.value >= best - RTOL * max(1.0, abs(best))
    assert np.trace(omega @ result.sigma) == pytest.approx(power, rel=1e-10)
    assert result.det == pytest.approx(np.linalg.det(result.covariance), rel=1e-9)


@HYP
@given(problems(), st.sampled_from(["full", "diagonal"]))
def test_trace_optimal_equals_numerical_maximum_on_random_systems(problem, structure):
    system, power, weight = problem
    check_trace_against_numerical(system, power, weight, structure, seed=1)


@HYP
@given(problems())
def test_det_optimal_equals_numerical_maximum_on_random_systems(problem):
    system, power, weight = problem
    check_det_against_numerical(system, power, weight, seed=2)


@HYP
@given(problems())
def test_det_optimal_satisfies_the_kkt_conditions(problem):
    system, power, weight = problem
    residuals = kkt_residuals(det_optimal(system, power, weight=weight))
    assert residuals.worst < 1e-9, residuals
    assert residuals.multiplier > 0.0


@settings(max_examples=50, deadline=None, derandomize=True)
@given(st.integers(0, 2**32 - 1), st.integers(1, 6), st.floats(-3.0, 4.0))
def test_water_filling_satisfies_its_kkt_conditions(seed, d, log_power):
    rng = np.random.default_rng(seed)
    xi = rng.uniform(0.01, 10.0, size=d) * (rng.uniform(size=d) < 0.8)  # some zero gains
    xi[rng.integers(d)] = rng.uniform(0.01, 10.0)
    power = 10.0**log_power
    s, level = water_filling(xi, power)
    lam = 1.0 / level
    assert s.sum() == pytest.approx(power, rel=1e-12)
    assert np.all(s >= 0.0)
    active = s > 0.0
    # stationarity ξ/(1 + s ξ) = λ where s > 0; dual feasibility ξ ≤ λ where s = 0
    np.testing.assert_allclose(xi[active] / (1.0 + s[active] * xi[active]), lam, rtol=1e-10)
    assert np.all(xi[~active] <= lam * (1.0 + 1e-10))


def test_water_filling_tends_to_equal_power_and_no_correlation_at_high_power():
    result = det_optimal("ch2-pv-1", power=1e9)
    s, xi = result.info["s"], result.info["xi"]
    # s_i = level − 1/ξ_i: the spread is |1/ξ_1 − 1/ξ_2| whatever the power
    assert s.max() - s.min() == pytest.approx(abs(1 / xi[0] - 1 / xi[1]), rel=1e-6)
    assert s.max() / s.min() == pytest.approx(1.0, abs=1e-6)
    assert abs(result.correlation[0, 1]) < 1e-6


# --- the literature's special cases are the general rule -------------------------------------


@HYP
@given(st.integers(0, 2**32 - 1), st.integers(1, 5), st.floats(-1.0, 4.0))
def test_position_rules_equal_the_general_rule(seed, M, log_power):
    rng = np.random.default_rng(seed)
    system = tracking_system(
        rng.uniform(0.05, 2.0), list(rng.uniform(0.1, 5.0, size=M)), T=rng.uniform(0.2, 2.0)
    )
    power = 10.0**log_power
    independent = independent_position_rule(system, power)
    diagonal = trace_optimal(system, power, structure="diagonal")
    assert independent.info["sensor"] == diagonal.info["sensor"]
    np.testing.assert_allclose(independent.sigma, diagonal.sigma, rtol=0, atol=EXACT * power)
    dependent = dependent_position_rule(system, power)
    full = trace_optimal(system, power)
    np.testing.assert_allclose(dependent.sigma, full.sigma, rtol=0, atol=EXACT * power)
    assert dependent.value == pytest.approx(full.value, rel=EXACT)


@HYP
@given(st.integers(0, 2**32 - 1), st.floats(-1.0, 4.0))
def test_single_pv_sensor_rule_equals_the_general_rule(seed, log_power):
    rng = np.random.default_rng(seed)
    sensor = pv_sensor(rng.uniform(0.1, 5.0), rng.uniform(0.1, 5.0), rng.uniform(-0.9, 0.9))
    system = tracking_system(rng.uniform(0.05, 2.0), T=rng.uniform(0.2, 3.0), sensors=[sensor])
    power = 10.0**log_power
    rule = pv_single_sensor_rule(system, power)
    full = trace_optimal(system, power)
    np.testing.assert_allclose(rule.sigma, full.sigma, rtol=0, atol=1e-9 * power)
    assert rule.value == pytest.approx(full.value, rel=EXACT)
    assert abs(rule.correlation[0, 1]) == pytest.approx(1.0, abs=1e-9)


def test_pv_rule_on_ch2_pv_1_has_the_stated_angles():
    rule = pv_single_sensor_rule("ch2-pv-1")
    (w11, w12), (w21, w22) = rule.W
    beta1, beta2 = w11**2 + w21**2, w12**2 + w22**2
    phi = np.arctan((beta2 - beta1) / (2 * (w11 * w12 + w21 * w22)))  # T = 1, α1 + α2 > 0
    assert rule.info["rho"] == 1.0
    assert rule.info["phi"] == pytest.approx(phi, rel=1e-12)
    assert rule.info["theta"] == pytest.approx(np.pi / 4 - phi / 2, rel=1e-12)
    assert rule.variances[0] == pytest.approx(3000.0 * np.sin(rule.info["theta"]) ** 2)


# --- multi-shot ------------------------------------------------------------------------------


@HYP
@given(problems(), st.integers(1, 8), st.sampled_from(["budget", "per_step"]), st.booleans())
def test_multi_shot_objective_equals_the_direct_recursion(problem, horizon, mode, random_weights):
    system, power, weight = problem
    weights = None
    if random_weights:
        rng = np.random.default_rng(horizon)
        weights = rng.dirichlet(np.ones(horizon))
    result = multi_shot(system, power, horizon, weights, weight=weight, power_mode=mode)
    direct = recursion_objective(system, result.sigmas, weights)
    assert result.value == pytest.approx(direct, rel=1e-10)
    omega = power_weight(system) if weight is None else weight
    powers = np.einsum("ab,kba->k", omega, result.sigmas)
    if mode == "budget":
        assert powers.sum() == pytest.approx(power, rel=1e-10)
        assert np.count_nonzero(powers) == 1 and powers[result.step] > 0
    else:
        np.testing.assert_allclose(powers, power, rtol=1e-10)


@HYP
@given(problems(), st.integers(2, 6))
def test_multi_shot_beats_random_plans(problem, horizon):
    system, power, weight = problem
    rng = np.random.default_rng(horizon)
    weights = rng.dirichlet(np.ones(horizon))
    best = multi_shot(system, power, horizon, weights, weight=weight).value
    omega = power_weight(system) if weight is None else weight
    Oi = inv_sqrt(omega)
    for _ in range(20):
        share = rng.dirichlet(np.ones(horizon)) * power
        plan = []
        for p in share:
            L = rng.standard_normal((system.nz, system.nz))
            plan.append(p * Oi @ (L @ L.T / np.sum(L * L)) @ Oi)
        assert recursion_objective(system, np.array(plan), weights) <= best * (1 + 1e-12)


def test_multi_shot_with_equal_weights_attacks_first_and_one_step_is_single_injection():
    result = multi_shot("ch2-pv-2", None, 6)
    assert result.step == 0
    single = trace_optimal("ch2-pv-2")
    one = multi_shot("ch2-pv-2", None, 1)
    assert one.value == pytest.approx(single.value, rel=EXACT)
    np.testing.assert_allclose(one.sigmas[0], single.sigma, rtol=0, atol=EXACT * 3000)


# --- equivalent sensor -----------------------------------------------------------------------


@HYP
@given(systems())
def test_equivalent_sensor_gives_the_same_posterior_covariance(system):
    try:
        eq = equivalent_sensor(system)
    except ValueError:  # sensors with different H and a singular Σ H_i' R_i⁻¹ H_i
        J = system.J.sum(axis=0)
        assert np.linalg.matrix_rank(J) < system.n
        return
    _, P, W = steady_state(system)
    _, P_e, W_e = steady_state(eq.system())
    np.testing.assert_allclose(P_e, P, rtol=1e-9, atol=1e-12 * np.abs(P).max())
    np.testing.assert_allclose(W_e @ eq.combine, W, rtol=1e-8, atol=1e-10 * np.abs(W).max())


def test_equivalent_sensor_uses_the_identical_h_rule_for_ch2_position():
    eq = equivalent_sensor("ch2-position")
    assert eq.identical
    np.testing.assert_allclose(eq.R, [[12.0 / 7.0]], rtol=1e-14)
    np.testing.assert_allclose(eq.combine, [[4.0 / 7.0, 3.0 / 7.0]], rtol=1e-14)
    mixed = tracking_system(0.5, [1.0], sensors=[pv_sensor(1.0, 2.0)])
    general = equivalent_sensor(mixed)
    assert not general.identical
    np.testing.assert_array_equal(general.H, np.eye(2))
    # the attack seen through the equivalent sensor has the same extra MSE
    attack = trace_optimal(mixed, 10.0)
    W_e = steady_state(general.system())[2]
    extra = np.trace(W_e @ general.bias_covariance(attack.sigma) @ W_e.T)
    assert extra == pytest.approx(attack.extra, rel=1e-9)


# --- policies in covariance_attack_v0 --------------------------------------------------------


def play_parallel(policy_of, **env_kwargs) -> float:
    """Episode return of ``policy_of(env)`` in the parallel env."""
    env = covariance_attack_v0.parallel_env(**env_kwargs)
    return attacker_return(env, policy_of(env))


@pytest.mark.parametrize(
    ("name", "structure", "objective"),
    [
        ("ch2-position", "full", "trace"),
        ("ch2-position", "diagonal", "trace"),
        ("ch2-pv-2", "full", "trace"),
        ("ch2-pv-2", "diagonal", "trace"),
        ("ch2-pv-1", "full", "logdet"),
        ("ch2-pv-2", "full", "logdet"),
    ],
)
def test_single_injection_policy_return_equals_the_closed_form(name, structure, objective):
    if objective == "trace":
        result = trace_optimal(name, structure=structure)
    else:
        result = det_optimal(name)
    ret = play_parallel(result.policy, scenario=name, structure=structure, objective=objective)
    # actions are float32: Σ's direction moves by ~1e-8, the value (stationary there) far less
    assert ret == pytest.approx(result.value, rel=1e-9)


@pytest.mark.parametrize("mode", ["budget", "per_step"])
@pytest.mark.parametrize("name", ["ch2-position", "ch2-pv-2"])
def test_multi_shot_policy_return_equals_its_objective(mode, name):
    N = 6
    terminal = multi_shot(name, None, N, np.eye(N)[-1], power_mode=mode)
    ret = play_parallel(terminal.policy, scenario=name, horizon=N, power_mode=mode)
    assert ret == pytest.approx(terminal.value, rel=1e-9)
    equal = multi_shot(name, None, N, power_mode=mode)
    ret = play_parallel(
        equal.policy, scenario=name, horizon=N, power_mode=mode, reward_mode="per_step"
    )
    assert ret == pytest.approx(N * equal.value, rel=1e-9)


def test_policy_plays_through_gymnasium_make_and_batches():
    env = gymnasium.make("fdia_env/CovarianceAttack-v0", scenario="ch2-pv-1", power_mode="budget")
    result = trace_optimal("ch2-pv-1")
    policy = CovariancePolicy(env, result.sigma)
    obs, _ = env.reset(seed=0)
    action, state = policy.predict(obs, state="kept")
    assert state == "kept" and action.dtype == np.float32
    assert env.action_space.contains(action)
    _, reward, terminated, _, _ = env.step(action)
    assert terminated and reward == pytest.approx(result.value, rel=1e-9)
    batch = np.stack([obs, obs])
    assert policy.predict(batch)[0].shape == (2, *env.action_space.shape)


def test_budget_policy_spends_the_plan_fractions():
    env = covariance_attack_v0.parallel_env(scenario="ch2-position", horizon=3, power_mode="budget")
    sigma = trace_optimal("ch2-position").sigma
    policy = CovariancePolicy(env, [sigma, 0 * sigma, sigma])  # half now, nothing, half at the end
    obs, _ = env.reset(seed=0)
    spent = []
    while env.agents:
        action, _ = policy.predict(obs["attacker"])
        obs, _, _, _, infos = env.step({"attacker": action})
        spent.append(infos["attacker"]["power"])
    np.testing.assert_allclose(spent, [1500.0, 0.0, 1500.0], rtol=1e-6)


# --- bad input -------------------------------------------------------------------------------

SOLVERS = {
    "trace_optimal": lambda **kw: trace_optimal("ch2-pv-2", **kw),
    "det_optimal": lambda **kw: det_optimal("ch2-pv-2", **kw),
    "multi_shot": lambda **kw: multi_shot("ch2-pv-2", kw.pop("power", None), 3, **kw),
}


@pytest.mark.parametrize("solver", list(SOLVERS))
@pytest.mark.parametrize("power", [0.0, -1.0, float("nan"), float("inf"), "3000"])
def test_bad_power_raises(solver, power):
    with pytest.raises(ValueError, match="power"):
        SOLVERS[solver](power=power)


@pytest.mark.parametrize("solver", list(SOLVERS))
def test_missing_power_raises_when_the_system_has_none(solver):
    with pytest.raises(ValueError, match="power is required"):
        {
            "trace_optimal": trace_optimal,
            "det_optimal": det_optimal,
            "multi_shot": lambda s: multi_shot(s, None, 2),
        }[solver]("ch4-position")


@pytest.mark.parametrize("solver", list(SOLVERS))
@pytest.mark.parametrize(
    ("weight", "message"),
    [
        (np.eye(3), r"weight must be an \(nz, nz\) = \(4, 4\)"),
        (np.eye(4) + np.triu(np.ones((4, 4)), 1), "weight must be symmetric"),
        (np.diag([1.0, 1.0, 0.0, 1.0]), "weight must be positive definite"),
        (np.diag([1.0, -1.0, 1.0, 1.0]), "weight must be positive definite"),
        (np.full((4, 4), np.nan), "weight must be finite"),
    ],
)
def test_bad_weight_raises(solver, weight, message):
    with pytest.raises(ValueError, match=message):
        SOLVERS[solver](weight=weight)


def _unobservable_pair() -> LinearSystem:
    """Two position-only sensors with different H: Σ H_i' R_i⁻¹ H_i is singular."""
    base = tracking_system(0.5, [1.0])
    other = Sensor(np.array([[2.0, 0.0]]), np.eye(1))
    return LinearSystem(F=base.F, Q=base.Q, sensors=(base.sensors[0], other))


def _policy(env_kwargs, sigmas, source=None):
    env = covariance_attack_v0.parallel_env(scenario="ch2-position", **env_kwargs)
    return CovariancePolicy(env if source is None else source, sigmas)


BAD_INPUTS = {
    "unknown structure": (
        lambda: trace_optimal("ch2-position", structure="block"),
        "structure must be one of",
    ),
    "multi_shot horizon 0": (lambda: multi_shot("ch2-position", None, 0), "horizon"),
    "multi_shot weights of the wrong length": (
        lambda: multi_shot("ch2-position", None, 3, [0.5, 0.5]),
        "weights must have 3 entries",
    ),
    "multi_shot weights not summing to 1": (
        lambda: multi_shot("ch2-position", None, 2, [0.7, 0.7]),
        "weights must be non-negative and sum to 1",
    ),
    "multi_shot negative weights": (
        lambda: multi_shot("ch2-position", None, 2, [1.5, -0.5]),
        "weights must be non-negative and sum to 1",
    ),
    "multi_shot unknown power mode": (
        lambda: multi_shot("ch2-position", None, 2, power_mode="total"),
        "power_mode must be one of",
    ),
    "recursion_objective sigmas of the wrong shape": (
        lambda: recursion_objective("ch2-position", np.zeros((2, 3, 3))),
        "sigmas must have shape",
    ),
    "independent rule on a pv sensor": (
        lambda: independent_position_rule("ch2-pv-1"),
        "independent_position_rule needs scalar sensors",
    ),
    "dependent rule on sensors with different H": (
        lambda: dependent_position_rule(
            tracking_system(0.5, [1.0], sensors=[Sensor(np.array([[0.0, 1.0]]), np.eye(1))])
        ),
        "dependent_position_rule needs scalar sensors",
    ),
    "pv rule on two sensors": (
        lambda: pv_single_sensor_rule("ch2-pv-2"),
        "pv_single_sensor_rule needs exactly one",
    ),
    "equivalent sensor of an unobservable step": (
        lambda: equivalent_sensor(_unobservable_pair()),
        "singular",
    ),
    "evaluate sigma of the wrong shape": (
        lambda: evaluate("ch2-position", np.eye(3)),
        "sigma must have shape",
    ),
    "evaluate sigma not PSD": (
        lambda: evaluate("ch2-position", np.diag([1.0, -1.0])),
        "sigma must be positive semidefinite",
    ),
    "evaluate unknown objective": (
        lambda: evaluate("ch2-position", np.eye(2), objective="volume"),
        "objective must be one of",
    ),
    "water_filling without a positive gain": (
        lambda: water_filling(np.zeros(3), 1.0),
        "xi must have a positive entry",
    ),
    "water_filling negative power": (lambda: water_filling(np.ones(3), -1.0), "power"),
    "policy from something that is not an env": (
        lambda: CovariancePolicy(object(), np.eye(2)),
        "source must be a CovarianceAttack",
    ),
    "policy from an unbound attack": (
        lambda: CovariancePolicy(CovarianceAttack(3000.0), np.eye(2)),
        "not bound yet",
    ),
    "policy sigma of the wrong shape": (lambda: _policy({}, np.eye(3)), "sigmas must be one"),
    "policy sigma not PSD": (
        lambda: _policy({"horizon": 2}, [np.eye(2), -np.eye(2)]),
        r"sigmas\[1\] must be positive semidefinite",
    ),
    "policy plan longer than the episode": (
        lambda: _policy({"horizon": 2}, [np.eye(2)] * 3),
        "horizon must be >= 3",
    ),
    "policy zero sigma in per-step mode": (
        lambda: _policy({"horizon": 2}, [np.eye(2), np.zeros((2, 2))]),
        "non-zero in power_mode='per_step'",
    ),
    "policy plan without power in budget mode": (
        lambda: _policy({"power_mode": "budget"}, np.zeros((2, 2))),
        "spends no power",
    ),
}


@pytest.mark.parametrize("case", list(BAD_INPUTS))
def test_bad_input_raises(case):
    call, message = BAD_INPUTS[case]
    with pytest.raises(ValueError, match=message):
        call()


# --- the reproduction script -----------------------------------------------------------------


def test_reproduce_ch2_quick_matches_the_literature_and_writes_figures(tmp_path, capsys):
    from experiments import reproduce

    output = tmp_path / "reproduction.md"
    output.write_text("# Title\n\n## Chapter 4: sparse attacks\n\nkept\n")
    assert reproduce.main(["ch2", "--quick", "--output", str(output)]) == 0
    text = output.read_text()
    assert "## Chapter 4: sparse attacks\n\nkept" in text
    assert text.count("## Chapter 2: attack covariances") == 1
    assert text.count("| yes |") == len(reproduce.CH2_LITERATURE)
    assert "**NO**" not in text
    for figure in ("ch2_ellipses.png", "ch2_position_allocation.png"):
        assert (tmp_path / "figures" / figure).stat().st_size > 0
    assert "Known literature errors" in capsys.readouterr().out
