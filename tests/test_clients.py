"""The ecosystem's real clients on every env: TorchRL, Tianshou, SuperSuit + SB3, PettingZoo."""

import contextlib
import io
import warnings

import gymnasium as gym
import numpy as np
import pytest
from pettingzoo.test import max_cycles_test, performance_benchmark, render_test

import fdia_env
from fdia_env import (
    covariance_attack_v0,
    detection_game_v0,
    fdia_v0,
    sensor_game_v0,
    sparse_attack_v0,
)
from fdia_env.registration import GYM_IDS
from fdia_env.wrappers import flatten_observation_v0, shared_policy_v0

MODULES = [sparse_attack_v0, covariance_attack_v0, sensor_game_v0, detection_game_v0, fdia_v0]
pytestmark = pytest.mark.filterwarnings("ignore")


# --- PettingZoo's own test set (the API and seed tests are in test_envs_api.py) ------------
@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.NAME)
def test_pettingzoo_render_max_cycles_and_performance_tests(module):
    with contextlib.redirect_stdout(io.StringIO()) as out:
        render_test(module.env)  # human, ansi and rgb_array
        max_cycles_test(module)
        performance_benchmark(module.env())
    assert "Φ(trace)" in out.getvalue()  # "human" printed the ansi line


# --- TorchRL -------------------------------------------------------------------------------
@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.NAME)
@pytest.mark.parametrize("dynamics", ["expected", "sampled"])
def test_torchrl_pettingzoo_wrapper_rollout_and_specs(module, dynamics):
    from torchrl.envs.libs.pettingzoo import PettingZooWrapper
    from torchrl.envs.utils import check_env_specs

    env = PettingZooWrapper(module.parallel_env(dynamics=dynamics), use_mask=True)
    check_env_specs(env)
    rollout = env.rollout(20, break_when_any_done=False)
    assert rollout.batch_size[0] == 20
    group = next(iter(env.group_map))
    reward = rollout["next", group, "reward"]
    assert torch_finite(reward)


def torch_finite(t):
    import torch

    return bool(torch.isfinite(t).all())


@pytest.mark.parametrize("env_id", sorted(GYM_IDS))
def test_torchrl_gym_env_with_four_async_envs(env_id):
    from torchrl.envs.libs.gym import GymEnv

    # the workers are spawned fresh processes: Gymnasium's "module:id" form imports fdia_env
    # there first (Gymnasium 1.x has no plugin discovery that would do it)
    env = GymEnv(f"fdia_env:{env_id}", num_envs=4)
    try:
        rollout = env.rollout(8, break_when_any_done=False)
    finally:
        env.close()
    assert tuple(rollout.batch_size) == (4, 8)
    assert torch_finite(rollout["next", "reward"])


@pytest.mark.parametrize("env_id", sorted(GYM_IDS))
def test_torchrl_gym_wrapper_on_the_native_vector_env(env_id):
    from torchrl.envs.libs.gym import GymWrapper
    from torchrl.envs.utils import check_env_specs

    venv = gym.make_vec(
        env_id,
        num_envs=4,
        vectorization_mode="vector_entry_point",
        autoreset_mode=gym.vector.AutoresetMode.SAME_STEP,  # what TorchRL asks for
    )
    env = GymWrapper(venv)
    check_env_specs(env)
    rollout = env.rollout(10, break_when_any_done=False)
    assert tuple(rollout.batch_size) == (4, 10)
    assert "phi" in rollout.keys()  # the stable infos become specs


# --- Tianshou ------------------------------------------------------------------------------
@pytest.mark.parametrize("module", [sensor_game_v0, sparse_attack_v0], ids=lambda m: m.NAME)
def test_tianshou_pettingzoo_env_and_collector(module):
    from tianshou.algorithm.multiagent.marl import MultiAgentPolicy
    from tianshou.algorithm.random import MARLRandomDiscreteMaskedOffPolicyAlgorithm
    from tianshou.data import Collector, VectorReplayBuffer
    from tianshou.env import DummyVectorEnv, PettingZooEnv

    def make():
        return PettingZooEnv(module.env())

    env = make()
    policies = {
        agent: MARLRandomDiscreteMaskedOffPolicyAlgorithm(env.action_space).policy
        for agent in env.agents
    }
    venv = DummyVectorEnv([make, make])
    collector = Collector(MultiAgentPolicy(policies), venv, VectorReplayBuffer(400, 2))
    collector.reset()
    stats = collector.collect(n_episode=6)
    assert stats.n_collected_episodes >= 6
    assert np.all(np.isfinite(stats.returns))


# --- SuperSuit + stable-baselines3 ---------------------------------------------------------
def supersuit_ppo(parallel, policy):
    import supersuit as ss
    from stable_baselines3 import PPO

    venv = ss.pettingzoo_env_to_vec_env_v1(parallel)
    venv = ss.concat_vec_envs_v1(venv, 2, num_cpus=0, base_class="stable_baselines3")
    model = PPO(policy, venv, n_steps=64, batch_size=64, n_epochs=1, device="cpu")
    model.learn(256)
    return model


def test_supersuit_sb3_ppo_on_the_sensor_game_with_a_shared_policy():
    model = supersuit_ppo(shared_policy_v0(sensor_game_v0.parallel_env(rounds=3)), "MlpPolicy")
    assert model.num_timesteps >= 256


def test_supersuit_sb3_ppo_on_sparse_attacks_dict_and_flattened():
    assert supersuit_ppo(sparse_attack_v0.parallel_env(), "MultiInputPolicy").num_timesteps >= 256
    flat = flatten_observation_v0(sparse_attack_v0.parallel_env(illegal_action="noop"))
    assert supersuit_ppo(flat, "MlpPolicy").num_timesteps >= 256


def test_supersuit_sb3_ppo_on_the_detection_game_with_padded_actions():
    model = supersuit_ppo(shared_policy_v0(detection_game_v0.parallel_env()), "MlpPolicy")
    assert model.num_timesteps >= 256


# --- Gymnasium -----------------------------------------------------------------------------
@pytest.mark.parametrize("env_id", sorted(GYM_IDS))
def test_gymnasium_check_env_on_every_id(env_id):
    from gymnasium.utils.env_checker import check_env

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        check_env(gym.make(env_id).unwrapped, skip_render_check=False)
    assert fdia_env.__version__
