"""agents/torch_vector.py: copies of a Gymnasium env as the torch vector env torch-ppo trains on.

Each copy must play exactly as the env alone: the same observations, rewards, flags, masks
and, when an episode ends, its last observation in ``final_obs`` and the next episode's first
observation in its place (Gymnasium's SAME_STEP autoreset).
"""

import numpy as np
import pytest
import torch

from agents.torch_ppo import TorchPPOConfig, train_torch_ppo
from agents.torch_vector import TorchVectorOf
from fdia_env import tasks

B = 3


def first_legal(mask: np.ndarray) -> int:
    return int(np.flatnonzero(mask)[-1])  # the largest legal subset: episodes differ by copy


@pytest.mark.parametrize("name", ["system-family/tracking-m6-v0", "covariance/ch2-pv-1-v0"])
def test_each_copy_plays_as_the_env_alone(name):
    task = tasks.get(name)
    venv = TorchVectorOf(task.make_env, B, "cpu")
    singles = [task.make_env() for _ in range(B)]
    try:
        obs, _ = venv.reset(seed=7)
        assert obs.dtype == torch.float64 and obs.shape == (B, *venv.single_observation_space.shape)
        expected = np.stack([env.reset(seed=7 + i)[0] for i, env in enumerate(singles)])
        np.testing.assert_array_equal(obs.numpy(), expected)
        masked = venv._masked
        assert masked == (name.startswith("system-family"))
        rng = np.random.default_rng(0)
        ended_once = np.zeros(B, dtype=bool)
        for _ in range(2 * 4 + 1):  # more than two episodes of the family's 4 steps
            if masked:
                masks = venv.action_masks()
                assert masks.dtype == torch.bool
                np.testing.assert_array_equal(
                    masks.numpy(), np.stack([env.unwrapped.action_masks() for env in singles])
                )
                actions = np.array([first_legal(m) for m in masks.numpy()])
            else:
                actions = rng.uniform(-1, 1, size=(B, *venv.single_action_space.shape))
                actions = actions.astype(np.float32)
            obs, reward, terminated, truncated, infos = venv.step(torch.as_tensor(actions))
            for i, env in enumerate(singles):
                o, r, term, trunc, _ = env.step(actions[i])
                assert reward[i].item() == r
                assert terminated[i].item() == term and truncated[i].item() == trunc
                if term or trunc:
                    ended_once[i] = True
                    assert infos["_final_obs"][i].item()
                    np.testing.assert_array_equal(infos["final_obs"][i].numpy(), o)
                    o, _ = env.reset()  # SAME_STEP: the next episode's first observation
                elif "_final_obs" in infos:
                    assert not infos["_final_obs"][i].item()
                np.testing.assert_array_equal(obs[i].numpy(), o)
        assert ended_once.all()
    finally:
        venv.close()
        for env in singles:
            env.close()
    assert venv.closed


def test_torch_ppo_trains_on_the_copies_of_an_entry_point_env():
    torch.set_num_threads(1)
    task = tasks.get("system-family/tracking-m6-v0")
    venv = TorchVectorOf(task.make_env, 4, "cpu")
    config = TorchPPOConfig(total_timesteps=32, num_envs=4, num_steps=4, num_minibatches=2)
    try:
        result = train_torch_ppo(venv, config, seed=0)
    finally:
        venv.close()
    assert result.timesteps == 32  # 2 iterations of 4 copies x 4 steps
    env = task.make_env()
    obs, _ = env.reset(seed=0)
    action, _ = result.policy.predict(
        obs, deterministic=True, action_masks=env.unwrapped.action_masks()
    )
    assert env.unwrapped.action_masks()[int(action)]  # a legal subset of the drawn system


def test_bad_copies_are_refused():
    task = tasks.get("covariance/ch2-pv-1-v0")
    with pytest.raises(ValueError, match="num_envs must be an integer >= 1, got 0"):
        TorchVectorOf(task.make_env, 0, "cpu")
