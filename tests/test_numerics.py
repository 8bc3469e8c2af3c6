"""Numerical stability of the detection game's exact error at every admissible attack power."""

import math
import warnings

import numpy as np
import pytest
import scipy.stats

from baselines.detection import (
    Detector,
    bayes_cost,
    cbd,
    csd,
    expected_mse,
    monte_carlo,
    obdd,
    obdi,
    static_problem,
    tracking_problem,
)
from fdia_env import detection_game_v0
from fdia_env._validation import MAX_POWER, check_power
from fdia_env.detection.gchisq import NumericalAccuracyWarning, gchisq_tails, imhof_sf

POWERS = [1e-2, 1.0, 1e2, 1e4, 1e8, 1e12, MAX_POWER]
Z = 4.5


def _reference_tails(x, mu, k):
    """Both tails of mu1 χ²_k1 + mu2 χ²_k2 by a positive 1-D convolution in 40-digit arithmetic.

    Conditioning on the larger-weight term, X1 = (x / mu1) v², v in [0, 1], every integrand is
    non-negative, so the result is accurate relative to its own size however small.
    """
    mp = pytest.importorskip("mpmath")
    mp.mp.dps = 40
    (m1, m2), (k1, k2) = mu, k
    if m1 < m2:
        m1, m2, k1, k2 = m2, m1, k2, k1
    x, m1, m2 = mp.mpf(x), mp.mpf(m1), mp.mpf(m2)
    h1, h2 = mp.mpf(k1) / 2, mp.mpf(k2) / 2
    c = (x / m1) ** h1 * 2 / (2**h1 * mp.gamma(h1))
    pts = sorted(
        {mp.mpf(0), mp.mpf(1)} | {mp.sqrt(1 - q * m2 / x) for q in (0.1, 1, 10, 100) if q * m2 < x}
    )

    def conv(tail):
        return c * mp.quad(
            lambda v: (
                v ** (2 * h1 - 1) * mp.exp(-x * v * v / (2 * m1)) * tail(x * (1 - v * v) / m2)
            ),
            pts,
        )

    lo = conv(lambda t: mp.gammainc(h2, 0, t / 2, regularized=True))
    up = conv(lambda t: mp.gammainc(h2, t / 2, mp.inf, regularized=True))
    up += mp.gammainc(h1, x / (2 * m1), mp.inf, regularized=True)
    return float(lo), float(up)


@pytest.mark.parametrize(
    ("mu", "k", "x"),
    [
        ((3.0, 0.5), (1, 1), 2.0),
        ((3.0, 0.5), (3, 1), 100.0),  # upper tail ~3e-7
        ((1e12, 1.0), (3, 1), 6.0),  # lower tail ~3e-18: P(D0 | H1) of a 1e12 attack
        ((1e12, 1.0), (1, 1), 1e8),  # the case Imhof's absolute accuracy got wrong by 1e-3
        ((1e100, 2.0), (1, 3), 30.0),
        ((1e300, 1.0), (3, 1), 0.5),  # ~1e-451 underflows: 0
        ((5.0, 1e-8), (1, 3), 0.01),
        ((1.0, 1.0001), (1, 1), 30.0),  # nearly equal weights, upper tail ~2e-7
    ],
)
def test_both_generalized_chi2_tails_are_accurate_relative_to_their_size(mu, k, x):
    lo, up = gchisq_tails(x, list(mu), list(k))
    ref_lo, ref_up = _reference_tails(x, mu, k)
    np.testing.assert_allclose([lo, up], [ref_lo, ref_up], rtol=1e-11, atol=1e-300)


def test_tails_agree_with_imhof_in_the_central_region_and_sum_to_one():
    rng = np.random.default_rng(0)
    for _ in range(10):
        lam = np.exp(rng.uniform(-3, 3, rng.integers(2, 6)))
        for x in np.array([0.3, 1.0, 2.0]) * lam.sum():
            lo, up = gchisq_tails(x, lam)
            assert abs(up - imhof_sf(x, lam)) < 1e-12
            assert abs(lo + up - 1.0) < 1e-14
    lo, up = gchisq_tails(7.0, [2.0, 2.0, 2.0])  # one distinct weight: exact χ²_3
    assert lo == scipy.stats.chi2.cdf(3.5, 3) and up == scipy.stats.chi2.sf(3.5, 3)


def _detector(problem, statistic, on_detect):
    tau = scipy.stats.chi2.ppf(0.95, problem.nz) if statistic == "chi2" else 1.0
    return Detector("D", problem, statistic, tau, on_detect)


@pytest.mark.parametrize("power", POWERS)
@pytest.mark.parametrize("statistic", ["chi2", "quadratic"])
@pytest.mark.parametrize("on_detect", ["discard", "incorporate"])
def test_exact_squared_error_matches_monte_carlo_at_every_power(power, statistic, on_detect):
    problem = static_problem("ch3-static", power)
    detector = _detector(problem, statistic, on_detect)
    with warnings.catch_warnings():
        warnings.simplefilter("error", NumericalAccuracyWarning)
        exact = expected_mse(detector)
    mc = monte_carlo(problem, {"d": detector}, draws=4000, seed=11).stats["d"]
    assert math.isfinite(exact) and exact >= 0.0
    assert abs(exact - mc.mse) <= Z * mc.se, (exact, mc.mse, mc.se)


def test_exact_error_reaches_its_strong_attack_limit_smoothly():
    """CSD and the quadratic test: the error at a² = 1e12, 1e40, 1e150 and MAX_POWER agrees with
    the a² → ∞ limit (old code: 4e11 at 1e12 and −1.6e84 at 1e100), and stays monotone."""
    for statistic, limit in (("chi2", 176.804867769), ("quadratic", 187.259127963)):
        values = [
            expected_mse(_detector(static_problem("ch3-static", a2), statistic, "discard"))
            for a2 in (1e4, 1e8, 1e12, 1e40, 1e150, MAX_POWER)
        ]
        np.testing.assert_allclose(values[3:], limit, rtol=1e-9)
        assert abs(values[2] - limit) < 1e-2 * limit


def test_exact_error_is_continuous_where_the_computed_tail_changes_side():
    """The tail on the threshold's side of the statistic's mean is integrated, the other is one
    minus it: the error is continuous across the mean (and in the threshold everywhere)."""
    problem = static_problem("ch3-static", 100.0)
    for statistic in ("chi2", "quadratic"):
        base = _detector(problem, statistic, "discard")
        mean = float(np.trace(base.matrix @ problem.Pzz1))  # E[statistic | H1]
        taus = mean * (1.0 + np.array([-1e-6, -1e-9, 1e-9, 1e-6]))
        values = [expected_mse(Detector("D", problem, statistic, t, "discard")) for t in taus]
        assert abs(values[1] - values[2]) < 1e-9 * values[1]
        assert abs(values[0] - values[3]) < 1e-4 * values[0]


@pytest.mark.parametrize("power", [1e8, 1e12, 1e150, MAX_POWER])
def test_detector_thresholds_and_bayes_costs_are_finite_at_huge_power(power):
    for problem in (static_problem("ch3-static", power), tracking_problem("ch3-tracking", power)):
        for make in (obdd, obdi, cbd, csd):
            detector = make(problem)
            assert not math.isnan(detector.threshold)  # ±inf only for the documented cases
            r = bayes_cost(detector)
            assert math.isfinite(r.value) and r.value >= 0.0
            assert 0.0 <= r.p_fa <= 1.0 and 0.0 <= r.p_d <= 1.0
            assert math.isfinite(expected_mse(detector)) and expected_mse(detector) >= 0.0


def test_bayes_cost_uses_the_miss_probability_directly():
    """CSD at a² = 1e12: P(D0 | H1) ~ 1e-18 multiplies c2 ~ 1e12; ``1 − P_d`` would be 0 or
    1e-16 (an error of 1e-4 in c, or of 100 %). The value is p1 [P_d c1 + P_miss c2] + p0 [...]
    with P_miss = P(λ χ²₁ + χ²₁ <= τ) from an independent 1-D convolution."""
    problem = static_problem("ch3-static", 1e12)
    d = csd(problem)
    lam = np.linalg.eigvalsh(d.matrix @ problem.Pzz1)  # the statistic's weights under H1
    p_miss, _ = _reference_tails(d.threshold, tuple(lam), (1, 1))
    c = d.costs
    want = problem.p1 * ((1 - p_miss) * c.c1 + p_miss * c.c2) + problem.p0 * (
        0.05 * c.c3 + 0.95 * c.c4
    )
    assert bayes_cost(d).value == pytest.approx(want, rel=1e-9)


@pytest.mark.parametrize("power", [1e8, 1e12, MAX_POWER])
def test_env_reward_is_the_stable_exact_error(power):
    for statistic in ("chi2", "quadratic"):
        env = detection_game_v0.parallel_env(
            scenario="ch3-static", power=power, statistic=statistic
        )
        env.reset(seed=0)
        attack = detection_game_v0.default_opponent(env, "defender").predict(None)[0]
        tau = 5.99 if statistic == "chi2" else 1.0
        _, rewards, *_ = env.step(
            {"attacker": attack, "defender": env.defense.threshold_to_action(tau)}
        )
        problem = static_problem("ch3-static", power)
        want = expected_mse(
            Detector("D", problem, statistic, env.defense.last_threshold, "discard")
        )
        assert math.isfinite(rewards["attacker"])
        assert rewards["attacker"] == pytest.approx(want, rel=1e-4)  # float32 action rounding


def test_power_bound_is_checked_with_a_clear_message():
    assert check_power("power", MAX_POWER) == MAX_POWER
    for bad in (0.0, -1.0, 2 * MAX_POWER, float("inf"), float("nan"), "1e3", True):
        with pytest.raises(ValueError, match="power must"):
            check_power("power", bad)
    with pytest.raises(ValueError, match="power must"):
        static_problem("ch3-static", 1e301)
