"""The one ``predict`` of the suite's own policies (fdia_env.envs.policy)."""

from __future__ import annotations

import inspect

import numpy as np
import pytest
from gymnasium import spaces

from agents.bench.agents import CallablePolicy
from agents.evaluate import RandomPolicy
from agents.population import ConstantPolicy
from baselines.covariance.policy import CovariancePolicy
from baselines.game.policy import MixedStrategyPolicy, TypedMixedStrategyPolicy
from baselines.sparse.policy import SparsePolicy
from baselines.stealth.policy import MixedActionPolicy, StealthPolicy
from fdia_env.detection_game_v0 import FixedAction
from fdia_env.envs.opponents import FixedMix
from fdia_env.envs.policy import (
    MaskedPolicyBase,
    PolicyBase,
    SampledPolicyBase,
    batch_size,
    observation_array,
    repeat_action,
)
from fdia_env.envs.sequential import PlanOrderPolicy
from fdia_env.stealth.dynamic_policy import ScheduledPolicy

SHIPPED = (
    FixedMix,
    MixedStrategyPolicy,
    TypedMixedStrategyPolicy,
    SparsePolicy,
    CovariancePolicy,
    StealthPolicy,
    MixedActionPolicy,
    ScheduledPolicy,
    FixedAction,
    RandomPolicy,
    CallablePolicy,
    PlanOrderPolicy,
    ConstantPolicy,
)


@pytest.mark.parametrize("cls", SHIPPED, ids=lambda c: c.__name__)
def test_every_shipped_policy_inherits_the_one_predict(cls):
    assert issubclass(cls, PolicyBase)
    assert "predict" not in vars(cls)  # written once, in the base
    masked = "action_masks" in inspect.signature(cls.predict).parameters
    assert masked == issubclass(cls, MaskedPolicyBase)


def test_predict_returns_acts_action_and_the_state_as_given():
    policy = StealthPolicy([0, 1, 1], kind="shift")
    state = object()
    action, got = policy.predict(np.zeros(3), state=state)
    assert got is state
    assert action.tolist() == [0, 1, 1]
    batch, _ = policy.predict({"observation": np.zeros((4, 3)), "action_mask": None})
    assert batch.shape == (4, 3) and batch[:, 1].tolist() == [1, 1, 1, 1]


def test_the_observation_helpers_read_dicts_none_and_batches():
    obs = {"observation": np.arange(6.0).reshape(2, 3), "action_mask": np.ones(2)}
    assert observation_array(obs).tolist() == [[0.0, 1.0, 2.0], [3.0, 4.0, 5.0]]
    assert observation_array([1, 2], dtype=np.float32).dtype == np.float32
    assert observation_array(None).shape == (0,)
    assert batch_size(obs) == 2 and batch_size(np.zeros(3)) is None and batch_size(None) is None
    single = np.array([1.0, -1.0])
    out = repeat_action(single, np.zeros(5))
    assert out.tolist() == [1.0, -1.0] and out is not single  # a copy, not the policy's array
    assert repeat_action(single, np.zeros((3, 5))).tolist() == [[1.0, -1.0]] * 3


def test_a_seeded_policy_replays_its_draws_after_reset_and_ignores_reset_without_seed():
    mix = FixedMix([0.2, 0.3, 0.5], seed=1)
    first = mix.predict(np.zeros((50, 2)))[0]
    mix.reset(1)
    assert np.array_equal(mix.predict(np.zeros((50, 2)))[0], first)
    assert isinstance(mix, SampledPolicyBase) and np.bincount(first, minlength=3).min() > 0
    rng = mix.rng
    mix.reset()
    assert mix.rng is rng


def test_the_masked_base_hands_the_masks_to_act():
    policy = RandomPolicy(spaces.Discrete(4), seed=0)
    draws = {
        int(policy.predict(np.zeros(2), action_masks=np.array([0, 0, 1, 0]))[0]) for _ in range(20)
    }
    assert draws == {2}


def test_a_policy_without_act_names_what_is_missing():
    class Bare(PolicyBase):
        pass

    with pytest.raises(NotImplementedError, match="Bare must implement act"):
        Bare().predict(np.zeros(2))


def test_a_users_policy_base_subclass_is_an_opponent_like_the_shipped_mix():
    """The docs' recipe: subclass PolicyBase, write act(); the view plays it as the opponent."""
    import gymnasium as gym

    class AlwaysFirst(PolicyBase):
        def act(self, observation, deterministic=False):
            batch = batch_size(observation)
            return np.int64(0) if batch is None else np.zeros(batch, dtype=np.int64)

    n = 7  # the ch5-game's 2**3 - 1 subsets
    returns = []
    for opponent in (AlwaysFirst(), FixedMix(np.eye(n)[0])):
        env = gym.make("fdia_env/SensorGameDefender-v0", opponent=opponent)
        row = []
        for a in range(n):  # one-shot game: one episode per defender action
            env.reset(seed=a)
            row.append(env.step(a)[1])
        returns.append(row)
        env.close()
    assert returns[0] == returns[1]
    assert len(set(returns[0])) > 1  # the defender's choice matters against that attacker


def test_constant_and_plan_order_policies_batch_and_hand_back_the_state():
    state = object()
    action, got = ConstantPolicy(3).predict(np.zeros((4, 2)), state=state)
    assert got is state and action.tolist() == [3, 3, 3, 3]
    assert int(ConstantPolicy(2).predict(np.zeros(2))[0]) == 2
    plan = PlanOrderPolicy([(1, 0), (0, 2)], num_sensors=3, horizon=2)
    obs = np.zeros((2, 4 + 6 + 1))
    obs[1, 4 + 2] = 1.0  # member 1 has planned (step 0, sensor 2): next is (step 1, sensor 0)
    action, got = plan.predict({"observation": obs, "action_mask": None}, state=state)
    assert got is state and action.tolist() == [3, 4]


@pytest.mark.parametrize(
    ("masks", "obs", "match"),
    [
        (np.zeros(3), np.zeros(2), "allows no action"),
        (np.array([1, 0]), np.zeros(2), "3 entries per mask"),
        (np.array([2, 1, 0]), np.zeros(2), "only 0 and 1"),
        ("abc", np.zeros(2), "0/1 \\(or bool\\) array"),
        (np.ones((2, 3)), np.zeros(2), "shape \\(n,\\)"),
        (np.ones((3, 3)), np.zeros((2, 2)), "shape \\(2, n\\)"),
        (np.array([[1, 1, 0], [0, 0, 0]]), np.zeros((2, 2)), "mask 1 allows no action"),
    ],
)
def test_a_malformed_mask_is_refused_by_name(masks, obs, match):
    # RandomPolicy played action 0 for each of these, legal or not
    policy = RandomPolicy(spaces.Discrete(3), seed=0)
    policy.seed_episodes([0, 1])
    with pytest.raises(ValueError, match=f"action_masks.*{match}|{match}"):
        policy.predict(obs, action_masks=masks)


def test_a_well_formed_mask_is_obeyed_batched_and_not():
    policy = RandomPolicy(spaces.Discrete(3), seed=0)
    for _ in range(20):
        assert int(policy.predict(np.zeros(2), action_masks=[0, 0, 1])[0]) == 2
    policy.seed_episodes([0, 1])
    masks = np.array([[True, False, False], [False, True, False]])
    assert policy.predict(np.zeros((2, 2)), action_masks=masks)[0].tolist() == [0, 1]
    fn = CallablePolicy(lambda obs, action_masks=None: int(np.argmax(action_masks)), "f")
    assert fn.predict(np.zeros(2), action_masks=[0, 1, 0])[0] == 1
