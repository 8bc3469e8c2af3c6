"""The native vector env checks a step's actions once (fdia_env.actions) and the models
act on the checked array: any integer dtype that casts safely to int64 acts as int64 (as
``Discrete.contains`` takes each member), and every bad batch is still refused with the message
naming the player and the member."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

from fdia_env.actions import check_batch_actions, check_vector_actions
from fdia_env.backend import get_backend


def _venv(env_id: str, B: int, **kwargs) -> gym.vector.VectorEnv:
    venv = gym.make_vec(env_id, num_envs=B, vectorization_mode="vector_entry_point", **kwargs)
    venv.reset(seed=3)
    return venv


@pytest.mark.parametrize(
    ("env_id", "kwargs", "n"),
    [
        ("fdia_env/SparseAttack-v0", {}, 8),
        ("fdia_env/SparseAttack-v0", {"action": "single"}, None),
        ("fdia_env/SensorGameAttacker-v0", {}, None),
        ("fdia_env/SensorGameDefender-v0", {}, None),
    ],
)
@pytest.mark.parametrize("dtype", [np.uint8, np.int16, np.int32])
def test_any_integer_dtype_steps_as_int64(env_id, kwargs, n, dtype):
    B = 16
    ref, other = _venv(env_id, B, **kwargs), _venv(env_id, B, **kwargs)
    n = n or int(ref.single_action_space.n)
    rng = np.random.default_rng(0)
    for _ in range(12):
        a = rng.integers(0, n, size=B)
        obs_r, rew_r, term_r, trunc_r, _ = ref.step(a.astype(np.int64))
        obs_o, rew_o, term_o, trunc_o, _ = other.step(a.astype(dtype))
        np.testing.assert_array_equal(obs_o, obs_r)
        np.testing.assert_array_equal(rew_o, rew_r)
        np.testing.assert_array_equal(term_o | trunc_o, term_r | trunc_r)


@pytest.mark.parametrize(
    ("actions", "match"),
    [
        (np.array([0, 3, 8, 1], dtype=np.uint8), r"integers in \[0, 8\); member 2 has 8"),
        (np.array([0, -1, 9, 1], dtype=np.int32), r"integers in \[0, 8\); member 1 has -1"),
        (np.array([0, 1, 2, 3], dtype=np.float64), "integer dtype"),
        (np.array([0, 1, 2], dtype=np.int64), r"shape \(4,\).*got shape \(3,\)"),
        (np.array([[0], [1], [2], [3]], dtype=np.int64), r"got shape \(4, 1\)"),
        (np.array([True, False, True, False]), "integer dtype"),  # np.bool_ members
        (np.array([0, 1, 2, 3], dtype=np.uint64), "casts safely to int64"),  # as contains
        ("0123", "be an array of shape"),
    ],
)
def test_bad_batches_are_refused_before_any_member_steps(actions, match):
    venv = _venv("fdia_env/SparseAttack-v0", 4)
    before = venv.unwrapped.sim.phi.copy() if hasattr(venv.unwrapped, "sim") else None
    with pytest.raises(ValueError, match=f"attacker actions must .*{match}"):
        venv.step(actions)
    if before is not None:
        np.testing.assert_array_equal(venv.unwrapped.sim.phi, before)


def test_multibinary_batches_are_checked_once_with_the_same_message():
    venv = _venv("fdia_env/SparseAttack-v0", 3, action="multibinary")
    M = venv.single_action_space.n
    with pytest.raises(ValueError, match=r"attacker action must be a 0/1 array"):
        venv.step(np.full((3, M), 2, dtype=np.int64))
    ok = np.zeros((3, M), dtype=np.float32)
    ok[1, 0] = 1.0
    venv.step(ok)
    assert venv.unwrapped.attack.b_attacked[:, 0].tolist() == [0, 1, 0]


def test_check_batch_actions_returns_the_checked_int64_batch():
    out = check_batch_actions(spaces.Discrete(5), np.array([4, 0], dtype=np.uint8), 2, "attacker")
    assert out.dtype == np.int64 and out.tolist() == [4, 0]
    out = check_batch_actions(spaces.Discrete(5, start=2), [2, 6], 2, "defender")
    assert out.dtype == np.int64 and out.tolist() == [2, 6]
    with pytest.raises(ValueError, match=r"defender actions must be integers in \[2, 7\)"):
        check_batch_actions(spaces.Discrete(5, start=2), np.array([1, 2]), 2, "defender")
    box = np.zeros((2, 3), dtype=np.float32)
    assert check_batch_actions(spaces.Box(-1, 1, (3,)), box, 2, "attacker") is box


def test_check_vector_actions_checks_on_the_envs_backend():
    space = spaces.Discrete(5)
    out = check_vector_actions(
        space, np.array([4, 0], dtype=np.uint8), 2, "attacker", get_backend()
    )
    assert out.dtype == np.int64 and out.tolist() == [4, 0]  # numpy: the checked array
    with pytest.raises(ValueError, match=r"attacker actions must be integers in \[0, 5\)"):
        check_vector_actions(space, np.array([5, 0]), 2, "attacker", get_backend())
    torch = pytest.importorskip("torch")
    xp = get_backend("torch", "cpu")
    t = torch.tensor([1, 3])
    assert check_vector_actions(space, t, 2, "defender", xp) is t  # torch: the tensor as given
    with pytest.raises(TypeError, match=r"defender actions must be a torch\.Tensor"):
        check_vector_actions(space, np.array([1, 3]), 2, "defender", xp)
    with pytest.raises(ValueError, match="defender actions must lie in Discrete"):
        check_vector_actions(space, torch.tensor([1, 7]), 2, "defender", xp)


@pytest.mark.parametrize(
    "env_id", ["fdia_env/CovarianceAttack-v0", "fdia_env/DetectionAttacker-v0"]
)
def test_box_batches_equal_sync_and_bad_ones_are_refused(env_id):
    native, sync = _venv(env_id, 3), gym.make_vec(env_id, num_envs=3, vectorization_mode="sync")
    sync.reset(seed=3)
    shape = (3, *native.single_action_space.shape)
    rng = np.random.default_rng(1)
    for _ in range(4):
        a = rng.uniform(-1.0, 1.0, size=shape).astype(np.float32)
        np.testing.assert_allclose(native.step(a)[1], sync.step(a)[1], rtol=1e-9, atol=1e-12)
    with pytest.raises(ValueError, match=r"attacker action must lie in \[-1, 1\]"):
        native.step(np.full(shape, 2.0))
    with pytest.raises(ValueError, match="attacker action must be finite"):
        native.step(np.full(shape, np.nan))
