"""The actual error of a filter unaware of injected biases (docs/math.md §2.1)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.linalg
from conftest import all_masks, random_psd, rel_err

from fdia_env import scenarios
from fdia_env.kalman import (
    actual_covariance_step,
    draw,
    extra_mse,
    predict_cov,
    psd_sqrt,
    sampled_step,
    steady_state,
    subset_update,
    transition_matrices,
)


def _nominal(system, steps, masks=None):
    """Nominal P[k|k] and gains W[k] for k = 0..steps (index 0 is the prior, W[0] unused)."""
    Ps, Ws = [np.array(system.P0)], [np.zeros((system.n, system.nz))]
    for k in range(1, steps + 1):
        P, W = subset_update(
            predict_cov(Ps[-1], system.F, system.Q), system, None if masks is None else masks[k]
        )
        Ps.append(P)
        Ws.append(W)
    return np.array(Ps), np.array(Ws)


def _sigma_sequence(rng, nz, length, power):
    """Random PSD Σ[k]: rank one, full rank, zero and low rank, cycling through the kinds."""
    kinds = [1, None, 0, max(1, nz - 1)]
    return np.array(
        [
            random_psd(rng, nz, rank=kinds[k % 4], power=0.0 if kinds[k % 4] == 0 else power)
            for k in range(length)
        ]
    )


def _actual(system, Ps, Ws, sigmas, K):
    """Direct recursion: M[K−1] = P[K−1|K−1], then M[k] from the Joseph form with R + Σ[k]."""
    M = Ps[K - 1]
    out = []
    for j, k in enumerate(range(K, K + len(sigmas))):
        M = actual_covariance_step(M, system.F, system.Q, system.H, system.R, Ws[k], sigmas[j])
        out.append(M)
    return np.array(out)


# --- 4. extra-MSE formula -----------------------------------------------------------------------


@pytest.mark.parametrize("name", ["ch5-game", "ch4-pv-case1", "ch2-pv-2"])
@pytest.mark.parametrize("N", [0, 1, 3, 12])
def test_extra_mse_equals_recursion_minus_nominal_covariance(name, N):
    """A[K+N] from the D_m sum = M[K+N] − P[K+N|K+N] (rel 1e-9), time-varying gains, any Σ."""
    system = scenarios.get(name).system
    rng = np.random.default_rng(100 + N)
    K = 4  # gains still time-varying: the filter starts from P0, not the steady state
    Ps, Ws = _nominal(system, K + N)
    sigmas = _sigma_sequence(rng, system.nz, N + 1, power=50.0)
    M = _actual(system, Ps, Ws, sigmas, K)
    for j in range(N + 1):
        A = extra_mse(system.F, system.H, Ws[K : K + j + 1], sigmas[: j + 1])
        assert rel_err(A, M[j] - Ps[K + j]) <= 1e-9, (j, A, M[j] - Ps[K + j])
    assert np.trace(M[-1] - Ps[K + N]) > 1e-3  # the attack did something


def test_extra_mse_with_dropped_sensors_matches_recursion():
    """Gains with zero columns (random sensor subsets per step) still satisfy A = M − P."""
    system = scenarios.get("ch4-position").system
    rng = np.random.default_rng(7)
    masks = all_masks(system.M)[rng.integers(0, 7, size=20)]
    Ps, Ws = _nominal(system, 19, masks)
    sigmas = _sigma_sequence(rng, system.nz, 15, power=1.0)
    M = _actual(system, Ps, Ws, sigmas, 5)
    A = extra_mse(system.F, system.H, Ws[5:20], sigmas)
    assert rel_err(A, M[-1] - Ps[19]) <= 1e-9


def test_no_attack_actual_covariance_equals_nominal():
    """Σ = None: the Joseph form with the optimal gain reproduces P[k|k] (rel 1e-12)."""
    system = scenarios.get("ch4-pv-case1").system
    Ps, Ws = _nominal(system, 30)
    M = Ps[0]
    for k in range(1, 31):
        M = actual_covariance_step(M, system.F, system.Q, system.H, system.R, Ws[k])
        assert rel_err(M, Ps[k]) <= 1e-12


@pytest.mark.parametrize("rank", [1, None])
def test_single_injection_gives_w_sigma_w_and_decays(rank):
    """A[K] = W Σ W'; after the injection A[K+m] = B^m A[K] B^m' decays to < 1e-6 of A[K]."""
    system = scenarios.get("ch5-game").system
    _, P, W = steady_state(system)
    rng = np.random.default_rng(8)
    sigma = random_psd(rng, system.nz, rank=rank, power=100.0)
    A0 = extra_mse(system.F, system.H, W[None], sigma[None])
    assert rel_err(A0, W @ sigma @ W.T) <= 1e-13
    M = actual_covariance_step(P, system.F, system.Q, system.H, system.R, W, sigma)
    assert rel_err(M - P, A0) <= 1e-10
    traces = [np.trace(A0)]
    B = transition_matrices(system.F, system.H, W)
    for m in range(1, 61):
        sigmas = np.concatenate([sigma[None], np.zeros((m, system.nz, system.nz))])
        A = extra_mse(system.F, system.H, np.broadcast_to(W, (m + 1, *W.shape)), sigmas)
        Bm = np.linalg.matrix_power(B, m)
        assert rel_err(A, Bm @ A0 @ Bm.T) <= 1e-9
        traces.append(np.trace(A))
    assert traces[-1] < 1e-6 * traces[0]
    assert all(b < a for a, b in itertools.pairwise(traces[10:]))  # monotone tail


def test_continuous_injection_reaches_lyapunov_steady_state():
    """Constant Σ with steady gains: A[K+N] → the solution of A = B A B' + W Σ W' (rel 1e-9)."""
    system = scenarios.get("ch4-pv-case1").system
    _, P, W = steady_state(system)
    sigma = random_psd(np.random.default_rng(9), system.nz, rank=1, power=1.0)
    B = transition_matrices(system.F, system.H, W)
    A_inf = scipy.linalg.solve_discrete_lyapunov(B, W @ sigma @ W.T)
    N = 200
    A = extra_mse(
        system.F,
        system.H,
        np.broadcast_to(W, (N + 1, *W.shape)),
        np.broadcast_to(sigma, (N + 1, *sigma.shape)),
    )
    assert rel_err(A, A_inf) <= 1e-9
    M = P
    for _ in range(N + 1):
        M = actual_covariance_step(M, system.F, system.Q, system.H, system.R, W, sigma)
    assert rel_err(M, P + A_inf) <= 1e-9
    assert np.trace(A_inf) > 1.5 * np.trace(W @ sigma @ W.T)  # effects accumulate over time


def test_extra_mse_rejects_mismatched_lengths():
    """Gains and Σ sequences of different lengths raise ValueError naming both."""
    system = scenarios.get("ch5-game").system
    W = np.zeros((3, system.n, system.nz))
    with pytest.raises(ValueError, match="gains and sigmas"):
        extra_mse(system.F, system.H, W, np.zeros((2, system.nz, system.nz)))


# --- 5. Monte Carlo of the sampled filter under attack -------------------------------------------


def test_monte_carlo_squared_error_matches_m_equals_p_plus_a():
    """20,000 runs: sample mean of x̃x̃' = M = P + A per entry and in trace within 5 standard errors.

    Time-varying gains (start from P0), biases b ~ N(0, Σ[k]) on steps 8..12 (rank one and full
    rank), then 4 clean steps. Power check: the same bound rejects the nominal P under attack.
    """
    system = scenarios.get("ch5-game").system
    runs, steps, attack = 20_000, 16, range(8, 13)
    rng = np.random.default_rng(10)
    Ps, Ws = _nominal(system, steps)
    sigmas = {k: random_psd(rng, system.nz, rank=1 + (k % 2) * 2, power=100.0) for k in attack}
    Q_factor, R_factor = psd_sqrt(system.Q), np.linalg.cholesky(system.R)
    x_hat = np.broadcast_to(system.x0, (runs, system.n)).copy()
    x = x_hat + draw(rng, psd_sqrt(system.P0), (runs,))
    M = Ps[0]
    rejected_nominal = []
    for k in range(1, steps + 1):
        sigma = sigmas.get(k)
        M = actual_covariance_step(M, system.F, system.Q, system.H, system.R, Ws[k], sigma)
        x, x_hat, _, _ = sampled_step(
            rng,
            system,
            x,
            x_hat,
            Ws[k],
            Q_factor=Q_factor,
            R_factor=R_factor,
            bias_factor=None if sigma is None else psd_sqrt(sigma),
        )
        e = x - x_hat
        outer = e[:, :, None] * e[:, None, :]
        mean, se = outer.mean(axis=0), outer.std(axis=0, ddof=1) / np.sqrt(runs)
        assert np.all(np.abs(mean - M) <= 5 * se), (k, mean, M, se)
        sq = np.einsum("ri,ri->r", e, e)
        assert abs(sq.mean() - np.trace(M)) <= 5 * sq.std(ddof=1) / np.sqrt(runs), k
        if k in attack:
            rejected_nominal.append(np.any(np.abs(mean - Ps[k]) > 5 * se))
    assert all(rejected_nominal)


# --- 8. numerical robustness --------------------------------------------------------------------


@pytest.mark.parametrize("name", ["ch5-game", "ch4-pv-case1"])
def test_actual_covariance_stays_finite_symmetric_psd_under_huge_biases(name):
    """1000 steps, Σ power log-uniform up to 1e12 (often rank one), random subsets: M stays PSD."""
    system = scenarios.get(name).system
    rng = np.random.default_rng(11)
    masks = np.concatenate([all_masks(system.M), np.zeros((1, system.M), bool)])
    P, M = np.array(system.P0), np.array(system.P0)
    largest = 0.0
    for k in range(1000):
        P, W = subset_update(
            predict_cov(P, system.F, system.Q), system, masks[rng.integers(len(masks))]
        )
        power = 10.0 ** rng.uniform(0, 12) if k % 10 else 1e12
        sigma = random_psd(rng, system.nz, rank=1 if k % 3 else None, power=power)
        M = actual_covariance_step(M, system.F, system.Q, system.H, system.R, W, sigma)
        eig = np.linalg.eigvalsh(M)
        assert np.all(np.isfinite(M)) and np.array_equal(M, M.T), k
        assert eig.min() >= -1e-9 * eig.max(), (k, eig)
        assert np.linalg.eigvalsh(P).min() > 0, k
        largest = max(largest, eig.max())
    assert largest > 1e9  # the huge biases really reached the error covariance
