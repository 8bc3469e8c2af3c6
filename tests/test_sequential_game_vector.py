"""The sensor game's sequential format in the native vector env (vector/sequential_game.py)."""

from __future__ import annotations

import warnings

import gymnasium as gym
import numpy as np
import pytest
from conftest import assert_infos_equal
from gymnasium.vector import AutoresetMode, SyncVectorEnv

from fdia_env import sensor_game_v0
from fdia_env.envs.opponents import FixedMix
from fdia_env.vector.env import make_vector
from fdia_env.vector.sequential_game import SequentialGameVectorEnv

IDS = {"attacker": "fdia_env/SensorGameAttacker-v0", "defender": "fdia_env/SensorGameDefender-v0"}
GAME = {"scenario": "ch5-game", "power": 1.0, "rounds": 3, "action": "sequential"}


def _opponent(agent, kwargs, pure):
    """A subset-format opponent: a pure subset (deterministic) or the uniform mix."""
    parallel = sensor_game_v0.parallel_env(**kwargs)
    other = "defender" if agent == "attacker" else "attacker"
    n = len(parallel.models[other].subsets)
    if not pure:
        return FixedMix.uniform(n)
    return FixedMix(np.eye(n)[n // 2])


@pytest.mark.parametrize("agent", ["attacker", "defender"])
@pytest.mark.parametrize("autoreset", [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP])
def test_native_vector_env_matches_sync_vector_env_of_single_views(agent, autoreset):
    # masked random decisions (and some illegal ones, "trim"), members committing rounds at
    # different decisions, episodes ending by the rounds and by max_episode_steps (decisions)
    # (a defender facing max_subset_size=2 would finish every round in 2 decisions: the
    # attacker's 1 or 2 picks take 2; with none, its 1 to 3 picks take 2 or 3)
    kwargs = {**GAME, "max_subset_size": 2 if agent == "attacker" else None}
    B, seed, cap = 4, 5, 6 if agent == "attacker" else 8
    native = gym.make_vec(
        IDS[agent], num_envs=B, vectorization_mode="vector_entry_point", autoreset_mode=autoreset,
        max_episode_steps=cap, opponent=_opponent(agent, kwargs, False), **kwargs,
    )  # fmt: skip
    assert isinstance(native, SequentialGameVectorEnv) and native.autoreset_mode == autoreset
    sync = SyncVectorEnv(
        [
            lambda: gym.make(
                IDS[agent],
                max_episode_steps=cap,
                opponent=_opponent(agent, kwargs, False),
                **kwargs,
            )
            for _ in range(B)
        ],
        autoreset_mode=autoreset,
    )
    assert native.single_observation_space == sync.single_observation_space
    assert native.single_action_space == sync.single_action_space
    obs_n, info_n = native.reset(seed=seed)
    obs_s, info_s = sync.reset(seed=seed)
    np.testing.assert_array_equal(obs_n, obs_s)
    assert_infos_equal(info_n, info_s, "reset", atol=1e-12, obs_atol=1e-7)
    rng = np.random.default_rng(seed)
    mixed = ended = truncated = 0
    for t in range(40):
        mask = info_s["action_mask"]
        np.testing.assert_array_equal(native.action_masks(), mask.astype(bool))
        legal = [int(rng.choice(np.flatnonzero(m))) for m in mask]
        actions = np.where(rng.random(B) < 0.15, rng.integers(0, native.M + 1, B), legal)
        k_before = info_s["step"].copy()
        obs_n, r_n, te_n, tr_n, info_n = native.step(actions)
        obs_s, r_s, te_s, tr_s, info_s = sync.step(actions)
        # to round-off (bit for bit while the members share the history table: the property
        # test in tests/properties/test_prop_engine.py)
        np.testing.assert_allclose(obs_n, obs_s, rtol=1e-6, atol=1e-7, err_msg=f"step {t}")
        np.testing.assert_allclose(r_n, r_s, rtol=1e-9, atol=1e-12, err_msg=f"step {t}")
        np.testing.assert_array_equal(te_n, te_s, err_msg=f"step {t}")
        np.testing.assert_array_equal(tr_n, tr_s, err_msg=f"step {t}")
        assert_infos_equal(info_n, info_s, f"step {t}", atol=1e-12, obs_atol=1e-7)
        moved = info_s["step"] != k_before
        mixed += bool(moved.any() and not moved.all())
        ended += int(te_s.sum())
        truncated += int((tr_s & ~te_s).sum())
    assert mixed > 5 and ended > 3 and truncated > 0, (mixed, ended, truncated)


@pytest.mark.parametrize("agent", ["attacker", "defender"])
def test_torch_backend_matches_numpy_in_expected_dynamics(agent):
    # a pure opponent (nothing drawn): torch equals numpy to 1e-10, autoresets included
    torch = pytest.importorskip("torch")
    kwargs = {**GAME, "scenario": "ch4-position", "power": 25.0, "rounds": 2}
    B, seed = 3, 2
    on_numpy, on_torch = (
        make_vector(
            "fdia_env.sensor_game_v0",
            B,
            agent=agent,
            opponent=_opponent(agent, kwargs, True),
            autoreset_mode=AutoresetMode.SAME_STEP,
            backend=backend,
            **kwargs,
        )
        for backend in ("numpy", "torch")
    )
    obs_n, info_n = on_numpy.reset(seed=seed)
    obs_t, info_t = on_torch.reset(seed=seed)
    np.testing.assert_allclose(obs_t.numpy(), obs_n, rtol=1e-6)
    rng = np.random.default_rng(seed)
    ends = 0
    for t in range(20):
        np.testing.assert_array_equal(on_torch.action_masks().numpy(), on_numpy.action_masks())
        actions = np.array([rng.choice(np.flatnonzero(m)) for m in info_n["action_mask"]])
        obs_n, r_n, te_n, _, info_n = on_numpy.step(actions)
        obs_t, r_t, te_t, _, info_t = on_torch.step(torch.as_tensor(actions))
        np.testing.assert_allclose(r_t.numpy(), r_n, rtol=1e-10, atol=1e-10, err_msg=f"{t}")
        np.testing.assert_allclose(obs_t.numpy(), obs_n, rtol=1e-5, atol=1e-6, err_msg=f"{t}")
        np.testing.assert_array_equal(te_t.numpy(), te_n)
        np.testing.assert_array_equal(info_t["action_mask"].numpy(), info_n["action_mask"])
        np.testing.assert_allclose(info_t["phi"].numpy(), info_n["phi"], rtol=1e-10)
        if "final_obs" in info_n:
            ends += int(info_n["_final_obs"].sum())
            for i in np.flatnonzero(info_n["_final_obs"]):
                np.testing.assert_allclose(
                    info_t["final_obs"][i].numpy(), info_n["final_obs"][i], rtol=1e-5, atol=1e-6
                )
    assert ends >= B


def test_illegal_actions_and_bad_input():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env = make_vector("fdia_env.sensor_game_v0", 2, illegal_action="error", **GAME)
    env.reset(seed=0)
    # attacker: its stop before a pick is illegal
    with pytest.raises(ValueError, match=r"action 0 of member 0 is illegal: the attacker's set is"):
        env.step(np.array([0, 1]))
    with pytest.raises(ValueError, match=r"integers in \[0, 4\); member 1 has 4"):
        env.step(np.array([1, env.M + 1]))
    with pytest.raises(RuntimeError, match="call reset"):
        make_vector("fdia_env.sensor_game_v0", 2, **GAME).step(np.array([1, 1]))
    with pytest.raises(TypeError, match="parallel must be a SequentialSubsetEnv"):
        SequentialGameVectorEnv(sensor_game_v0.parallel_env(), 2)
    with pytest.raises(ValueError, match="backend must be one of"):
        make_vector("fdia_env.sensor_game_v0", 2, backend="jax", **GAME)
    with pytest.raises(ValueError, match="render_mode is not supported"):
        make_vector("fdia_env.sensor_game_v0", 2, render_mode="ansi", **GAME)
    with pytest.raises(ValueError, match="agent must be one of"):
        make_vector("fdia_env.sensor_game_v0", 2, agent="spy", **GAME)
    with pytest.raises(ValueError, match="num_envs"):
        make_vector("fdia_env.sensor_game_v0", 0, **GAME)


@pytest.mark.parametrize("agent", ["attacker", "defender"])
def test_evaluate_plays_the_format_batched_on_its_native_vector_env(agent):
    # agents.evaluate's num_envs path: the same episodes (seeds seed + i) as one by one
    from agents.evaluate import evaluate

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        env = gym.make(IDS[agent], **{**GAME, "rounds": 2})
        one_by_one = evaluate("random", env, n_episodes=6, seed=3)
        batched = evaluate("random", env, n_episodes=6, seed=3, num_envs=4)
    assert np.ptp(one_by_one.returns) > 0  # the episodes differ
    np.testing.assert_allclose(batched.returns, one_by_one.returns, rtol=1e-9, atol=1e-12)
    n = len(env.unwrapped.parallel.models[agent].subsets)
    with pytest.raises(ValueError, match="num_envs=4: a subset-format mix plays the sequential"):
        evaluate(FixedMix.uniform(n), env, n_episodes=2, num_envs=4)


@pytest.mark.parametrize("backend", ["numpy", "torch"])
def test_torchrl_face_serves_the_format_with_its_action_mask(backend):
    pytest.importorskip("torchrl")
    from torchrl.envs.utils import check_env_specs

    from fdia_env.torchrl import FdiaTorchRLEnv

    env = FdiaTorchRLEnv(
        IDS["defender"], num_envs=3, backend=backend, **{**GAME, "rounds": 2}
    )  # fmt: skip
    td = env.reset(seed=0)
    assert td["action_mask"].shape == (3, 4) and td["observation"].shape == (3, 10)
    check_env_specs(env, seed=0)
    rollout = env.rollout(12, break_when_any_done=False)
    assert int(rollout["next", "done"].sum()) >= 3  # every member ended an episode


def test_maskable_ppo_trains_on_the_native_vector_env_through_the_sb3_adapter():
    sb3_contrib = pytest.importorskip("sb3_contrib")
    from fdia_env.vector.sb3 import make_sb3_vec_env

    venv = make_sb3_vec_env(IDS["attacker"], 4, **{**GAME, "rounds": 2})
    model = sb3_contrib.MaskablePPO("MlpPolicy", venv, n_steps=16, batch_size=32, seed=0)
    model.learn(64)
    assert model.num_timesteps == 64
