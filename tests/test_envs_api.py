"""API conformance of every environment: PettingZoo, Gymnasium and stable-baselines3 checkers."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from pettingzoo.test import api_test, parallel_api_test, parallel_seed_test, seed_test
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import fdia_env
from fdia_env import (
    sparse_attack_v0,
)
from fdia_env.registration import ENV_NAMES, GYM_IDS, load

MODULES = [load(name) for name in ENV_NAMES]  # every entry of the table of environments
DYNAMICS = ["expected", "sampled"]


@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.NAME)
@pytest.mark.parametrize("dynamics", DYNAMICS)
def test_parallel_api_and_seed(module, dynamics):
    parallel_api_test(module.parallel_env(dynamics=dynamics), num_cycles=200)
    parallel_seed_test(lambda: module.parallel_env(dynamics=dynamics))


@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.NAME)
@pytest.mark.filterwarnings("ignore::UserWarning")
def test_aec_api_and_seed(module):
    api_test(module.env(), num_cycles=100)
    seed_test(lambda: module.env(dynamics="sampled"), num_cycles=50)


@pytest.mark.parametrize("env_id", sorted(GYM_IDS))
@pytest.mark.parametrize("dynamics", DYNAMICS)
def test_gymnasium_and_sb3_checkers(env_id, dynamics):
    gym_check_env(gym.make(env_id, dynamics=dynamics).unwrapped, skip_render_check=False)
    sb3_check_env(gym.make(env_id, dynamics=dynamics), warn=True)


def test_every_gym_id_is_registered_on_import():
    assert set(GYM_IDS) <= set(gym.registry)
    assert fdia_env.__version__


def test_spaces_are_the_same_object_every_call():
    env = sparse_attack_v0.parallel_env()
    assert env.observation_space("attacker") is env.observation_space("attacker")
    assert env.action_space("attacker") is env.action_space("attacker")


@pytest.mark.parametrize("dynamics", DYNAMICS)
def test_same_seed_same_rollout(dynamics):
    def rollout(seed):
        env = gym.make("fdia_env/SparseAttack-v0", dynamics=dynamics, reward_mode="per_step")
        obs, info = env.reset(seed=seed)
        env.action_space.seed(seed)
        trace = [obs]
        done = False
        while not done:
            obs, r, term, trunc, info = env.step(env.action_space.sample(mask=info["action_mask"]))
            trace += [obs, np.array([r])]
            done = term or trunc
        return np.concatenate(trace)

    np.testing.assert_array_equal(rollout(3), rollout(3))
    if dynamics == "sampled":
        assert not np.array_equal(rollout(3), rollout(4))


def test_render_ansi_and_rgb():
    env = sparse_attack_v0.parallel_env(render_mode="ansi")
    env.reset(seed=0)
    env.step({"attacker": 0b011})
    text = env.render()
    assert "step 1/6" in text and "z1, z2" in text and "Φ(trace)" in text
    env = gym.make("fdia_env/SparseAttack-v0", render_mode="rgb_array")
    env.reset(seed=0)
    env.step(1)
    img = env.render()
    assert img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8
    assert img.std() > 0  # something was drawn


def test_observations_are_order_one_and_in_space():
    env = sparse_attack_v0.parallel_env(budget=18)
    obs, _ = env.reset(seed=0)
    space = env.observation_space("attacker")
    for _ in range(6):
        assert space.contains(obs["attacker"])
        assert np.abs(obs["attacker"]["observation"]).max() <= 5
        obs, *_ = env.step({"attacker": 0b111})
