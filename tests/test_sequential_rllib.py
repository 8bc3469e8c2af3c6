"""RLlib's masked PPO module on the sequential action format (agents/rllib/module.py).

Needs the fdia-env[rllib] extra. One local Ray; one small PPO iteration of the sensor game's
two masked players with ``illegal_action="error"``, so a single action outside either mask
would stop the test (the sparse attacker's masked view goes through the same module: its
bitmask format is tested in tests/test_rllib.py).
"""

from __future__ import annotations

import pytest

pytest.importorskip("ray.rllib", reason="needs the fdia-env[rllib] extra")


@pytest.fixture(scope="module")
def local_ray():
    import ray

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


@pytest.mark.parametrize(
    ("name", "env_config", "policies"),
    [
        ("sensor_game_v0", {"rounds": 2}, {"attacker", "defender"}),
    ],
)
def test_plain_ppo_config_trains_on_the_sequential_format_within_the_mask(
    local_ray, name, env_config, policies
):
    from ray.rllib.algorithms.ppo import PPOConfig

    from agents.rllib.envs import register_envs
    from agents.rllib.module import MaskedPPOTorchRLModule

    register_envs()
    config = (
        PPOConfig()
        .environment(name, env_config={**env_config, "action": "sequential"})
        .env_runners(num_env_runners=0)
        .training(train_batch_size_per_learner=64, minibatch_size=64, num_epochs=1)
    )
    config.env_config["illegal_action"] = "error"
    if policies is not None:
        config = config.multi_agent(
            policies=policies, policy_mapping_fn=lambda agent_id, *a, **k: agent_id
        )
    algo = config.build_algo()
    try:
        result = algo.train()
        assert result["env_runners"]["num_env_steps_sampled"] >= 64
        for module_id in policies or ["default_policy"]:
            module = algo.get_module(module_id)
            assert isinstance(module, MaskedPPOTorchRLModule) and module._keys is not None
            assert module.observation_space["action_mask"].shape == (4,)  # M + 1, M = 3
    finally:
        algo.stop()
