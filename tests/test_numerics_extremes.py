"""Rewards and infos at the extremes of every accepted parameter (exact, finite, or refused)."""

import gymnasium as gym
import numpy as np
import pytest

from baselines.covariance import det_optimal
from fdia_env import covariance_attack_v0

torch = pytest.importorskip("torch")

COV_ID = "fdia_env/CovarianceAttack-v0"


def _covariance_rewards(power: float, actions: list[np.ndarray], backend: str) -> np.ndarray:
    """The logdet rewards of ``actions`` (one member each) in ch2-position at ``power``."""
    kw = {"scenario": "ch2-position", "power": power, "objective": "logdet"}
    if backend == "single":
        out = []
        for a in actions:
            env = covariance_attack_v0.parallel_env(**kw)
            env.reset(seed=0)
            out.append(env.step({"attacker": a})[1]["attacker"])
        return np.array(out)
    env = gym.make_vec(
        COV_ID,
        num_envs=len(actions),
        vectorization_mode="vector_entry_point",
        backend=backend,
        **kw,
    )
    env.reset(seed=0)
    batch = np.stack(actions).astype(np.float32)
    if backend == "torch":
        batch = torch.as_tensor(batch)
    reward = env.step(batch)[1]
    return np.asarray(reward.numpy() if backend == "torch" else reward, dtype=np.float64)


@pytest.mark.parametrize("backend", ["single", "numpy", "torch"])
@pytest.mark.parametrize("power", [3e3, 1e10, 1e20, 1e30, 1e100, 1e300])
def test_logdet_covariance_rewards_are_exact_and_never_beat_the_certified_optimum(power, backend):
    """det_optimal's policy earns its value; no action (all ones, random) earns more.

    Summing P and a rank-one W Σ W' of 1e20 loses P's small eigenvalue (log det −inf, or
    above the optimum at 1e30 and on torch).
    """
    best = det_optimal("ch2-position", power)
    env = covariance_attack_v0.parallel_env(scenario="ch2-position", power=power)
    optimal = env.attack.sigma_to_action(best.sigma)
    rng = np.random.default_rng(0)
    others = [np.ones(3), -np.ones(3), np.array([1.0, -1.0, 1.0])]
    others += [rng.uniform(-1, 1, 3) for _ in range(5)]
    others += [np.array([1.0, 0.75, 0.0]) * s for s in (1.0, 1.0 - 1e-7, 1.0 + 1e-7)]
    others = [np.clip(a, -1, 1).astype(np.float32) for a in others]
    rewards = _covariance_rewards(power, [optimal, *others], backend)
    assert np.isfinite(rewards).all()
    np.testing.assert_allclose(rewards[0], best.value, rtol=1e-13)
    assert (rewards[1:] <= best.value * (1 + 1e-13)).all(), (rewards, best.value)


# --- the non-central χ² tail far out ------------------------------------------------------------

mpmath = pytest.importorskip("mpmath")


def _mp_ncx2_miss(x: float, dof: int, lam: float) -> "mpmath.mpf":
    """``P[χ²_dof(λ) ≤ x]`` to 40 digits by its Poisson mixture (moderate λ)."""
    with mpmath.workdps(40):
        mu, y, a = mpmath.mpf(lam) / 2, mpmath.mpf(x) / 2, mpmath.mpf(dof) / 2
        # past j ≈ 3 sqrt(μ y) + 3 y each term is below a ninth of the last (P(a + j, y) falls
        # as y^j / j!), past μ + 40 sqrt(μ) the Poisson weights are nothing
        mu_f, y_f = lam / 2, x / 2
        top = int(min(mu_f + 40 * np.sqrt(mu_f), 3 * np.sqrt(mu_f * y_f) + 3 * y_f + dof) + 200)
        return mpmath.fsum(
            mpmath.exp(j * mpmath.log(mu) - mu - mpmath.loggamma(j + 1) if j else -mu)
            * mpmath.gammainc(a + j, 0, y, regularized=True)
            for j in range(top)
        )


def _mp_ncx2_miss_bound(x: float, dof: int, lam: float) -> "mpmath.mpf":
    """An upper bound of ``P[χ²_dof(λ) ≤ x]`` at any λ (40 digits).

    ``P(a + j, y) ≤ y^{a+j} / Γ(a + j + 1) ≤ y^a / Γ(a + 1) · y^j / j!`` in the Poisson
    mixture gives ``e^{−μ} y^a / Γ(a + 1) · I₀(2 sqrt(μ y))``.
    """
    with mpmath.workdps(40):
        mu, y, a = mpmath.mpf(lam) / 2, mpmath.mpf(x) / 2, mpmath.mpf(dof) / 2
        return (
            mpmath.exp(-mu)
            * y**a
            / mpmath.gamma(a + 1)
            * mpmath.besseli(0, 2 * mpmath.sqrt(mu * y))
        )


@pytest.mark.parametrize(("x", "dof"), [(12.591587243743977, 6), (55.75847927888702, 40)])
def test_ncx2_tail_matches_mpmath_up_to_its_far_tail(x, dof):
    """scipy's range to 1e-14, and 1.0 exactly past it, where scipy gives NaN (λ ≥ ~1e19)."""
    from fdia_env.stealth.tails import ncx2_sf

    moderate = [0.0, 1.0, 40.0, 400.0, 3000.0, 12000.0]
    got = ncx2_sf(x, dof, np.array(moderate))
    want = [float(1 - _mp_ncx2_miss(x, dof, lam)) for lam in moderate]
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-14)
    huge = [1e19, 3.3e19, 1e30, 1e300, np.inf]
    got = ncx2_sf(x, dof, np.array(huge))
    assert got.tolist() == [1.0] * len(huge)
    for lam in huge[:-1]:  # the miss probability is far below a double's last digit at 1.0
        assert _mp_ncx2_miss_bound(x, dof, lam) < mpmath.mpf(2) ** -60
    got_t = torch_ncx2(x, dof, moderate + huge)
    np.testing.assert_allclose(got_t, want + [1.0] * len(huge), rtol=0, atol=1e-14)


def torch_ncx2(x: float, dof: int, lams: list[float]) -> np.ndarray:
    """The torch backend's tail on the CPU (scipy) and by its series (the other devices)."""
    from fdia_env.stealth.torch_ops import ncx2_sf, ncx2_sf_series

    lam = torch.tensor(lams, dtype=torch.float64)
    cpu = ncx2_sf(x, dof, lam).numpy()
    series = ncx2_sf_series(x, dof, lam[lam < 1e5])
    np.testing.assert_allclose(series.numpy(), cpu[: len(series)], rtol=0, atol=1e-13)
    return cpu


STEALTH_DYNAMIC_ID = "fdia_env/StealthDynamic-v0"


@pytest.mark.parametrize("backend", ["single", "numpy", "torch"])
@pytest.mark.parametrize(
    ("a_max", "dynamics"), [(3e9, "expected"), (1e10, "sampled"), (1e15, "expected")]
)
def test_stealth_dynamic_detection_probability_is_one_past_scipys_range(a_max, dynamics, backend):
    """A bias of 3e9 innovation deviations is detected with probability 1.0 (scipy: NaN)."""
    from fdia_env.stealth import stealth_dynamic_v0

    kw = {"a_max": a_max, "dynamics": dynamics, "horizon": 3}
    if backend == "single":
        env = stealth_dynamic_v0.parallel_env(**kw)
        env.reset(seed=0)
        steps = []
        for _ in range(3):
            act = np.ones(env.action_space("attacker").shape, np.float32)
            _, rew, _, _, info = env.step({"attacker": act})
            steps.append((rew["attacker"], info["attacker"]["detection_probability"]))
        rewards, p = (np.array(v, dtype=np.float64) for v in zip(*steps, strict=True))
    else:
        env = gym.make_vec(
            STEALTH_DYNAMIC_ID,
            num_envs=2,
            vectorization_mode="vector_entry_point",
            backend=backend,
            **kw,
        )
        env.reset(seed=0)
        rewards, p = [], []
        for _ in range(3):
            act = np.ones((2, *env.single_action_space.shape), np.float32)
            _, rew, _, _, info = env.step(torch.as_tensor(act) if backend == "torch" else act)
            rewards.append(np.asarray(rew.numpy() if backend == "torch" else rew))
            q = info["detection_probability"]
            p.append(np.asarray(q.numpy() if backend == "torch" else q))
        rewards, p = np.array(rewards, dtype=np.float64), np.array(p)
    assert (p == 1.0).all(), p
    assert np.isfinite(rewards).all()
    if dynamics == "expected":  # (1 − p) · phi + p · 0 with p = 1: nothing
        assert (rewards == 0.0).all(), rewards
