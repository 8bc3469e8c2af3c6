"""Optimal Bayesian detectors with minimum MSE (docs/math.md §3): orderings, rules, probabilities.

Monte-Carlo tolerances: estimates are compared within 4 standard errors (two-sided, a false
failure once in ~16,000 comparisons; every draw is seeded, so the outcome is deterministic).
Orderings are asserted with paired differences on common random numbers, which must be positive
by more than 3 standard errors.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.integrate
import scipy.stats
from conftest import random_pd, random_psd
from hypothesis import given, settings
from hypothesis import strategies as st

from baselines.detection import (
    DETECTORS,
    STATISTICS,
    DetectionProblem,
    Detector,
    bayes_cost,
    c2_gain_matrix,
    c2_optimal_pbb,
    cbd,
    csd,
    detection_probabilities,
    expected_mse,
    gchisq_sf,
    gchisq_sf_mc,
    mmse,
    monte_carlo,
    obdd,
    obdi,
    predicted_covariance,
    simulate_prediction,
    static_problem,
    tracking_problem,
)
from fdia_env import scenarios
from fdia_env.kalman import steady_state

DRAWS = 100_000
Z_CI = 4.0  # Monte-Carlo agreement: within this many standard errors
Z_ORDER = 3.0  # an ordering holds when the paired difference exceeds this many standard errors
HYP = settings(max_examples=40, deadline=None, derandomize=True)


def all_estimators(problem: DetectionProblem) -> dict:
    out = {name: build(problem) for name, build in DETECTORS.items()}
    out["MMSE"] = mmse(problem)
    return out


# --- the literature's ordering --------------------------------------------------------------


@pytest.mark.parametrize(
    ("build", "power"),
    [(static_problem, a2) for a2 in (10.0, 50.0, 100.0, 200.0, 400.0)]
    + [(tracking_problem, a2) for a2 in (7.5, 30.0, 120.0)],
)
def test_mmse_obdi_obdd_ordering_in_monte_carlo_mse(build, power):
    """docs/references.md §3: MMSE ≤ OBDI ≤ OBDD at every a² (10⁵ draws, common random numbers).

    Each difference is the mean of per-draw paired differences and must exceed 3 of its
    standard errors (the smallest margin on ch3-static is ~5 SE, OBDI − MMSE at a² = 10).
    """
    problem = build(power=power)
    mc = monte_carlo(problem, all_estimators(problem), DRAWS, seed=0)
    for better, worse in (("MMSE", "OBDI"), ("OBDI", "OBDD")):
        mean, se = mc.difference(worse, better)
        assert mean > Z_ORDER * se, (power, better, worse, mean, se)


def test_chi_square_beats_cbd_and_obdd_at_high_power_in_true_mse():
    """docs/references.md §3: under the true MSE CSD beats CBD and OBDD at high power (a² = 400),
    while by the Bayes cost (which they minimise) OBDD and CBD both beat it."""
    problem = static_problem(power=400.0)
    est = all_estimators(problem)
    mc = monte_carlo(problem, est, DRAWS, seed=0)
    for other in ("CBD", "OBDD"):
        mean, se = mc.difference(other, "CSD")
        assert mean > Z_ORDER * se
        assert bayes_cost(est[other]).value < bayes_cost(est["CSD"]).value


# --- decision rules -------------------------------------------------------------------------


def test_obdd_declares_no_attack_whenever_c2_below_c1():
    """ch3-static, a² = 100: c2 = 101.02 < c1 = tr Pxx = 200, so OBDD is 'always D0' (α = +inf).

    Checked on measurements far into both tails and on MC draws under H1; the estimate is then
    the clean LMMSE everywhere, and the numerical P_fa = P_d = 0.
    """
    problem = static_problem(power=100.0)
    det = obdd(problem)
    assert det.costs.c2 < det.costs.c1
    assert det.threshold == math.inf
    rng = np.random.default_rng(1)
    z = (
        problem.z_bar
        + rng.standard_normal((5000, 2))
        * np.array([1.0, 1.0, 1e3])[rng.integers(0, 3, 5000)][:, None]
    )
    z = np.vstack([z, [[1e8, -1e8], [0.0, 0.0]]])
    r = det(z)
    assert not r.decision.any()
    np.testing.assert_allclose(r.estimate, problem.x_bar + (z - problem.z_bar) @ problem.K0.T)
    assert detection_probabilities(det) == (0.0, 0.0)
    mc = monte_carlo(problem, {"OBDD": det}, 10_000, seed=2)
    assert mc.stats["OBDD"].p_d == 0.0 and mc.stats["OBDD"].p_fa == 0.0


def test_obdd_switches_from_always_d0_once_c2_exceeds_c1():
    """c2 = c4 + a² (100/103)² crosses c1 = 200 at a² ≈ 205.07: α jumps from +inf to finite."""
    below, above = obdd(static_problem(power=205.0)), obdd(static_problem(power=206.0))
    assert below.costs.c2 < below.costs.c1 and below.threshold == math.inf
    assert above.costs.c2 > above.costs.c1 and math.isfinite(above.threshold)


def _direct_bayes_decision(problem: DetectionProblem, costs, z: np.ndarray) -> np.ndarray:
    """D1 where p1 (c1 − c2) N(z; z̄, Pzz1) + p0 (c3 − c4) N(z; z̄, Pzz0) < 0 (docs/math.md §3)."""
    n1 = scipy.stats.multivariate_normal(problem.z_bar, problem.Pzz1).pdf(z)
    n0 = scipy.stats.multivariate_normal(problem.z_bar, problem.Pzz0).pdf(z)
    return problem.p1 * (costs.c1 - costs.c2) * n1 + problem.p0 * (costs.c3 - costs.c4) * n0 < 0


@pytest.mark.parametrize(
    ("build", "power", "p1", "genuine"),
    [
        (static_problem, 230.0, None, {"OBDD"}),
        (tracking_problem, 7.5, 0.2, {"OBDD", "OBDI", "CBD"}),
        (static_problem, 100.0, 0.2, {"OBDI", "CBD"}),
    ],
)
def test_threshold_tests_equal_the_likelihood_rules(build, power, p1, genuine):
    """OBDD / OBDI decisions = the Bayes rule written with densities; CBD = MAP hypothesis.

    ``genuine`` names the detectors that are not constant in that case (the others are always
    D0 or always D1, which the rule must reproduce too).
    """
    problem = build(power=power, p1=p1)
    rng = np.random.default_rng(3)
    y = rng.standard_normal((20_000, 2)) @ np.linalg.cholesky(problem.Pzz1).T * 1.5
    z = problem.z_bar + y
    n1 = scipy.stats.multivariate_normal(problem.z_bar, problem.Pzz1).pdf(z)
    n0 = scipy.stats.multivariate_normal(problem.z_bar, problem.Pzz0).pdf(z)
    decisions = {"CBD": (cbd(problem)(z).decision, problem.p1 * n1 > problem.p0 * n0)}
    for det in (obdd(problem), obdi(problem)):
        decisions[det.name] = (det(z).decision, _direct_bayes_decision(problem, det.costs, z))
    for name, (got, direct) in decisions.items():
        np.testing.assert_array_equal(got, direct)
        assert (0 < direct.mean() < 1) == (name in genuine), name


def test_costs_equal_the_closed_forms_of_math_md():
    """c1..c4 from mse(K, Pzz_h) against docs/math.md §3's printed formulas (rel 1e-12)."""
    p = tracking_problem(power=30.0)
    Pxx, Pxz, S0, S1 = p.Pxx, p.Pxz, p.Pzz0, p.Pzz1
    S0i, S1i = np.linalg.inv(S0), np.linalg.inv(S1)
    c2 = np.trace(Pxx - Pxz @ S0i @ (np.eye(2) - p.Pbb @ S0i) @ Pxz.T)
    c4 = np.trace(Pxx - Pxz @ S0i @ Pxz.T)
    d, i = obdd(p).costs, obdi(p).costs
    assert (d.c1, d.c3) == (pytest.approx(np.trace(Pxx)), pytest.approx(np.trace(Pxx)))
    assert i.c1 == pytest.approx(np.trace(Pxx - Pxz @ S1i @ Pxz.T), rel=1e-12)
    c3 = np.trace(Pxx + Pxz @ S1i @ S0 @ S1i @ Pxz.T - 2 * Pxz @ S1i @ Pxz.T)
    assert i.c3 == pytest.approx(c3, rel=1e-12)
    for c in (d, i):
        assert c.c2 == pytest.approx(c2, rel=1e-12) and c.c4 == pytest.approx(c4, rel=1e-12)
    assert i.c2 > i.c1 and i.c3 > i.c4


# --- chi-square detector --------------------------------------------------------------------


@pytest.mark.parametrize(
    "problem",
    [static_problem(power=50.0), static_problem(power=400.0), tracking_problem(power=60.0)],
    ids=["static-50", "static-400", "tracking-60"],
)
def test_csd_false_alarm_rate_is_five_percent(problem):
    """P_fa of CSD = 0.05 numerically (1e-12) and by MC within 4 binomial SE (±0.0028 at 10⁵)."""
    det = csd(problem)
    assert det.statistic == "chi2"
    assert det.threshold == pytest.approx(5.991464547107979, rel=1e-12)
    p_fa, _ = detection_probabilities(det)
    assert p_fa == pytest.approx(0.05, abs=1e-12)
    mc = monte_carlo(problem, {"CSD": det}, DRAWS, seed=4)
    bound = Z_CI * math.sqrt(0.05 * 0.95 / DRAWS)
    assert abs(mc.stats["CSD"].p_fa - 0.05) <= bound


def test_chi2_statistic_is_the_normalised_innovation_squared():
    """`chi2` = (z − H x̂)' S⁻¹ (z − H x̂), S = H P[K|K−1] H' + R, the filter's NIS."""
    problem = tracking_problem(power=30.0)
    system = scenarios.get("ch3-tracking").system
    S = system.H @ predicted_covariance("ch3-tracking") @ system.H.T + system.R
    z = np.array([[1.0, -2.0], [3.0, 0.5]])
    tau = z - problem.z_bar
    nis = np.einsum("bi,ij,bj->b", tau, np.linalg.inv(S), tau)
    np.testing.assert_allclose(csd(problem)(z).statistic, nis, rtol=1e-12)


# --- Bayes cost against Monte Carlo ---------------------------------------------------------


def _cases():
    robust = static_problem(Pbb=np.diag([270.0, 0.0]))
    return [
        ("static-230-OBDD", obdd(static_problem(power=230.0)), None),
        ("static-100-CSD", csd(static_problem(power=100.0)), None),
        ("static-p1=0.2-OBDI", obdi(static_problem(power=100.0, p1=0.2)), None),
        ("tracking-7.5-OBDD", obdd(tracking_problem(power=7.5)), None),
        ("tracking-30-CSD", csd(tracking_problem(power=30.0)), None),
        ("robust-270-OBDD", obdd(robust), robust.with_pbb(np.diag([0.0, 270.0]))),
        ("robust-270-CSD", csd(robust), robust.with_pbb(np.diag([0.0, 270.0]))),
    ]


@pytest.mark.parametrize(("label", "det", "truth"), _cases(), ids=[c[0] for c in _cases()])
def test_bayes_cost_equals_monte_carlo_average_of_fixed_costs(label, det, truth):
    """Numerical P_fa, P_d and Bayes cost within 4 SE of their MC estimates (10⁵ draws); the MC
    MSE within 4 SE of the closed-form true MSE (which differs from the Bayes cost)."""
    truth = det.problem if truth is None else truth
    b = bayes_cost(det, truth)
    s = monte_carlo(truth, {"d": det}, DRAWS, seed=5).stats["d"]
    assert abs(s.mse - expected_mse(det, truth)) <= Z_CI * s.se
    assert 0.01 < b.p_d < 0.99  # a genuine test: the probabilities matter
    assert abs(b.value - s.fixed_cost) <= Z_CI * s.fixed_se, (b.value, s.fixed_cost, s.fixed_se)
    for num, est in ((b.p_fa, s.p_fa), (b.p_d, s.p_d)):
        assert abs(num - est) <= Z_CI * math.sqrt(max(num * (1 - num), 1e-6) / DRAWS)


@pytest.mark.parametrize(("label", "det", "truth"), _cases(), ids=[c[0] for c in _cases()])
def test_exact_mse_agrees_with_the_core_detection_numerics(label, det, truth):
    """`expected_mse` and P_fa/P_d against fdia_env.detection.expected (rel 1e-10)."""
    from fdia_env.detection.expected import expected_squared_error

    t = det.problem if truth is None else truth
    K_d1 = np.zeros_like(det.problem.K0) if det.on_detect == "discard" else det.problem.K1
    core = expected_squared_error(
        t.Pxx, t.H, t.Pww, t.Pbb, t.p1, det.matrix, det.threshold, det.problem.K0, K_d1
    )
    assert expected_mse(det, truth) == pytest.approx(core.mse, rel=1e-10)
    p_fa, p_d = detection_probabilities(det, truth)
    assert (p_fa, p_d) == (
        pytest.approx(core.p_false_alarm, abs=1e-12),
        pytest.approx(core.p_detection, abs=1e-12),
    )


@pytest.mark.parametrize(("label", "det", "truth"), _cases(), ids=[c[0] for c in _cases()])
def test_exact_bayes_cost_criterion_agrees_with_the_baselines_bayes_cost(label, det, truth):
    """The core's ``criterion="bayes_cost"`` trace is the baselines' Bayes cost (rel 1e-10)."""
    from fdia_env.detection.expected import expected_squared_error

    t = det.problem if truth is None else truth
    K_d1 = np.zeros_like(det.problem.K0) if det.on_detect == "discard" else det.problem.K1
    args = (t.Pxx, t.H, t.Pww, t.Pbb, t.p1, det.matrix, det.threshold, det.problem.K0, K_d1)
    core = expected_squared_error(*args, criterion="bayes_cost")
    assert core.mse == pytest.approx(bayes_cost(det, truth).value, rel=1e-10)
    mse = expected_squared_error(*args)
    assert (core.p_false_alarm, core.p_detection) == (
        pytest.approx(mse.p_false_alarm, abs=1e-12),
        pytest.approx(mse.p_detection, abs=1e-12),
    )
    with pytest.raises(ValueError, match="criterion must be one of"):
        expected_squared_error(*args, criterion="bayes")


def test_constant_decisions_make_the_bayes_cost_exact():
    """Always-D1 OBDI: the Bayes cost is p1 c1 + p0 c3, and the MC MSE estimates it."""
    problem = static_problem(power=100.0)
    det = obdi(problem)
    assert det.threshold < 0  # q >= 0: always D1
    b = bayes_cost(det)
    assert b.value == pytest.approx(0.85 * det.costs.c1 + 0.15 * det.costs.c3, rel=1e-14)
    s = monte_carlo(problem, {"d": det}, DRAWS, seed=6).stats["d"]
    assert s.fixed_se == 0.0 and abs(s.mse - b.value) <= Z_CI * s.se


# --- numerical detection probabilities -------------------------------------------------------


def _two_weight_sf(x: float, big: float, small: float) -> float:
    """Exact P(big·X1 + small·X2 > x), X χ²_1: E_{X2}[χ²_1.sf((x − small X2) / big)], X2 = v²."""
    dens = 2.0 / math.sqrt(2.0 * math.pi)
    vmax = math.sqrt(x / small)

    def f(v: float) -> float:
        return dens * math.exp(-0.5 * v * v) * scipy.stats.chi2.sf((x - small * v * v) / big, 1)

    inner = scipy.integrate.quad(f, 0.0, vmax, epsabs=1e-15, epsrel=1e-13, limit=500)[0]
    return inner + scipy.stats.chi2.sf(x / small, 1)


@pytest.mark.parametrize("weights", [(3.0, 0.5), (100.0, 0.01), (7.0, 0.04), (2.0, 1.5)])
def test_imhof_matches_the_exact_two_weight_convolution(weights):
    lam = np.array(weights)
    x = np.array([0.01, 0.5, 2.0, 6.0, 20.0]) * lam.sum()
    exact = [_two_weight_sf(v, *weights) for v in x]
    np.testing.assert_allclose(gchisq_sf(x, lam), exact, rtol=0, atol=1e-10)


def test_imhof_matches_monte_carlo_with_three_weights_and_chi2_when_equal():
    lam = np.array([0.3, 2.0, 7.0])
    x = np.array([0.5, 2.0, 6.0]) * lam.sum()
    mc, se = gchisq_sf_mc(x, lam, draws=400_000, seed=7)
    assert np.all(np.abs(gchisq_sf(x, lam) - mc) <= Z_CI * se)
    np.testing.assert_allclose(gchisq_sf(x, [2.0] * 3), scipy.stats.chi2.sf(x / 2.0, 3))
    assert gchisq_sf(-1.0, lam) == 1.0 and gchisq_sf(0.0, lam) == 1.0
    assert gchisq_sf(np.inf, lam) == 0.0
    assert gchisq_sf(-1.0, [0.0, 0.0]) == 1.0 and gchisq_sf(1.0, [0.0, 0.0]) == 0.0


# --- MMSE estimator -------------------------------------------------------------------------


def _grid_posterior_mean(problem: DetectionProblem, z: np.ndarray, half: float, step: float):
    """E[x | z] by brute force: the unnormalised posterior summed on a grid around x̄.

    ``p(x | z) ∝ N(x; x̄, Pxx) [p0 N(z; Hx, Pww) + p1 N(z; Hx, Pww + Pbb)]``; the trapezoid rule
    on a smooth Gaussian integrand with step << posterior SD is accurate to rounding.
    """
    axis = np.arange(-half, half + step / 2, step)
    g = np.stack(np.meshgrid(axis, axis, indexing="ij"), -1).reshape(-1, 2) + problem.x_bar
    log_prior = scipy.stats.multivariate_normal(problem.x_bar, problem.Pxx).logpdf(g)
    resid = z - g @ problem.H.T
    l0 = scipy.stats.multivariate_normal(np.zeros(2), problem.Pww).logpdf(resid)
    l1 = scipy.stats.multivariate_normal(np.zeros(2), problem.Pww + problem.Pbb).logpdf(resid)
    log_w = log_prior + np.logaddexp(np.log(problem.p0) + l0, np.log(problem.p1) + l1)
    w = np.exp(log_w - log_w.max())
    return w @ g / w.sum()


@pytest.mark.parametrize(
    ("problem", "half", "step", "offsets"),
    [
        (static_problem(power=200.0), 60.0, 0.2, [[0.0, 0.0], [15.0, -5.0], [-15.0, 7.0]]),
        (tracking_problem(power=30.0), 10.0, 0.025, [[0.0, 0.0], [4.0, 1.0], [-2.0, 3.0]]),
    ],
    ids=["static-200", "tracking-30"],
)
def test_mmse_estimate_equals_brute_force_posterior_mean(problem, half, step, offsets):
    """E[x | z] of the mixture formula against grid integration, at z = z̄ + offset (1e-6)."""
    est = mmse(problem)
    z = problem.z_bar + np.array(offsets)
    for zi, got in zip(z, est(z).estimate, strict=True):
        np.testing.assert_allclose(got, _grid_posterior_mean(problem, zi, half, step), atol=1e-6)


# --- the attacker's Pbb ---------------------------------------------------------------------


def test_c2_optimal_pbb_on_ch3_static_is_the_literature_diag():
    for a2 in (10.0, 100.0, 400.0):
        np.testing.assert_allclose(static_problem(power=a2).Pbb, np.diag([a2, 0.0]), atol=1e-12)


@st.composite
def pbb_cases(draw):
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    n, nz = draw(st.integers(1, 3)), draw(st.integers(1, 3))
    Pxx, Pww = random_pd(rng, n, 0.1, 50.0), random_pd(rng, nz, 0.1, 10.0)
    H = rng.standard_normal((nz, n))
    power = float(rng.uniform(0.1, 500.0))
    rank = int(rng.integers(1, nz + 1))
    return Pxx, H, Pww, power, random_psd(rng, nz, rank=rank, power=power)


@HYP
@given(pbb_cases())
def test_c2_optimal_pbb_beats_random_psd_of_the_same_power(case):
    """c2(Pbb*) = c4 + a² λ_max(G) >= c2(Pbb) for every random PSD Pbb with tr Pbb = a²."""
    Pxx, H, Pww, power, other = case
    best = c2_optimal_pbb(Pxx, H, Pww, power)
    assert np.trace(best) == pytest.approx(power, rel=1e-12)
    assert np.linalg.matrix_rank(best, tol=1e-9 * power) == 1
    p_best = DetectionProblem(np.zeros(len(Pxx)), Pxx, H, Pww, best, 0.5)
    p_other = p_best.with_pbb(other)
    c2_best, c2_other = p_best.mse(p_best.K0, 1), p_other.mse(p_other.K0, 1)
    c4 = p_best.mse(p_best.K0, 0)
    lam = np.linalg.eigvalsh(c2_gain_matrix(Pxx, H, Pww))[-1]
    assert c2_best - c4 == pytest.approx(power * lam, rel=1e-9, abs=1e-12)
    assert c2_best >= c2_other - 1e-9 * c2_best


# --- tracking reduction ---------------------------------------------------------------------


def test_tracking_prior_is_the_filter_prediction_at_k():
    """P[K|K−1] after 99 clean updates = the DARE steady state; simulated runs have
    E‖x[K] − x̂[K|K−1]‖² = tr P[K|K−1] within 4 SE (4000 runs)."""
    sc = scenarios.get("ch3-tracking")
    P = predicted_covariance(sc)
    np.testing.assert_allclose(P, steady_state(sc.system)[0], atol=1e-12)
    np.testing.assert_allclose(tracking_problem(power=30.0).Pxx, P)
    x, x_pred = simulate_prediction(sc, runs=4000, seed=8)
    err = np.sum((x - x_pred) ** 2, axis=1)
    assert abs(err.mean() - np.trace(P)) <= Z_CI * err.std(ddof=1) / math.sqrt(err.size)


# --- env-facing attributes and batching -----------------------------------------------------


def test_detectors_expose_statistic_threshold_and_on_detect():
    problem = tracking_problem(power=7.5)
    expected = {
        "OBDD": ("quadratic", "discard"),
        "OBDI": ("quadratic", "incorporate"),
        "CBD": ("quadratic", "discard"),
        "CSD": ("chi2", "discard"),
    }
    for name, build in DETECTORS.items():
        det = build(problem)
        assert det.name == name and (det.statistic, det.on_detect) == expected[name]
        assert det.statistic in STATISTICS and isinstance(det.threshold, float)
    # a hand-built detector on the same statistic as the env's action
    custom = Detector("mine", problem, "quadratic", 1.5, "incorporate")
    z = problem.z_bar + np.array([[0.1, 0.0], [6.0, 2.0]])
    r = custom(z)
    np.testing.assert_array_equal(r.decision, r.statistic > 1.5)
    y = z - problem.z_bar
    np.testing.assert_allclose(r.statistic, np.einsum("bi,ij,bj->b", y, problem.A, y))


def test_estimators_are_vectorised_over_leading_batch_axes():
    problem = tracking_problem(power=30.0)
    rng = np.random.default_rng(9)
    z = problem.z_bar + 3.0 * rng.standard_normal((3, 4, 2))
    for est in all_estimators(problem).values():
        batched = est(z).estimate
        assert batched.shape == (3, 4, 2)
        flat = np.stack([est(zi).estimate for zi in z.reshape(-1, 2)])
        np.testing.assert_allclose(batched.reshape(-1, 2), flat, rtol=1e-13)
    r = obdd(problem)(z)
    assert r.decision.shape == r.statistic.shape == (3, 4)


# --- bad inputs -----------------------------------------------------------------------------


def _args(**over):
    args = dict(
        x_bar=np.zeros(2),
        Pxx=np.eye(2),
        H=np.eye(2),
        Pww=np.eye(2),
        Pbb=np.zeros((2, 2)),
        p1=0.5,
    )
    args.update(over)
    return args


@pytest.mark.parametrize("p1", [-0.1, 1.5, float("nan"), "high"])
def test_p1_outside_unit_interval_raises(p1):
    with pytest.raises(ValueError, match="p1"):
        DetectionProblem(**_args(p1=p1))
    with pytest.raises(ValueError, match="p1"):
        static_problem(power=10.0, p1=p1)


@pytest.mark.parametrize("Pbb", [np.diag([1.0, -1.0]), np.array([[1.0, 2.0], [0.0, 1.0]])])
def test_non_psd_pbb_raises(Pbb):
    with pytest.raises(ValueError, match="Pbb"):
        DetectionProblem(**_args(Pbb=Pbb))


def test_nan_threshold_raises():
    problem = DetectionProblem(**_args())
    with pytest.raises(ValueError, match="threshold"):
        Detector("bad", problem, "chi2", float("nan"), "discard")


@pytest.mark.parametrize(
    ("over", "name"),
    [
        ({"H": np.eye(3)}, "H"),
        ({"Pww": np.eye(3)}, "Pww"),
        ({"Pbb": np.zeros((3, 3))}, "Pbb"),
        ({"x_bar": np.zeros(3)}, "x_bar"),
    ],
)
def test_mismatched_shapes_raise(over, name):
    with pytest.raises(ValueError, match=name):
        DetectionProblem(**_args(**over))


def test_measurement_of_the_wrong_size_raises():
    problem = DetectionProblem(**_args())
    for est in all_estimators(problem).values():
        with pytest.raises(ValueError, match="z"):
            est(np.zeros((4, 3)))


def test_other_bad_parameters_name_themselves():
    problem = DetectionProblem(**_args())
    with pytest.raises(ValueError, match="statistic"):
        Detector("bad", problem, "nis", 1.0, "discard")
    with pytest.raises(ValueError, match="on_detect"):
        Detector("bad", problem, "chi2", 1.0, "drop")
    with pytest.raises(ValueError, match="level"):
        csd(problem, level=1.5)
    with pytest.raises(ValueError, match="power"):
        static_problem(power=-1.0)
    with pytest.raises(ValueError, match="draws"):
        monte_carlo(problem, {}, draws=0)


# --- reproduction ---------------------------------------------------------------------------


def test_reproduce_ch3_quick_writes_its_section(tmp_path, capsys):
    from experiments import reproduce

    output = tmp_path / "reproduction.md"
    assert reproduce.main(["ch3", "--quick", "--output", str(output)]) == 0
    text = output.read_text()
    assert "## Chapter 3: detection with minimum MSE" in text
    assert "MMSE ≤ OBDI ≤ OBDD in Monte-Carlo MSE at every a² of the sweep" in text
    assert text.count("**holds**") == 2  # ch3-static and ch3-tracking
    assert "Where the Bayes-cost ranking and the Monte-Carlo ranking disagree" in text
    for name in ("ch3_static.png", "ch3_tracking.png", "ch3_robustness.png"):
        assert (tmp_path / "figures" / name).stat().st_size > 10_000
    assert "Chapter 3" in capsys.readouterr().out
