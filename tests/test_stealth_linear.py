"""The KL-optimal linear attack on remote estimation (baselines.stealth.linear)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import optimize

from baselines.stealth import kalman_model, optimal_linear_attack
from baselines.stealth.linear import attack_value

A = np.array([[0.8, 0.2], [0.0, 0.7]])
C = np.array([[1.0, 0.0], [1.0, 1.0]])
Q = 0.5 * np.eye(2)
R = np.diag([1.0, 2.0])


def test_strict_stealth_reverses_the_innovation():
    attack = optimal_linear_attack(A, C, Q, R, 0.0)
    np.testing.assert_allclose(attack.T, -np.eye(2), atol=1e-12)
    assert not attack.Sigma_b.any()
    assert attack.kl == pytest.approx(0.0, abs=1e-12)
    # M = 4 Σ: the remote error gains 4 tr(W Σ) over the clean filter
    assert attack.value > 3 * attack.clean


@pytest.mark.parametrize("delta", [0.05, 0.5, 2.0])
def test_scalar_closed_form_is_the_lambert_w_root(delta):
    attack = optimal_linear_attack([[0.9]], [[1.0]], [[1.0]], [[1.0]], delta)
    s = attack.T[0, 0] ** 2
    assert attack.T[0, 0] < -1.0
    assert s - np.log(s) == pytest.approx(1.0 + 2.0 * delta, rel=1e-12)
    assert attack.kl == pytest.approx(delta, rel=1e-9)


@pytest.mark.parametrize("delta", [0.0, 0.1, 0.5])
def test_closed_form_beats_every_point_of_a_numerical_optimisation(delta):
    model = kalman_model(A, C, Q, R)
    best = optimal_linear_attack(A, C, Q, R, delta)
    assert best.kl <= delta + 1e-9

    def unpack(p):
        B = p[4:].reshape(2, 2)
        return p[:4].reshape(2, 2), B @ B.T

    rng = np.random.default_rng(0)
    found = []
    for _ in range(6):
        res = optimize.minimize(
            lambda p: -attack_value(model, *unpack(p))[0],
            rng.normal(0.0, 0.5, 8),
            method="SLSQP",
            constraints=[
                {"type": "ineq", "fun": lambda p: delta - attack_value(model, *unpack(p))[1]}
            ],
            options={"maxiter": 500, "ftol": 1e-12},
        )
        value, kl = attack_value(model, *unpack(res.x))
        if kl <= delta + 1e-9:
            found.append(value)
            assert value <= best.value * (1 + 1e-6)
    # random feasible points are below it too
    for _ in range(200):
        T = rng.normal(0.0, 1.0, (2, 2))
        value, kl = attack_value(model, T, np.zeros((2, 2)))
        if kl <= delta:
            assert value <= best.value * (1 + 1e-12)
    assert found and max(found) == pytest.approx(best.value, rel=1e-5)


@pytest.mark.parametrize(
    ("args", "match"),
    [
        (([[1.1]], [[1.0]], [[1.0]], [[1.0]], 0.1), "A must be stable"),
        (([[0.5]], [[1.0]], [[1.0]], [[1.0]], -0.1), "delta must be a finite KL budget >= 0"),
        (([[0.5]], [[1.0]], [[1.0]], [[1.0]], np.nan), "delta must be a finite KL budget >= 0"),
        (([[0.5]], [[1.0]], [[1.0]], [[0.0]], 0.1), "R must be positive definite"),
    ],
)
def test_bad_input_names_the_parameter(args, match):
    with pytest.raises(ValueError, match=match):
        optimal_linear_attack(*args)
