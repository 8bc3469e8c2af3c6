"""The closed-form 2×2 kernels equal the generic numpy path, on floats and on component arrays."""

import math

import numpy as np
import pytest

from fdia_env.kalman import information_update, inv2, predict_cov, small


def random_spd(rng, batch=()):
    A = rng.standard_normal((*batch, 2, 2))
    return A @ np.swapaxes(A, -1, -2) + 0.1 * np.eye(2)


def test_batched_inv2_equals_numpy_inverse():
    rng = np.random.default_rng(0)
    A = rng.standard_normal((500, 3, 2, 2))
    np.testing.assert_allclose(inv2(A), np.linalg.inv(A), rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("seed", range(5))
def test_float_kernels_equal_generic_path(seed):
    rng = np.random.default_rng(seed)
    P, Q, J = random_spd(rng), random_spd(rng), random_spd(rng)
    F = rng.standard_normal((2, 2))
    p_pred = small.predict2(small.to_sym2(P), small.to_mat2(F), small.to_sym2(Q))
    np.testing.assert_allclose(small.from_sym2(p_pred), predict_cov(P, F, Q), rtol=1e-12)
    post = small.info_update2(p_pred, small.to_sym2(J))
    expected = information_update(predict_cov(P, F, Q), J[None], np.array([True]))
    np.testing.assert_allclose(small.from_sym2(post), expected, rtol=1e-10)
    assert small.trace2(post) == pytest.approx(np.trace(expected), rel=1e-12)
    assert small.logdet2(post) == pytest.approx(np.linalg.slogdet(expected)[1], rel=1e-10)
    a, b, d = post
    a0, _, d0 = small.to_sym2(P)
    assert small.shape_features2(post, small.to_sym2(P)) == pytest.approx(
        [math.log(a / a0), math.log(d / d0), b / math.sqrt(a * d)], rel=1e-12
    )


def test_kernels_work_on_component_arrays():
    rng = np.random.default_rng(7)
    P, Q = random_spd(rng, (64,)), random_spd(rng)
    F = rng.standard_normal((2, 2))
    comps = (P[:, 0, 0], P[:, 0, 1], P[:, 1, 1])
    a, b, d = small.inv2(small.predict2(comps, small.to_mat2(F), small.to_sym2(Q)))
    expected = np.linalg.inv(predict_cov(P, F, Q))
    np.testing.assert_allclose(
        np.stack([a, b, d]), [expected[:, 0, 0], expected[:, 0, 1], expected[:, 1, 1]], rtol=1e-9
    )


def test_singular_matrix_has_minus_infinite_logdet():
    assert small.logdet2((1.0, 1.0, 1.0)) == -math.inf
