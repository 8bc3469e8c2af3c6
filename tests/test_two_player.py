"""The two-player framework: an active defender, both views, and a fixed opponent policy."""

from typing import Any

import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.utils.env_checker import check_env
from pettingzoo.test import parallel_api_test, parallel_seed_test

from baselines.sparse import SparsePolicy
from fdia_env import fdia_v0
from fdia_env.attacks import SparseAttack
from fdia_env.defenses import DefenseModel
from fdia_env.envs.single_agent import SingleAgentEnv


class DropChosenSensors(DefenseModel):
    """Test defense: the defender picks sensors to distrust; attacked ones it keeps leak nothing.

    (Biases are irrelevant in the sparse model, so an attacked sensor the defender keeps is
    simply dropped as under perfect detection; the defender's own drops cost it information.)
    """

    name = "drop_chosen"
    passive = False

    def bind(self, system, spec) -> None:
        self.full = (1 << system.M) - 1
        self.action_space = spaces.Discrete(2**system.M)
        self.feature_low = np.zeros(0, dtype=np.float32)
        self.feature_high = np.zeros(0, dtype=np.float32)

    def batch_apply(self, actions: Any, attacked: Any, sigma: Any) -> tuple:
        # one implementation over batches (the single env runs it on the batch of one);
        # the env has checked the actions against action_space
        dropped = self.xp.astype(actions, self.xp.int64)
        return self.full & ~dropped & ~attacked, None, None, False


class FixedAction:
    def __init__(self, action: int) -> None:
        self.action = action

    def predict(self, observation, state=None, episode_start=None, deterministic=True):
        return self.action, state


def make(**kwargs):
    return fdia_v0.parallel_env(
        attack=SparseAttack(budget=5), defense=DropChosenSensors(), horizon=6, **kwargs
    )


@pytest.mark.parametrize("dynamics", ["expected", "sampled"])
def test_two_player_parallel_api(dynamics):
    env = make(dynamics=dynamics)
    assert env.possible_agents == ["attacker", "defender"]
    parallel_api_test(env, num_cycles=100)
    parallel_seed_test(lambda: make(dynamics=dynamics))


def test_rewards_are_zero_sum_and_a_dropping_defender_only_hurts_itself():
    env = make(reward_mode="per_step")
    env.reset(seed=0)
    for _ in range(6):
        _, rewards, *_ = env.step({"attacker": 0, "defender": 0b100})
        assert rewards["attacker"] == -rewards["defender"]
    phi_drop = rewards["attacker"]
    env.reset(seed=0)
    for _ in range(6):
        _, rewards, *_ = env.step({"attacker": 0, "defender": 0})
    assert rewards["attacker"] < phi_drop


def test_gymnasium_views_with_fixed_opponents():
    plan = SparsePolicy([0, 0, 1, 1, 1, 3])
    defender_view = SingleAgentEnv(make(), agent="defender", opponent=plan)
    check_env(defender_view, skip_render_check=True)
    defender_view.reset(seed=0)
    total = sum(defender_view.step(0)[1] for _ in range(6))
    assert total == pytest.approx(
        -0.03278559152906327, rel=1e-12
    )  # attacker's plan, no extra drops

    attacker_view = SingleAgentEnv(make(), agent="attacker", opponent=FixedAction(0))
    check_env(attacker_view, skip_render_check=True)


def test_view_of_a_two_player_env_needs_an_opponent():
    with pytest.raises(ValueError, match="opponent is required"):
        SingleAgentEnv(make(), agent="attacker")
