"""Static DC state estimation under bad-data detection (fdia_env.stealth.static)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from fdia_env.scenarios import GRID_PRESETS
from fdia_env.stealth import sidak_threshold, static_estimation


@pytest.fixture(scope="module")
def ieee14():
    return static_estimation("ieee14")


@pytest.mark.parametrize("preset", sorted(GRID_PRESETS))
def test_undetectable_injection_leaves_residual_unchanged_on_every_grid_preset(preset):
    est = static_estimation(preset)
    rng = np.random.default_rng(7)
    z = est.H @ rng.normal(0.0, 0.1, est.n) + rng.normal(0.0, 0.01, (4, est.m))
    c = rng.normal(0.0, 0.2, est.n)
    a = est.H @ c
    assert np.abs(est.residual(z + a) - est.residual(z)).max() < 1e-9
    assert np.abs(est.statistic(z + a) - est.statistic(z)).max() < 1e-9
    assert np.abs(est.normalized_residuals(z + a) - est.normalized_residuals(z)).max() < 1e-9
    np.testing.assert_allclose(est.estimate(z + a) - est.estimate(z), np.tile(c, (4, 1)), atol=1e-9)
    assert np.all(est.alarm(z + a) == est.alarm(z))
    assert est.noncentrality(a) < 1e-18
    assert est.is_stealthy(a)
    # one meter off the column space is seen
    a[0] += 0.05
    assert not est.is_stealthy(a)
    assert est.noncentrality(a) > 1.0


def test_wls_on_two_equal_meters_by_hand():
    # z1, z2 measure one state with unit noise: estimate = mean, J = (z1 - z2)^2 / 2, dof 1
    est = static_estimation([[1.0], [1.0]], alpha=0.1)
    z = np.array([1.0, 3.0])
    assert est.estimate(z) == pytest.approx([2.0])
    assert est.residual(z) == pytest.approx([-1.0, 1.0])
    assert est.statistic(z) == pytest.approx(2.0)
    assert est.dof == 1
    assert est.threshold == pytest.approx(2.705543454095404)  # chi2(1) upper 10 %
    # residual covariance I - 1 1'/2: normalised residual (z1 - z2) / sqrt(2) per meter
    assert est.normalized_residuals(z) == pytest.approx([-np.sqrt(2.0), np.sqrt(2.0)])
    # injection (d, 0): non-centrality d^2 / 2
    assert est.noncentrality([2.0, 0.0]) == pytest.approx(2.0)
    assert est.detection_probability([2.0, 0.0]) == pytest.approx(
        stats.ncx2.sf(2.705543454095404, 1, 2.0)
    )


def test_noncentrality_matches_the_explicit_formula(ieee14):
    est = ieee14
    W = np.linalg.inv(est.R)
    G = est.H.T @ W @ est.H
    S = np.eye(est.m) - est.H @ np.linalg.solve(G, est.H.T @ W)
    rng = np.random.default_rng(3)
    a = rng.normal(0.0, 0.03, (5, est.m))
    want = np.einsum("bi,ij,bj->b", a, W @ S, a)
    np.testing.assert_allclose(est.noncentrality(a), want, rtol=1e-9)
    Omega = est.R - est.H @ np.linalg.solve(G, est.H.T)
    np.testing.assert_allclose(est.Omega, Omega, atol=1e-15)


@pytest.mark.parametrize("meter", [0, 20])
def test_exact_detection_probability_matches_sampling(ieee14, meter):
    a = np.zeros(ieee14.m)
    a[meter] = 0.06 if meter == 0 else 0.04
    p = float(ieee14.detection_probability(a))
    assert 0.2 < p < 0.9  # a nontrivial probability
    n = 20_000
    rate = ieee14.detection_rate(a, samples=n, seed=11)
    assert abs(rate - p) < 4.0 * np.sqrt(p * (1 - p) / n)


def test_false_alarm_rates(ieee14):
    n = 20_000
    zero = np.zeros(ieee14.m)
    chi2_rate = ieee14.detection_rate(zero, samples=n, seed=5)
    assert abs(chi2_rate - 0.05) < 4.0 * np.sqrt(0.05 * 0.95 / n)
    lnr_rate = ieee14.detection_rate(zero, samples=n, seed=5, test="lnr")
    assert lnr_rate < 0.05 + 4.0 * np.sqrt(0.05 * 0.95 / n)  # Šidák: at most alpha
    assert lnr_rate > 0.03  # and not far below on 34 meters
    # an undetectable attack is seen only at the false-alarm rate, by either test
    a = ieee14.H @ np.full(ieee14.n, 0.3)
    assert float(ieee14.detection_probability(a)) == pytest.approx(0.05, abs=1e-12)
    assert ieee14.detection_rate(a, samples=n, seed=5, test="lnr") == lnr_rate


def test_sidak_threshold():
    assert sidak_threshold(0.05, 1) == pytest.approx(stats.norm.isf(0.025))
    lam = sidak_threshold(0.05, 34)
    assert (1 - 2 * stats.norm.sf(lam)) ** 34 == pytest.approx(0.95)


def test_critical_meter_is_flagged_and_left_out_of_lnr():
    # the third meter is the only one seeing state 2: its residual is always zero
    est = static_estimation([[1.0, 0.0], [1.0, 0.0], [0.0, 1.0]])
    assert est.critical.tolist() == [False, False, True]
    z = np.array([0.0, 0.0, 100.0])
    assert est.residual(z)[2] == pytest.approx(0.0, abs=1e-12)
    assert est.normalized_residuals(z)[2] == 0.0
    assert not est.alarm(z, "lnr")


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"source": [[1.0, 2.0], [2.0, 4.0], [3.0, 6.0]]}, "H must have full column rank"),
        ({"source": [[1.0, 0.0], [0.0, 1.0]]}, "H must have more meters"),
        ({"source": [[1.0], [np.nan]]}, "H must be finite"),
        ({"source": "ieee15"}, "source must be a grid case"),
        ({"alpha": 0.0}, "alpha must be a false-alarm rate in"),
        ({"alpha": 1.0}, "alpha must be a false-alarm rate in"),
        ({"alpha": True}, "alpha must be a false-alarm rate in"),
        ({"sigma": -1.0}, "sigma must be one positive number"),
        ({"sigma": [1.0, 2.0]}, "sigma must be one positive number"),
        ({"R": np.eye(2)}, "R must have shape"),
        ({"R": -np.eye(3)}, "R must be positive definite"),
        ({"lnr_threshold": 0.0}, "lnr_threshold must be a finite number > 0"),
    ],
)
def test_bad_input_names_the_parameter(kwargs, match):
    kwargs = {"source": [[1.0], [1.0], [2.0]], **kwargs}
    source = kwargs.pop("source")
    with pytest.raises(ValueError, match=match):
        static_estimation(source, **kwargs)


def test_non_finite_injection_is_refused(ieee14):
    a = np.zeros(ieee14.m)
    a[2] = np.inf
    with pytest.raises(ValueError, match="a must be finite"):
        ieee14.detection_probability(a)
    with pytest.raises(ValueError, match=r"a must have shape \(\.\.\., 34\)"):
        ieee14.estimate_shift(np.zeros(3))
    with pytest.raises(ValueError, match="test must be one of"):
        ieee14.alarm(np.zeros(34), test="max")
