"""Property: every env constructor builds a sane env or names a parameter it was passed.

For arbitrary keyword arguments (valid values mixed with edge numbers and wrong types) each of
``<module>.parallel_env``, ``gymnasium.make`` and ``gymnasium.make_vec`` either builds an env
whose reset observations lie in their spaces and whose infos are finite, or raises
``ValueError``/``TypeError`` whose message contains the name of a keyword argument passed.
"""

from __future__ import annotations

import importlib
import warnings

import gymnasium as gym
import numpy as np
import pytest
from env_strategies import (
    MODULES,
    PARAMS,
    VECTOR_PARAMS,
    VIEW_PARAMS,
    random_seed,
)
from hypothesis import given
from hypothesis import strategies as st
from prop_support import (
    assert_finite,
    assert_in_space,
    bounded,
    kwargs_of,
    mixed,
    outcome,
    prop_settings,
)

from fdia_env.registration import GYM_IDS, kalman_gym_ids

pytestmark = pytest.mark.filterwarnings("ignore")


def _check_infos(infos: dict) -> None:
    for key, value in infos.items():
        if key != "action_mask":
            assert_finite(value, f"info[{key!r}]")


def _check_parallel(env, seed: int) -> None:
    obs, infos = env.reset(seed=seed)
    assert set(obs) == set(env.possible_agents) == set(infos)
    for agent in env.possible_agents:
        assert_in_space(env.observation_space(agent), obs[agent], f"{agent} observation")
        _check_infos(infos[agent])
    actions = {a: env.action_space(a).sample() for a in env.agents}
    obs, rewards, *_ = env.step(actions)
    for agent in obs:
        assert_in_space(env.observation_space(agent), obs[agent], f"{agent} observation")
        assert_finite(rewards[agent], f"{agent} reward")


@pytest.mark.parametrize("module", MODULES)
@prop_settings(25)
@given(data=st.data(), seed=random_seed())
def test_parallel_env_builds_sane_or_names_a_parameter(module, data, seed):
    mod = importlib.import_module(f"fdia_env.{module}")
    kwargs = data.draw(kwargs_of(PARAMS[module]), label="kwargs")
    built, env = outcome(lambda: mod.parallel_env(**kwargs), kwargs)
    if built:
        with bounded():
            _check_parallel(env, seed)


@pytest.mark.parametrize("env_id", sorted(kalman_gym_ids()))
@prop_settings(12)
@given(data=st.data(), seed=random_seed())
def test_gymnasium_make_builds_sane_or_names_a_parameter(env_id, data, seed):
    module = GYM_IDS[env_id][0].rsplit(".", 1)[1]
    kwargs = data.draw(kwargs_of({**PARAMS[module], **VIEW_PARAMS}), label="kwargs")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        built, env = outcome(lambda: gym.make(env_id, **kwargs), kwargs)
        if not built:
            return
        with bounded():
            obs, info = env.reset(seed=seed)
            assert_in_space(env.observation_space, obs)
            _check_infos(info)
            obs, reward, *_ = env.step(env.action_space.sample())
            assert_in_space(env.observation_space, obs)
            assert_finite(reward, "reward")


@pytest.mark.parametrize("env_id", sorted(kalman_gym_ids()))
@prop_settings(12)
@given(data=st.data(), seed=random_seed())
def test_make_vec_builds_sane_or_names_a_parameter(env_id, data, seed):
    module = GYM_IDS[env_id][0].rsplit(".", 1)[1]
    params = {k: v for k, v in PARAMS[module].items() if k != "render_mode"}
    kwargs = data.draw(kwargs_of({**params, **VECTOR_PARAMS}), label="kwargs")
    kwargs["num_envs"] = data.draw(mixed(st.integers(1, 4)), label="num_envs")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        built, env = outcome(
            lambda: gym.make_vec(env_id, vectorization_mode="vector_entry_point", **kwargs),
            kwargs,
        )
        if not built:
            return
        with bounded():
            obs, _ = env.reset(seed=seed)
            assert_in_space(env.observation_space, obs)
            obs, reward, *_ = env.step(env.action_space.sample())
            assert_in_space(env.observation_space, obs)
            assert_finite(reward, "rewards")
            assert np.shape(reward) == (env.num_envs,)
