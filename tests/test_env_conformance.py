"""Stable infos, masks, time limits, rendering and misuse errors of the envs and their views."""

import contextlib
import io

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode
from sb3_contrib.common.maskable.utils import get_action_masks
from stable_baselines3.common.vec_env import DummyVecEnv

from fdia_env import (
    detection_game_v0,
    fdia_v0,
    sensor_game_v0,
    sparse_attack_v0,
)
from fdia_env.envs.opponents import FixedMix
from fdia_env.envs.single_agent import SingleAgentEnv
from fdia_env.registration import ENV_NAMES, load

MODULES = [load(name) for name in ENV_NAMES]  # every entry of the table of environments


def signature(info):
    """Keys, and for each value its Python type or its numpy dtype and shape."""
    return {
        k: (type(v).__name__,) if not isinstance(v, np.ndarray) else (str(v.dtype), v.shape)
        for k, v in info.items()
    }


@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.NAME)
@pytest.mark.parametrize("dynamics", ["expected", "sampled"])
def test_infos_have_the_same_keys_and_shapes_at_reset_and_every_step(module, dynamics):
    env = module.parallel_env(dynamics=dynamics, max_cycles=3)
    _, infos = env.reset(seed=0)
    expected = {a: signature(i) for a, i in infos.items()}
    for sig in expected.values():
        assert {"phi", "step"} <= set(sig)
        assert all(t[0] in ("float", "int", "bool") or len(t) == 2 for t in sig.values()), sig
    env.action_space("attacker").seed(0)
    while env.agents:
        actions = {a: env.action_space(a).sample() for a in env.agents}
        _, _, _, _, infos = env.step(actions)
        assert {a: signature(i) for a, i in infos.items()} == {a: expected[a] for a in infos}


def test_sparse_info_reports_attacked_sensors_as_a_fixed_length_indicator():
    env = sparse_attack_v0.parallel_env(budget=5, horizon=6)
    _, infos = env.reset(seed=0)
    np.testing.assert_array_equal(infos["attacker"]["attacked"], [0, 0, 0])
    assert infos["attacker"]["budget_left"] == 5
    _, _, _, _, infos = env.step({"attacker": 0b101})
    np.testing.assert_array_equal(infos["attacker"]["attacked"], [1, 0, 1])
    assert infos["attacker"]["attacked"].dtype == np.int8
    assert infos["attacker"]["budget_left"] == 3


def test_illegal_action_rules_trim_noop_and_error():
    def spend(rule, action=0b111):
        env = sparse_attack_v0.parallel_env(budget=2, horizon=6, illegal_action=rule)
        env.reset(seed=0)
        _, _, _, _, infos = env.step({"attacker": action})
        return infos["attacker"]["attacked"].tolist(), infos["attacker"]["budget_left"]

    assert spend("trim") == ([1, 1, 0], 0)  # lowest-numbered sensors that fit
    assert spend("noop") == ([0, 0, 0], 2)
    assert spend("error", 0b011) == ([1, 1, 0], 0)  # legal actions pass
    env = sparse_attack_v0.parallel_env(budget=2, horizon=6, illegal_action="error")
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"action 7 \(sensors \[1, 2, 3\]\) is illegal.*mask"):
        env.step({"attacker": 7})
    assert env.step({"attacker": 1})[4]["attacker"]["budget_left"] == 1  # still usable
    with pytest.raises(ValueError, match="illegal_action must be one of"):
        sparse_attack_v0.parallel_env(illegal_action="clip")


@pytest.mark.parametrize("rule", ["trim", "noop", "error"])
def test_illegal_action_rule_is_the_same_in_the_vector_env(rule):
    kwargs = {"budget": 2, "horizon": 3, "illegal_action": rule}
    venv = gym.make_vec("fdia_env/SparseAttack-v0", num_envs=3, **kwargs)
    single = [gym.make("fdia_env/SparseAttack-v0", **kwargs) for _ in range(3)]
    venv.reset(seed=0)
    for e in single:
        e.reset(seed=0)
    actions = np.array([0b001, 0b011, 0b111])
    if rule == "error":
        with pytest.raises(ValueError, match=r"action 7 .* is illegal"):
            venv.step(actions)
        with pytest.raises(ValueError, match=r"action 7 .* is illegal"):
            single[2].step(7)
        return
    _, _, _, _, info = venv.step(actions)
    for i, e in enumerate(single):
        np.testing.assert_array_equal(info["attacked"][i], e.step(int(actions[i]))[4]["attacked"])


def test_gymnasium_view_mask_through_the_standard_wrapper_paths():
    env = gym.make("fdia_env/SparseAttack-v0", budget=1, horizon=2)
    _, info = env.reset(seed=0)
    mask = env.get_wrapper_attr("action_masks")()
    np.testing.assert_array_equal(mask, info["action_mask"].astype(bool))
    np.testing.assert_array_equal(env.unwrapped.action_masks(), mask)
    assert mask.sum() == 4  # nothing, or one of the three sensors
    vec = DummyVecEnv([lambda: gym.make("fdia_env/SparseAttack-v0")])
    vec.reset()
    assert get_action_masks(vec).shape == (1, 8)  # what MaskablePPO reads


def test_max_cycles_sets_the_window_or_truncates_a_longer_one():
    env = sparse_attack_v0.parallel_env(max_cycles=4)  # no horizon: the window is 4 steps
    env.reset(seed=0)
    for _ in range(4):
        _, rewards, terms, truncs, _ = env.step({"attacker": 0})
    assert terms["attacker"] and not truncs["attacker"] and rewards["attacker"] > 0
    env = sparse_attack_v0.parallel_env(horizon=6, max_cycles=2)  # truncated before the end
    env.reset(seed=0)
    env.step({"attacker": 0})
    _, rewards, terms, truncs, _ = env.step({"attacker": 0})
    assert truncs["attacker"] and not terms["attacker"] and rewards["attacker"] == 0.0
    assert env.agents == []
    with pytest.raises(ValueError, match="max_cycles must be >= 1"):
        sensor_game_v0.parallel_env(max_cycles=0)


def test_render_human_prints_the_ansi_line_and_render_accepts_a_mode():
    env = sparse_attack_v0.parallel_env(render_mode="human")
    assert env.metadata["render_fps"] == 4 and "human" in env.metadata["render_modes"]
    env.reset(seed=0)
    with contextlib.redirect_stdout(io.StringIO()) as out:
        env.step({"attacker": 0b011})
        assert env.render() is None
    assert out.getvalue().count("attacked: z1, z2") == 2  # at the step, and by render()
    assert "step 1/6" in env.render("ansi")  # RLlib's ParallelPettingZooEnv passes a mode
    assert env.render("rgb_array").shape[2] == 3
    with pytest.raises(ValueError, match="mode must be one of"):
        env.render("window")


def test_parallel_step_rejects_unknown_agents_wrong_kinds_and_changes_nothing():
    env = sensor_game_v0.parallel_env(rounds=2)
    env.reset(seed=0)
    with pytest.raises(ValueError, match=r"unknown \['atacker'\]"):
        env.step({"atacker": 1, "attacker": 1, "defender": 1})
    with pytest.raises(ValueError, match="defender action must be an integer"):
        env.step({"attacker": 1, "defender": "1"})
    with pytest.raises(ValueError, match="attacker action must be an integer"):
        env.step({"attacker": 1 + 0j, "defender": 1})
    with pytest.raises(ValueError, match="attacker action must be an integer"):
        env.step({"attacker": np.bool_(True), "defender": 1})  # Discrete.contains refuses it
    with pytest.raises(TypeError, match="actions must be a dict"):
        env.step([1, 1])
    _, _, _, _, infos = env.step({"attacker": 1, "defender": 5})
    assert infos["attacker"]["step"] == 1  # the failed calls changed nothing


@pytest.mark.parametrize(
    "action, match",
    [
        (np.array([0.5 + 1j]), "must be real numbers"),
        ("0.5", r"must have shape \(1,\)"),
        (np.array([0.5], dtype=object), "must be real numbers"),
        (np.array([[0.5]]), r"shape \(1,\)"),
    ],
)
def test_box_actions_of_the_wrong_kind_are_rejected(action, match):
    env = detection_game_v0.parallel_env()
    env.reset(seed=0)
    attack = detection_game_v0.default_opponent(env, "defender").predict(None)[0]
    with pytest.raises(ValueError, match=match):
        env.step({"attacker": attack, "defender": action})


def test_aec_misuse_gives_clear_errors_and_leaves_the_env_usable():
    env = sparse_attack_v0.raw_env()
    with pytest.raises(RuntimeError, match="before reset"):
        env.step(0)
    env.reset(seed=0)
    for _ in range(6):
        env.step(0)
    assert env.terminations["attacker"]
    with pytest.raises(ValueError, match="is done: its action must be None"):
        env.step(0)
    env.step(None)  # PettingZoo's protocol: the done agent steps with None
    with pytest.raises(RuntimeError, match="after the episode ended"):
        env.step(None)
    env.reset(seed=1)  # not wedged
    env.step(1)
    assert env.infos["attacker"]["budget_left"] == 4


def test_reset_arguments_are_checked():
    env = sparse_attack_v0.parallel_env()
    env.reset(seed=np.int64(3))
    for bad in (-1, 1.5, "3", True):
        with pytest.raises(ValueError, match="seed must be"):
            env.reset(seed=bad)
    with pytest.warns(UserWarning, match=r"reset options \['budget'\] are ignored"):
        env.reset(seed=0, options={"budget": 2})
    with pytest.raises(TypeError, match="options must be a dict"):
        env.reset(options=3)
    venv = gym.make_vec("fdia_env/SparseAttack-v0", num_envs=2)
    obs_a, _ = venv.reset(seed=np.int64(3))
    obs_b, _ = venv.reset(seed=3)
    np.testing.assert_array_equal(obs_a, obs_b)
    with pytest.raises(ValueError, match="seed must be an int or a list of 2 seeds"):
        venv.reset(seed=[1, 2, 3])


def test_opponents_are_checked_at_construction():
    parallel = sensor_game_v0.parallel_env()
    with pytest.raises(TypeError, match=r"opponent must be a policy with stable-baselines3"):
        SingleAgentEnv(parallel, "attacker", opponent=object())
    with pytest.raises(ValueError, match=r"opponent plays 3 actions .* needs 7 probabilities"):
        SingleAgentEnv(parallel, "attacker", opponent=FixedMix([0.2, 0.3, 0.5]))
    with pytest.raises(ValueError, match="opponent plays 3 actions"):
        gym.make_vec(
            "fdia_env/SensorGameAttacker-v0", num_envs=2, opponent=FixedMix([0.2, 0.3, 0.5])
        )


@pytest.mark.parametrize(
    "actions, match",
    [
        (np.array([1]), r"shape \(4,\)"),  # never broadcast to the batch
        (np.array([1, 2, 3, 4, 5]), r"shape \(4,\)"),
        (np.array([1, 2, 3, 9]), r"member 3 has 9"),
        (np.array([1, 2, 3, 4]) + 0j, "must be integers"),
        (np.array(["1", "2", "3", "4"]), r"member 0 must be an integer in \[0, 8\)"),
        (np.array([1.5, 2, 3, 4]), "must be integers"),
    ],
)
def test_vector_actions_are_checked_against_the_batch(actions, match):
    venv = gym.make_vec("fdia_env/SparseAttack-v0", num_envs=4)
    venv.reset(seed=0)
    with pytest.raises(ValueError, match=match):
        venv.step(actions)
    venv.step(np.zeros(4, dtype=np.int64))  # still usable


def test_vector_box_actions_are_checked_against_the_batch():
    venv = gym.make_vec("fdia_env/DetectionDefender-v0", num_envs=3)
    venv.reset(seed=0)
    with pytest.raises(ValueError, match=r"shape \(3, 1\)"):
        venv.step(np.zeros((1, 1), dtype=np.float32))
    with pytest.raises(ValueError, match=r"must lie in \[-1, 1\]"):
        venv.step(np.full((3, 1), 2.0, dtype=np.float32))
    assert venv.autoreset_mode == AutoresetMode.NEXT_STEP


def test_fdia_v0_model_kwargs_are_checked():
    with pytest.raises(TypeError, match="attack_kwargs must be a dict"):
        fdia_v0.parallel_env(attack_kwargs=3)
    with pytest.raises(ValueError, match=r"attack_kwargs: 'sparse' takes .* unknown \['budgt'\]"):
        fdia_v0.parallel_env(attack_kwargs={"budgt": 3})
    env = fdia_v0.parallel_env(attack_kwargs={"budget": 2, "illegal_action": "noop"})
    assert env.attack.illegal_action == "noop"


@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.NAME)
def test_a_deleted_env_is_garbage_collected(module):
    # the spaces used to be cached with functools.cache on the method, which kept every env
    # alive; they are plain dict lookups now
    import gc
    import weakref

    env = module.parallel_env()
    env.reset(seed=0)
    for agent in env.possible_agents:
        env.observation_space(agent), env.action_space(agent)
    ref = weakref.ref(env)
    del env
    gc.collect()
    assert ref() is None


def test_pickled_envs_keep_read_only_systems():
    import pickle

    env = pickle.loads(pickle.dumps(sparse_attack_v0.parallel_env()))
    assert not env.system.F.flags.writeable and not env.system.Q.flags.writeable
    env.reset(seed=0)
    assert env.step({"attacker": 1})[4]["attacker"]["budget_left"] == 4
