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
