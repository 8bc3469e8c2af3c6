"""Mo & Sinopoli's stealthy attack on a Kalman filter with a χ² detector (baselines.stealth)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import optimize, stats

from baselines.stealth import mo_sinopoli
from baselines.stealth.dynamic import attack_effect
from fdia_env.stealth import static_estimation

F = np.array([[1.0, 1.0], [0.0, 1.0]])  # position-velocity tracking, T = 1
C = np.eye(2)  # a position sensor and a velocity sensor
Q = 0.01 * np.eye(2)
R = np.eye(2)


def test_tracking_position_sensor_admits_an_unbounded_stealthy_attack():
    # the unstable eigenvector is the position: C v = (1, 0) lives on the position sensor only
    assert mo_sinopoli(F, C, Q, R, [0]).vulnerable
    assert mo_sinopoli(F, C, Q, R, [0, 1]).vulnerable
    assert not mo_sinopoli(F, C, Q, R, [1]).vulnerable
    result = mo_sinopoli(F, C, Q, R, [0])
    np.testing.assert_allclose(result.direction, [1.0, 0.0], atol=1e-12)
    with pytest.raises(ValueError, match="no attack to play"):
        mo_sinopoli(F, C, Q, R, [1]).attack(10)


def _kalman_run(model, steps, injections, rng):
    """The steady-state filter on sampled data; returns errors and innovations."""
    x = np.zeros(model.n)
    xh = np.zeros(model.n)
    Lq, Lr = np.linalg.cholesky(model.Q + 1e-15 * np.eye(model.n)), np.linalg.cholesky(model.R)
    errors, innovations = [], []
    for k in range(steps):
        x = model.A @ x + Lq @ rng.standard_normal(model.n)
        y = model.C @ x + Lr @ rng.standard_normal(model.m) + injections[k]
        z = y - model.C @ model.A @ xh
        xh = model.A @ xh + model.K @ z
        errors.append(x - xh)
        innovations.append(z)
    return np.array(errors), np.array(innovations)


def test_attack_grows_the_error_and_keeps_the_detector_statistic_in_distribution():
    result = mo_sinopoli(F, C, Q, R, [0])
    steps = 4000
    inj = result.attack(steps, scale=0.01)
    assert np.all(inj[:, 1] == 0.0)  # only the attacked sensor is touched
    clean_e, clean_z = _kalman_run(
        result.model, steps, np.zeros((steps, 2)), np.random.default_rng(1)
    )
    att_e, att_z = _kalman_run(result.model, steps, inj, np.random.default_rng(1))
    de, dz = attack_effect(result.model, inj)
    # linearity: the sampled filter moves by exactly the predicted changes
    np.testing.assert_allclose(att_e - clean_e, de, atol=1e-8)
    np.testing.assert_allclose(att_z - clean_z, dz, atol=1e-8)
    # the error grows without bound (linearly: λ = 1) ...
    growth = np.linalg.norm(de, axis=1)
    assert growth[-1] > 15.0 and growth[-1] > 1.9 * growth[steps // 2 - 1]
    assert np.linalg.norm(att_e[-1]) > 10 * np.sqrt(np.trace(result.model.P))
    # ... while the innovation moves by a bounded, periodic amount: the χ² statistic keeps its
    # distribution (same alarm rate as the clean run, Kolmogorov-Smirnov against χ²(2))
    assert np.abs(dz).max() < 0.15
    np.testing.assert_allclose(dz[100:102], dz[2000:2002], atol=1e-9)
    Pz_inv = np.linalg.inv(result.model.Pz)
    g = np.einsum("ki,ij,kj->k", att_z, Pz_inv, att_z)
    assert stats.kstest(g, stats.chi2(2).cdf).pvalue > 0.01
    threshold = stats.chi2.isf(0.05, 2)
    g0 = np.einsum("ki,ij,kj->k", clean_z, Pz_inv, clean_z)
    assert abs(np.mean(g > threshold) - np.mean(g0 > threshold)) < 0.01


def _max_error_under_bounded_innovation(model, sensors, horizon, direction):
    """LP: max direction' Δe[T] over attacks on ``sensors`` with |Δz[k]|_∞ ≤ 1 for all k."""
    S = list(sensors)
    cols_e, cols_z = [], []
    for k in range(horizon):
        for s in S:
            inj = np.zeros((horizon, model.m))
            inj[k, s] = 1.0
            de, dz = attack_effect(model, inj)
            cols_e.append(de[-1])
            cols_z.append(dz.reshape(-1))
    E, Z = np.array(cols_e).T, np.array(cols_z).T
    res = optimize.linprog(
        -(direction @ E),
        A_ub=np.vstack([Z, -Z]),
        b_ub=np.ones(2 * Z.shape[0]),
        bounds=[(None, None)] * E.shape[1],
    )
    assert res.status == 0
    return -res.fun


def test_rejected_sets_keep_every_stealthy_attack_bounded():
    model = mo_sinopoli(F, C, Q, R, [1]).model
    for direction in (np.array([1.0, 0.0]), np.array([0.0, 1.0])):
        short = _max_error_under_bounded_innovation(model, [1], 30, direction)
        long = _max_error_under_bounded_innovation(model, [1], 60, direction)
        assert long == pytest.approx(short, rel=1e-2)  # converged: bounded for every horizon
    # positive control: on the accepted set the best stealthy error keeps growing
    short = _max_error_under_bounded_innovation(model, [0], 30, np.array([1.0, 0.0]))
    long = _max_error_under_bounded_innovation(model, [0], 60, np.array([1.0, 0.0]))
    assert long > 1.5 * short


def test_unstable_mode_grows_geometrically():
    A = np.diag([1.2, 0.5])
    Cm = np.array([[1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])
    result = mo_sinopoli(A, Cm, 0.1 * np.eye(2), np.eye(3), [0, 1])
    assert result.vulnerable and result.eigenvalue == pytest.approx(1.2)
    de, dz = result.simulate(40)
    assert np.linalg.norm(de[-1]) > 1000.0
    assert np.abs(dz).max() < 2.0
    # C v = (1, 1, 0): the third sensor is untouched, so sensor 1 alone is not enough
    assert not mo_sinopoli(A, Cm, 0.1 * np.eye(2), np.eye(3), [0]).vulnerable
    assert not mo_sinopoli(A, Cm, 0.1 * np.eye(2), np.eye(3), [2]).vulnerable


def test_grid_random_walk_links_to_the_static_security_index():
    # with F = I every direction is an eigenvector of λ = 1: a meter set admits an unbounded
    # stealthy attack iff it holds the support of an undetectable static attack
    est = static_estimation("ieee14")
    n = est.n
    args = (np.eye(n), est.H, 1e-6 * np.eye(n), est.R)
    assert mo_sinopoli(*args, [6, 7, 32]).vulnerable  # the 3-meter attack on bus 7
    for fewer in ([6, 7], [6, 32], [7, 32]):
        assert not mo_sinopoli(*args, fewer).vulnerable


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"sensors": [2]}, "sensors must be distinct positions 0..1"),
        ({"sensors": [0, 0]}, "sensors must be distinct positions"),
        ({"R": -np.eye(2)}, "R must be positive definite"),
        ({"C": np.eye(3)}, "C must have shape"),
        ({"A": [[1.0, np.inf], [0.0, 1.0]]}, "A must be finite"),
    ],
)
def test_bad_input_names_the_parameter(kwargs, match):
    args = {"A": F, "C": C, "Q": Q, "R": R, "sensors": [0], **kwargs}
    with pytest.raises(ValueError, match=match):
        mo_sinopoli(args.pop("A"), args.pop("C"), args.pop("Q"), args.pop("R"), args.pop("sensors"))
