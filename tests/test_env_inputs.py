"""Every bad input to an environment raises a clear error naming the parameter."""

import gymnasium as gym
import numpy as np
import pytest

from fdia_env import fdia_v0, sparse_attack_v0, tracking_system
from fdia_env.envs.single_agent import SingleAgentEnv


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"budget": -1}, r"budget must be >= 0"),
        ({"budget": 2.5}, r"budget must be an integer"),
        ({"budget": True}, r"budget must be an integer"),
        ({"budget": 19}, r"budget must be <= M \* horizon = 18"),
        ({"horizon": 0}, r"horizon must be >= 1"),
        ({"horizon": 3.0}, r"horizon must be an integer"),
        ({"warmup": -2}, r"warmup must be >= 0"),
        ({"objective": "max"}, r"objective must be one of \['trace', 'logdet'\]"),
        ({"reward_mode": "dense"}, r"reward_mode must be one of"),
        ({"dynamics": "random"}, r"dynamics must be one of"),
        ({"render_mode": "window"}, r"render_mode must be one of \['human', 'ansi', 'rgb_array'\]"),
        (
            {"objective": "logdet", "dynamics": "sampled"},
            r"logdet.*only defined for dynamics='expected'",
        ),
        (
            {"scenario": "ch9-nowhere"},
            r"unknown scenario 'ch9-nowhere'; known scenarios: .*ch4-position",
        ),
        ({"scenario": 42}, r"scenario must be a preset name, a Scenario or a LinearSystem"),
    ],
)
def test_bad_constructor_arguments_raise_value_error(kwargs, match):
    with pytest.raises(ValueError, match=match):
        sparse_attack_v0.parallel_env(**kwargs)


def test_custom_system_without_budget_or_horizon_needs_them():
    system = tracking_system(sigma_v=0.5, sigma_w=[3, 4])
    with pytest.raises(ValueError, match="horizon is required"):
        sparse_attack_v0.parallel_env(scenario=system, budget=1)
    with pytest.raises(ValueError, match="budget is required"):
        sparse_attack_v0.parallel_env(scenario=system, horizon=3)
    env = sparse_attack_v0.parallel_env(scenario=system, budget=1, horizon=3)
    assert env.action_space("attacker").n == 4


def test_too_many_sensors_for_subset_actions():
    system = tracking_system(sigma_v=0.5, sigma_w=[1.0] * 17)
    with pytest.raises(ValueError, match="at most 16 sensors"):
        sparse_attack_v0.parallel_env(scenario=system, budget=1, horizon=2, action="bitmask")


@pytest.mark.parametrize("action", [8, -1, 1.5, "1", None, np.array([1, 2])])
def test_action_outside_space_raises(action):
    env = sparse_attack_v0.parallel_env()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"attacker action must be an integer in \[0, 8\)"):
        env.step({"attacker": action})


def test_numpy_integer_actions_are_accepted():
    env = sparse_attack_v0.parallel_env()
    env.reset(seed=0)
    env.step({"attacker": np.int64(3)})
    env.step({"attacker": np.array(1)})


def test_step_before_reset_raises():
    env = sparse_attack_v0.parallel_env()
    with pytest.raises(RuntimeError, match=r"before reset\(\)"):
        env.step({"attacker": 0})


def test_step_after_episode_end_raises():
    env = sparse_attack_v0.parallel_env(horizon=2, budget=1)
    env.reset(seed=0)
    env.step({"attacker": 0})
    env.step({"attacker": 0})
    with pytest.raises(RuntimeError, match="after the episode ended"):
        env.step({"attacker": 0})
    genv = gym.make("fdia_env/SparseAttack-v0", horizon=1, budget=1)
    genv.reset(seed=0)
    genv.step(0)
    with pytest.raises(RuntimeError, match="after the episode ended"):
        genv.step(0)


def test_missing_agent_action_raises():
    env = sparse_attack_v0.parallel_env()
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"missing \['attacker'\]"):
        env.step({})


def test_single_agent_view_rejects_unknown_agent():
    with pytest.raises(ValueError, match=r"agent must be one of \['attacker'\]"):
        SingleAgentEnv(sparse_attack_v0.parallel_env(), agent="defender")


def test_fdia_v0_rejects_unknown_models():
    with pytest.raises(
        ValueError,
        match=r"attack must be one of \['covariance', 'probabilistic', 'sparse', 'subset'\]",
    ):
        fdia_v0.parallel_env(attack="laser")
    with pytest.raises(
        ValueError,
        match=r"defense must be one of \[.*'threshold_detector', 'unaware'\]",
    ):
        fdia_v0.parallel_env(defense="moat")
    with pytest.raises(TypeError, match="attack must be an AttackModel"):
        fdia_v0.parallel_env(attack=object())


def test_errors_survive_python_optimisations():
    """Checks are exceptions, not asserts: they still fire under ``python -O``."""
    import subprocess
    import sys

    code = (
        "from fdia_env import sparse_attack_v0\n"
        "try:\n    sparse_attack_v0.parallel_env(budget=-1)\n"
        "except ValueError:\n    print('raised')\n"
    )
    out = subprocess.run(
        [sys.executable, "-O", "-c", code], capture_output=True, text=True, check=True
    )
    assert out.stdout.strip() == "raised"
