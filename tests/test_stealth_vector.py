"""The native vector env of ``fdia_env/StealthAttack-v0`` against the single env."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from fdia_env.stealth import GYM_ID, static_estimation, stealth_attack_v0


@pytest.fixture(scope="module")
def est():
    return static_estimation("ieee14")


def _vec(est, num_envs, **kwargs):
    return gym.make_vec(
        GYM_ID, num_envs=num_envs, vectorization_mode="vector_entry_point", scenario=est, **kwargs
    )


@pytest.mark.parametrize("action", ["shift", "free"])
def test_expected_rewards_and_infos_equal_the_single_env(est, action):
    kwargs = {"budget": 5, "action": action, "dynamics": "expected", "protected": [3]}
    vec = _vec(est, 16, **kwargs)
    vec.reset(seed=0)
    vec.action_space.seed(1)
    actions = vec.action_space.sample()
    _, rewards, terms, _, infos = vec.step(actions)
    single = stealth_attack_v0.parallel_env(scenario=est, **kwargs)
    for i in range(16):
        single.reset(seed=0)
        _, r, _, _, info = single.step({"attacker": actions[i]})
        assert rewards[i] == pytest.approx(r["attacker"], rel=1e-12, abs=1e-15)
        assert infos["meters_used"][i] == info["attacker"]["meters_used"]
        assert infos["detection_probability"][i] == pytest.approx(
            info["attacker"]["detection_probability"], rel=1e-12
        )
    assert terms.all()


def test_next_step_autoreset(est):
    vec = _vec(est, 4, horizon=2)
    obs, _ = vec.reset(seed=0)
    assert obs[:, 0].tolist() == [1.0] * 4
    bits = np.zeros((4, est.n), dtype=np.int8)
    _, _, terms, _, _ = vec.step(bits)
    assert not terms.any()
    _, _, terms, _, _ = vec.step(bits)
    assert terms.all()
    obs, rewards, terms, truncs, _ = vec.step(bits)  # the reset step
    assert obs[:, 0].tolist() == [1.0] * 4
    assert not rewards.any() and not terms.any() and not truncs.any()


def test_sampled_alarm_rate_matches_the_exact_probability(est):
    a = np.zeros(est.m)
    a[0] = 0.06
    p = float(est.detection_probability(a))
    vec = _vec(est, 8000, budget=1, action="free", a_max=0.06)
    vec.reset(seed=5)
    _, rewards, _, _, infos = vec.step(np.tile((a / 0.06).astype(np.float32), (8000, 1)))
    rate = infos["detected"].mean()
    assert abs(rate - p) < 4 * np.sqrt(p * (1 - p) / 8000)
    np.testing.assert_array_equal(rewards == 0.0, infos["detected"])


def test_torch_backend_is_refused(est):
    with pytest.raises(ValueError, match="runs numpy on the CPU"):
        _vec(est, 2, backend="torch")


def test_defender_is_refused_by_the_native_vector_env(est):
    with pytest.raises(ValueError, match="plays the attacker alone"):
        _vec(est, 2, defender="threshold")
