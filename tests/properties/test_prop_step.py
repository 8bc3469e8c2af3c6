"""Property: ``step`` takes any action and either steps sanely or names the player.

A valid action steps: finite rewards, observations inside the observation space, infos with the
keys and shapes they had at reset. Anything else (wrong dtype, shape, NaN, huge, strings,
complex, bools, None, lists) raises ``ValueError``/``TypeError`` naming ``"attacker"`` or
``"defender"``, and the env stays usable: a valid step works right after. A short random rollout
keeps the filter's covariances symmetric PSD and finite at every step, for powers up to 1e12.
"""

from __future__ import annotations

import importlib
import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from env_strategies import random_seed
from gymnasium import spaces
from hypothesis import given
from hypothesis import strategies as st
from prop_support import (
    assert_finite,
    assert_in_space,
    assert_psd,
    bounded,
    info_signature,
    outcome,
    prop_settings,
    wrong_values,
)

from fdia_env.registration import GYM_IDS, kalman_gym_ids

pytestmark = pytest.mark.filterwarnings("ignore")

PLAYERS = ("attacker", "defender")
# small, fast envs of every module (horizons > 1 so that a rejected action is followed by a step)
ENVS = {
    "sparse_attack_v0": {"scenario": "ch4-position", "budget": 3, "horizon": 3},
    "sparse_attack_v1": {"scenario": "ch4-position", "budget": 3, "horizon": 3},
    "sparse_attack_v2": {"scenario": "ch4-position", "budget": 3, "horizon": 3},
    "covariance_attack_v0": {"scenario": "ch2-pv-2", "horizon": 3, "power_mode": "budget"},
    "sensor_game_v0": {"scenario": "ch5-game", "rounds": 3},
    "detection_game_v0": {"scenario": "ch3-static", "horizon": 3},
    "fdia_v0": {
        "scenario": "ch2-position",
        "attack": "covariance",
        "defense": "unaware",
        "horizon": 3,
    },
}


def garbage_arrays(shape: tuple[int, ...]) -> st.SearchStrategy[np.ndarray]:
    """Arrays that are not actions of a space of ``shape``: wrong shape, dtype or values."""
    size = max(1, int(np.prod(shape)) if shape else 1)
    return st.one_of(
        st.sampled_from(
            [
                np.full(shape or (), np.nan),
                np.full(shape or (), np.inf),
                np.full(shape or (), 1e30),
                np.full(shape or (), -1e30),
                np.full(shape or (), 2.5),
                np.zeros((size + 1,)),
                np.zeros((1, size)),
                np.zeros((0,)),
                np.zeros(shape or (), dtype=complex) + 1j,
                np.ones(shape or (), dtype=bool),
                np.array(["a"] * size),
                np.array([None] * size, dtype=object),
            ]
        ),
        st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=size + 1),
    )


def actions_for(space: spaces.Space) -> st.SearchStrategy:
    """Actions inside ``space`` (half the draws) and outside it."""
    if isinstance(space, spaces.Discrete):
        inside = st.one_of(
            st.integers(0, int(space.n) - 1),
            st.integers(0, int(space.n) - 1).map(np.int64),
            st.integers(0, int(space.n) - 1).map(lambda a: np.array(a)),
        )
        outside = st.one_of(
            st.integers(-3, -1),
            st.integers(int(space.n), int(space.n) + 3),
            st.integers(2**62, 2**64),
            st.floats(0, int(space.n) - 1),
            garbage_arrays(()),
            wrong_values(),
        )
    else:
        shape = space.shape
        n = int(np.prod(shape))
        inside = st.lists(st.floats(-1.0, 1.0, width=32), min_size=n, max_size=n).map(
            lambda v: np.array(v, dtype=np.float32).reshape(shape)
        )
        outside = st.one_of(
            st.lists(st.floats(-3.0, 3.0), min_size=n, max_size=n).map(
                lambda v: np.array(v).reshape(shape)
            ),
            st.lists(st.floats(-1.0, 1.0), min_size=n, max_size=n),  # a list: valid if in range
            garbage_arrays(shape),
            wrong_values(),
        )
    return st.one_of(inside, outside)


def _stack(actions: list):
    """The members' actions as one array where numpy can stack them, else the list."""
    try:
        return np.array(actions)
    except (ValueError, TypeError):
        return actions


def _valid_action(space: spaces.Space, rng: np.random.Generator):
    if isinstance(space, spaces.Discrete):
        return int(rng.integers(space.n))
    return rng.uniform(-1.0, 1.0, space.shape).astype(space.dtype)


def _check_step(env, out, signature) -> None:
    obs, rewards, _, _, infos = out
    for agent in obs:
        assert_in_space(env.observation_space(agent), obs[agent], f"{agent} observation")
        assert_finite(rewards[agent], f"{agent} reward")
        assert info_signature(infos[agent]) == signature, (infos[agent], signature)


@pytest.mark.parametrize("module", sorted(ENVS))
@prop_settings(30)
@given(data=st.data(), seed=random_seed())
def test_parallel_step_is_sane_or_names_the_player(module, data, seed):
    env = importlib.import_module(f"fdia_env.{module}").parallel_env(**ENVS[module])
    rng = np.random.default_rng(seed)
    _, infos = env.reset(seed=seed)
    signature = info_signature(infos["attacker"])
    while env.agents:
        actions = {
            a: data.draw(actions_for(env.action_space(a)), label=f"{a} action") for a in env.agents
        }
        stepped, out = outcome(lambda actions=actions: env.step(actions), PLAYERS)
        if stepped:
            _check_step(env, out, signature)
            continue
        # rejected: nothing changed, a valid step works
        valid = {a: _valid_action(env.action_space(a), rng) for a in env.agents}
        with bounded():
            _check_step(env, env.step(valid), signature)


@pytest.mark.parametrize("env_id", sorted(kalman_gym_ids()))
@prop_settings(15)
@given(data=st.data(), seed=random_seed())
def test_gym_view_step_is_sane_or_names_the_player(env_id, data, seed):
    module = GYM_IDS[env_id][0].rsplit(".", 1)[1]
    kwargs = {k: v for k, v in ENVS[module].items() if k not in ("budget",)}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env = gym.make(env_id, **kwargs)
        _, info = env.reset(seed=seed)
        signature = info_signature(info)
        action = data.draw(actions_for(env.action_space), label="action")
        stepped, out = outcome(lambda: env.step(action), PLAYERS)
        if not stepped:
            out = env.step(_valid_action(env.action_space, np.random.default_rng(seed)))
        obs, reward, _, _, info = out
        assert_in_space(env.observation_space, obs)
        assert_finite(reward, "reward")
        assert info_signature(info) == signature


@pytest.mark.parametrize("env_id", sorted(kalman_gym_ids()))
@prop_settings(10)
@given(data=st.data(), seed=random_seed(), num_envs=st.integers(1, 3))
def test_vector_step_is_sane_or_names_the_player(env_id, data, seed, num_envs):
    module = GYM_IDS[env_id][0].rsplit(".", 1)[1]
    kwargs = {k: v for k, v in ENVS[module].items() if k not in ("budget",)}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env = gym.make_vec(
            env_id, num_envs=num_envs, vectorization_mode="vector_entry_point", **kwargs
        )
        _, infos = env.reset(seed=seed)
        signature = info_signature(infos)
        single = env.single_action_space
        batch = data.draw(
            st.one_of(
                st.lists(actions_for(single), min_size=num_envs, max_size=num_envs).map(_stack),
                st.lists(actions_for(single), min_size=0, max_size=num_envs + 2),
                actions_for(single),
                wrong_values(),
            ),
            label="actions",
        )
        stepped, out = outcome(lambda: env.step(batch), PLAYERS)
        if not stepped:
            out = env.step(env.action_space.sample())
        obs, reward, _, _, infos = out
        assert_in_space(env.observation_space, obs)
        assert_finite(reward, "rewards")
        assert {k: v for k, v in info_signature(infos).items() if "final" not in k} == signature


ROLLOUT_ENVS = {
    "sparse_attack_v0": {
        "scenario": st.sampled_from(["ch4-position", "ch4-pv-case1", "ch2-pv-2"]),
        "budget": st.integers(0, 4),  # <= M * horizon: every scenario here has M >= 1
        "objective": st.sampled_from(["trace", "logdet"]),
    },
    "covariance_attack_v0": {
        "scenario": st.sampled_from(["ch2-position", "ch2-pv-1", "ch2-pv-2", "ch4-pv-case3"]),
        "power": st.sampled_from([1e-12, 1e-3, 1.0, 3000.0, 1e6, 1e9, 1e12]),
        "structure": st.sampled_from(["full", "diagonal"]),
        "power_mode": st.sampled_from(["per_step", "budget"]),
    },
    "sensor_game_v0": {
        "scenario": st.sampled_from(["ch5-game", "ch2-position", "ch4-position"]),
        "power": st.sampled_from([1e-12, 1.0, 100.0, 1e6, 1e12]),
        "allocation": st.sampled_from(["independent", "dependent"]),
    },
    "detection_game_v0": {
        "scenario": st.sampled_from(["ch3-static", "ch3-tracking"]),
        "power": st.sampled_from([1e-12, 1e-3, 1.0, 100.0, 1e6, 1e9, 1e12]),
        "statistic": st.sampled_from(["quadratic", "chi2"]),
        "on_detect": st.sampled_from(["discard", "incorporate"]),
        "criterion": st.sampled_from(["mse", "bayes_cost"]),
    },
}


@pytest.mark.parametrize("module", sorted(ROLLOUT_ENVS))
@prop_settings(20)
@given(
    data=st.data(),
    seed=random_seed(),
    dynamics=st.sampled_from(["expected", "sampled"]),
    reward_mode=st.sampled_from(["terminal", "shaped", "per_step"]),
    horizon=st.integers(1, 4),
)
def test_random_rollout_keeps_covariances_psd_and_rewards_finite(
    module, data, seed, dynamics, reward_mode, horizon
):
    kwargs = {k: data.draw(v, label=k) for k, v in ROLLOUT_ENVS[module].items()}
    kwargs.update(dynamics=dynamics, reward_mode=reward_mode)
    kwargs["rounds" if module == "sensor_game_v0" else "horizon"] = horizon
    if module == "detection_game_v0" and kwargs["scenario"] == "ch3-tracking":
        kwargs["horizon"] = 1 if dynamics == "expected" else horizon
    if module == "sparse_attack_v0":
        kwargs["budget"] = min(kwargs["budget"], horizon)
        if dynamics == "sampled":
            kwargs["objective"] = "trace"
    env = importlib.import_module(f"fdia_env.{module}").parallel_env(**kwargs)
    rng = np.random.default_rng(seed)
    with bounded():
        obs, _ = env.reset(seed=seed)
        assert_psd(env.sim.P, "P at reset")
        steps = 0
        while env.agents:
            actions = {a: _valid_action(env.action_space(a), rng) for a in env.agents}
            obs, rewards, *_ = env.step(actions)
            steps += 1
            for agent in obs:
                assert_in_space(env.observation_space(agent), obs[agent], f"{agent} obs")
                assert math.isfinite(rewards[agent]), rewards
            assert_psd(env.sim.P, f"P after step {steps}")
            assert_psd(env.sim.M, f"M after step {steps}")
        assert steps == env.spec.horizon
