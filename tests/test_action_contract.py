"""The action contract, on every env, every player and every face.

An action is accepted exactly when the player's action space's ``contains`` accepts it, with
one widening for ``Box`` (a numpy array of any real dtype is checked after its cast to the
space's dtype, as ``contains`` casts a list); a batch of a native vector env exactly when every
member ``batch[i]`` is. Anything refused is a ``ValueError`` (``TypeError`` for a wrong kind of
batch on torch) naming the player and the space. :func:`in_space` is that rule written with
Gymnasium's own ``contains``; the tests below compare every face against it, on variants built
for each space type so that both outcomes occur.
"""

from __future__ import annotations

import enum
import importlib
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

import fdia_env  # noqa: F401 - registers the ids
from fdia_env.actions import check_action, check_batch_actions
from fdia_env.registration import ENVS, get_env

pytestmark = pytest.mark.filterwarnings("ignore")


def contains(space: spaces.Space, action) -> bool:
    """Gymnasium's ``space.contains`` (an exception, e.g. an int beyond int64, is False)."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return bool(space.contains(action))
    except Exception:  # what contains cannot read is not in the space
        return False


def in_space(space: spaces.Space, action) -> bool:
    """The documented rule: ``contains``, a real numpy array cast first for a ``Box``."""
    if contains(space, action):
        return True
    if isinstance(space, spaces.Box) and isinstance(action, np.ndarray):
        if action.dtype.kind in "biuf":
            with np.errstate(all="ignore"):
                return contains(space, action.astype(space.dtype))
    return False


class Level(enum.IntEnum):
    ONE = 1


def discrete_variants(space: spaces.Discrete) -> list:
    lo, hi = space.start, space.start + space.n
    return [
        lo,
        hi - 1,
        True,
        False,
        Level.ONE,
        np.int64(lo),
        np.int8(lo),
        np.uint8(lo),
        np.array(lo, dtype=np.int32),
        np.array(lo),
        np.bool_(True),
        np.uint64(lo),
        np.array(lo, dtype=np.uint64),
        np.array([lo]),
        float(lo),
        np.float64(lo),
        np.array(float(lo)),
        hi,
        lo - 1,
        np.int64(hi),
        2**70,
        str(lo),
        None,
        [lo],
        complex(lo),
    ]


def box_variants(space: spaces.Box) -> list:
    shape = space.shape
    zeros = np.zeros(shape)
    edge = np.full(shape, float(space.high.flat[0]))
    return [
        zeros.astype(np.float32),
        zeros,  # float64: refused by contains, accepted after the cast
        zeros.astype(np.int64),
        zeros.astype(np.int16),
        np.ones(shape, dtype=bool),  # bool: 1.0 each
        np.zeros(shape, dtype=bool),
        zeros.tolist(),
        tuple(zeros.tolist()),
        np.ones(shape, dtype=bool).tolist(),  # a list of bools
        edge,
        edge + 1e-9,  # float64 round-off above the bound: on it once cast to float32
        edge + 1e-3,
        np.full(shape, 2.0, dtype=np.float32),
        np.full(shape, np.nan),
        np.full(shape, np.inf, dtype=np.float32),
        zeros.astype(complex),
        zeros.astype(object),
        np.zeros((*shape, 1)),
        np.zeros(shape[0] + 1),
        0.0,
        "abc",
        None,
        {"a": 1},
    ]


def multibinary_variants(space: spaces.MultiBinary) -> list:
    shape = space.shape
    bits = (np.arange(int(np.prod(shape))) % 2).reshape(shape)
    return [
        bits.astype(np.int8),
        bits.astype(np.float32),
        bits.astype(np.float64),
        bits.astype(bool),
        bits.astype(object),  # object 0/1
        bits.astype(np.uint64),
        bits.astype(complex),
        bits.tolist(),
        tuple(bits.tolist()),
        bits.astype(bool).tolist(),
        (bits * 2).astype(np.int64),
        bits.astype(np.float64) * 0.5,
        np.where(bits == 1, np.nan, 0.0),
        bits.astype(str),
        np.zeros(bits.size + 1, dtype=np.int8),
        np.int8(1),
        "01",
        None,
    ]


def variants(space: spaces.Space) -> list:
    if isinstance(space, spaces.Discrete):
        return discrete_variants(space)
    if isinstance(space, spaces.Box):
        return box_variants(space)
    if isinstance(space, spaces.MultiBinary):
        return multibinary_variants(space)
    raise AssertionError(f"no variants for {space}")


def valid(space: spaces.Space):
    """An action every space accepts (its first variant)."""
    return variants(space)[0]


# Every env of the table with the options that change a player's action space (its type, or the
# face: the sequential formats wrap the env).
CONFIGS = [
    ("sparse_attack_v0", {}),
    ("sparse_attack_v0", {"action": "multibinary"}),
    ("sparse_attack_v0", {"action": "single"}),
    ("sparse_attack_v0", {"action": "sequential"}),
    ("covariance_attack_v0", {}),
    ("sensor_game_v0", {}),
    ("sensor_game_v0", {"action": "sequential"}),
    ("detection_game_v0", {}),
    ("fdia_v0", {}),
    ("fdia_v0", {"attack": "covariance", "attack_kwargs": {"power": 1.0}}),
    ("sparse_attack_v1", {}),
    ("sparse_attack_v2", {"action": "sequential"}),
    ("stealth_attack_v0", {}),
    ("stealth_attack_v0", {"action": "free"}),
    ("stealth_attack_v0", {"defender": "threshold"}),
    ("stealth_dynamic_v0", {}),
    ("stealth_dynamic_v0", {"defender": "threshold"}),
]


def test_the_configs_cover_every_env_and_every_space_type():
    assert {name for name, _ in CONFIGS} == set(ENVS)
    kinds = set()
    for name, kwargs in CONFIGS:
        env = importlib.import_module(get_env(name).module).parallel_env(**kwargs)
        kinds |= {type(env.action_space(a)) for a in env.possible_agents}
    assert kinds == {spaces.Discrete, spaces.Box, spaces.MultiBinary}


def _ids(config) -> str:
    name, kwargs = config
    return name + "".join(f"-{k}={v}" for k, v in kwargs.items())


def assert_refusal(exc: Exception, who: str, space: spaces.Space, action=None) -> None:
    """The error names the player, the space and (one action) the action."""
    msg = str(exc)
    assert who in msg, msg
    assert str(space) in msg, msg
    if action is not None:
        assert repr(action)[:30] in msg, msg


def _outcome(step, action, who, space, single=True):
    try:
        step(action)
    except (ValueError, TypeError) as exc:
        assert_refusal(exc, who, space, action if single else None)
        return False
    return True


def _both_outcomes(results) -> None:
    assert any(results) and not all(results), results  # the variants probe both sides


@pytest.mark.parametrize("config", CONFIGS, ids=_ids)
def test_parallel_env_accepts_exactly_what_contains_accepts(config):
    name, kwargs = config
    env = importlib.import_module(get_env(name).module).parallel_env(**kwargs)
    for agent in env.possible_agents:
        space = env.action_space(agent)
        seen = []
        for action in variants(space):
            if not env.agents:
                env.reset(seed=0)
            env.reset(seed=0)
            others = {a: valid(env.action_space(a)) for a in env.agents if a != agent}
            step = lambda a, agent=agent, others=others: env.step({agent: a, **others})  # noqa: E731
            ok = _outcome(step, action, agent, space)
            assert ok == in_space(space, action), (agent, space, action)
            seen.append(ok)
        _both_outcomes(seen)


@pytest.mark.parametrize("config", CONFIGS, ids=_ids)
def test_aec_env_accepts_exactly_what_contains_accepts(config):
    name, kwargs = config
    env = importlib.import_module(get_env(name).module).env(**kwargs)
    for agent in env.possible_agents:
        space = env.action_space(agent)
        seen = []
        for action in variants(space):
            env.reset(seed=0)
            while env.agent_selection != agent:  # the other players' turns first
                env.step(valid(env.action_space(env.agent_selection)))
            ok = _outcome(env.step, action, agent, space)
            assert ok == in_space(space, action), (agent, space, action)
            seen.append(ok)
        _both_outcomes(seen)


VIEWS = [
    (name, kwargs, agent)
    for name, kwargs in CONFIGS
    for agent in get_env(name).views
    if agent == "attacker"
    or kwargs.get("defender")
    or name in ("sensor_game_v0", "detection_game_v0")
]


@pytest.mark.parametrize(("name", "kwargs", "agent"), VIEWS, ids=lambda v: str(v))
def test_gymnasium_view_accepts_exactly_what_contains_accepts(name, kwargs, agent):
    kwargs = {k: v for k, v in kwargs.items() if not (k == "defender" and agent == "defender")}
    env = gym.make(get_env(name).views[agent], **kwargs)
    space = env.action_space
    seen = []
    for action in variants(space):
        env.reset(seed=0)
        ok = _outcome(env.step, action, agent, space)
        assert ok == in_space(space, action), (agent, space, action)
        seen.append(ok)
    _both_outcomes(seen)


VECTOR = [
    (name, kwargs, agent, backend)
    for name, kwargs, agent in VIEWS
    if get_env(name).has_vector(agent) and not kwargs.get("defender")
    for backend in get_env(name).backends
]
B = 2


def batches(space: spaces.Space) -> list:
    """Two-member batches: [valid, variant] as a list and, for numeric variants, as an array."""
    out = []
    for action in variants(space):
        out.append([valid(space), action])
        arr = np.asarray(action) if isinstance(action, np.ndarray | np.generic) else None
        if arr is not None and arr.dtype.kind in "biufc":
            first = np.zeros_like(arr) if arr.shape == np.shape(valid(space)) else arr
            out.append(np.stack([first, arr]))
    out.append(np.stack([np.asarray(valid(space))] * (B + 1)))  # B + 1 members
    return out


def batch_in_space(space: spaces.Space, batch) -> bool:
    """Every member ``batch[i]`` in the space, and B of them."""
    return len(batch) == B and all(in_space(space, batch[i]) for i in range(B))


@pytest.mark.parametrize(("name", "kwargs", "agent", "backend"), VECTOR, ids=lambda v: str(v))
def test_native_vector_env_accepts_exactly_the_batches_of_members_contains_accepts(
    name, kwargs, agent, backend
):
    venv = gym.make_vec(
        get_env(name).views[agent],
        num_envs=B,
        vectorization_mode="vector_entry_point",
        backend=backend,
        **kwargs,
    )
    space = venv.single_action_space
    venv.reset(seed=0)
    seen = []
    for batch in batches(space):
        if backend == "torch":
            torch = pytest.importorskip("torch")
            if not isinstance(batch, np.ndarray) or batch.dtype.kind not in "biufc":
                with pytest.raises(TypeError, match=f"{agent} actions must be a torch.Tensor"):
                    venv.step(batch)
                continue
            tensor = torch.as_tensor(batch)
            expected = len(batch) == B and all(
                in_space(space, tensor[i].numpy()) for i in range(len(batch))
            )
            ok = _outcome(venv.step, tensor, agent, space, single=False)
        else:
            expected = batch_in_space(space, batch)
            ok = _outcome(venv.step, batch, agent, space, single=False)
        assert ok == expected, (space, batch)
        seen.append(ok)
    _both_outcomes(seen)


# --- the meaning of an accepted action ------------------------------------------------------


def test_true_is_action_1_on_every_discrete_face():
    from fdia_env import sensor_game_v0, sparse_attack_v0

    rewards = []
    for action in (1, True, np.array(1, dtype=np.int8)):
        env = sparse_attack_v0.parallel_env()
        env.reset(seed=0)
        _, r, _, _, infos = env.step({"attacker": action})
        assert infos["attacker"]["attacked"].tolist() == [1, 0, 0]
        rewards.append(r["attacker"])
    assert rewards[0] == rewards[1] == rewards[2]
    env = sensor_game_v0.parallel_env()
    env.reset(seed=0)
    ref = env.step({"attacker": 1, "defender": 1})[1]
    env.reset(seed=0)
    assert env.step({"attacker": True, "defender": True})[1] == ref
    assert check_action(spaces.Discrete(3), True, "attacker") == 1
    assert type(check_action(spaces.Discrete(3), np.uint8(2), "attacker")) is int


def test_a_bool_box_action_is_its_0_1_floats():
    from fdia_env import covariance_attack_v0

    rewards = []
    for action in (np.array([1.0, 0.0, 1.0], np.float32), np.array([True, False, True])):
        env = covariance_attack_v0.parallel_env()
        env.reset(seed=0)
        rewards.append(env.step({"attacker": action})[1]["attacker"])
    assert rewards[0] == rewards[1]
    out = check_action(spaces.Box(-1, 1, (3,)), np.array([True, False, True]), "attacker")
    assert out.dtype == np.float64 and out.tolist() == [1.0, 0.0, 1.0]
    out = check_action(spaces.Box(-1, 1, (2,)), np.array([1.0 + 1e-9, -1.0 - 1e-9]), "attacker")
    assert out.tolist() == [1.0, -1.0]  # on the bounds, as the float32 cast puts them


def test_an_object_0_1_array_is_a_multibinary_action():
    from fdia_env.stealth import stealth_attack_v0

    damages, attacked = [], []
    for dtype in (np.int8, object):
        env = stealth_attack_v0.parallel_env(dynamics="expected", budget=3)
        env.reset(seed=0)
        bits = np.zeros(13, dtype=dtype)
        bits[[0, 4]] = 1
        info = env.step({"attacker": bits})[4]["attacker"]
        damages.append(info["phi"])
        attacked.append(info["attacked"].tolist())
    assert damages[0] == damages[1] > 0.02  # |K a|_inf of the shift of states 0 and 4
    assert attacked[0] == attacked[1] and sum(attacked[0]) == 3  # the budget's 3 meters
    out = check_action(spaces.MultiBinary(3), np.array([1, 0, 1], dtype=object), "attacker")
    assert out.dtype == np.int8 and out.tolist() == [1, 0, 1]


def test_batches_are_checked_member_by_member_with_the_single_rule():
    space = spaces.Discrete(4)
    out = check_batch_actions(space, [True, np.int64(3)], 2, "attacker")
    assert out.dtype == np.int64 and out.tolist() == [1, 3]
    with pytest.raises(ValueError, match=r"member 1 must be an integer in \[0, 4\)"):
        check_batch_actions(space, [1, 1.0], 2, "attacker")
    with pytest.raises(ValueError, match="casts safely to int64"):
        check_batch_actions(space, np.array([1, 2], dtype=np.uint64), 2, "attacker")
    box = spaces.Box(-1, 1, (2,))
    out = check_batch_actions(box, np.array([[True, False], [False, True]]), 2, "attacker")
    assert out.dtype == np.float64 and out.tolist() == [[1.0, 0.0], [0.0, 1.0]]
    with pytest.raises(ValueError, match=r"attacker action must be finite.*member 1"):
        check_batch_actions(box, np.array([[0.0, 0.0], [np.nan, 0.0]]), 2, "attacker")
    mb = spaces.MultiBinary(2)
    out = check_batch_actions(mb, np.array([[1, 0], [0, 1]], dtype=object), 2, "attacker")
    assert out.dtype == np.int8 and out.tolist() == [[1, 0], [0, 1]]


@pytest.mark.parametrize("action", ["bitmask", "sequential"])
def test_the_system_family_env_takes_its_actions_by_the_same_rule(action):
    from fdia_env.envs.system_family import SystemFamilyEnv, TrackingFamily

    env = SystemFamilyEnv(TrackingFamily(), system_seeds=range(3), action=action, max_sensors=12)
    space = env.action_space
    seen = []
    for variant in discrete_variants(space):
        env.reset(seed=0)
        ok = _outcome(env.step, variant, "attacker", space)
        assert ok == in_space(space, variant), (space, variant)
        seen.append(ok)
    _both_outcomes(seen)
