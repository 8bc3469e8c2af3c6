"""Property: a wrong value of an enumerated option is an error that names the option.

Every string or enumerated option of every env constructor (``<module>.parallel_env``, the
Gymnasium views' ``gymnasium.make`` and the native vector envs' ``gymnasium.make_vec``) gets
wrong-typed values (None where None is not allowed, arrays, lists, dicts, integers, floats,
NaN, bytes, unknown strings): each must raise ``ValueError`` or ``TypeError`` whose message
contains the option's name, never numpy's "truth value of an array is ambiguous", an
``AttributeError`` or a ``KeyError``.
"""

from __future__ import annotations

import importlib
import inspect

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from prop_support import bounded, examples

import fdia_env  # noqa: F401 - registers the ids
from fdia_env.registration import ENVS

pytestmark = pytest.mark.filterwarnings("ignore")

# option -> (None allowed, non-negative integers allowed) for every enumerated option
ENUMERATED = {
    "scenario": (False, False),
    "objective": (False, False),
    "reward_mode": (False, False),
    "dynamics": (False, False),
    "warmup": (True, True),
    "render_mode": (True, False),
    "illegal_action": (False, False),
    "action": (False, False),
    "order": (False, False),
    "groups": (True, False),
    "structure": (False, False),
    "power_mode": (False, False),
    "allocation": (True, False),
    "types": (True, False),
    "attacker_model": (False, False),
    "statistic": (False, False),
    "on_detect": (False, False),
    "criterion": (False, False),
    "attack": (False, False),
    "defense": (False, False),
    "test": (False, False),
    "defender": (True, False),
}
NONE_OK = {  # None: the default chosen by another option
    ("sensor_game_v0", "illegal_action"),
    ("sparse_attack_v1", "order"),
    ("sparse_attack_v2", "order"),
}
VIEW_OPTIONS = ("agent", "backend", "device")  # gymnasium.make's own
VECTOR_OPTIONS = ("agent", "backend", "device", "autoreset_mode")  # make_vec's own


def _module(name: str):
    return importlib.import_module(ENVS[name].module)


def _params(name: str) -> list[str]:
    return list(inspect.signature(_module(name).parallel_env).parameters)


def test_every_string_option_of_every_constructor_is_enumerated():
    for name in ENVS:
        sig = inspect.signature(_module(name).parallel_env)
        for p in sig.parameters.values():
            text = str(p.annotation)
            if "str" in text or p.name == "scenario":
                assert p.name in ENUMERATED, (name, p.name, text)


CASES = [
    ("parallel", name, None, option)
    for name in ENVS
    for option in _params(name)
    if option in ENUMERATED
]
CASES += [
    ("make", name, env_id, option)
    for name, entry in ENVS.items()
    for env_id in entry.views.values()
    for option in VIEW_OPTIONS
]
CASES += [
    ("make_vec", name, env_id, option)
    for name, entry in ENVS.items()
    for agent, env_id in entry.views.items()
    if entry.has_vector(agent)
    for option in VECTOR_OPTIONS
]


def wrong_values(name: str, option: str) -> st.SearchStrategy:
    none_ok, ints_ok = ENUMERATED.get(option, (option == "device", False))
    none_ok = none_ok or (name, option) in NONE_OK
    text = st.text(max_size=12).filter(lambda s: s.strip() and not s.startswith("grid-"))
    values = [
        st.builds(lambda v: np.array(v), st.lists(text, min_size=1, max_size=3)),
        st.builds(lambda v: np.array(v), st.lists(st.integers(-3, 3), min_size=2, max_size=3)),
        st.lists(text, min_size=1, max_size=2),
        st.dictionaries(text, st.integers(), min_size=1, max_size=2),
        st.floats(allow_nan=True) | st.just(float("nan")),
        st.binary(min_size=1, max_size=6),
        text.map(lambda s: "no-such-" + s),
        st.integers(-(2**40), -1) if ints_ok else st.integers(),
    ]
    if not none_ok:
        values.append(st.none())
    return st.one_of(values)


def _build(face: str, name: str, env_id: str | None, kwargs: dict):
    if face == "parallel":
        return _module(name).parallel_env(**kwargs)
    if face == "make":
        return gym.make(env_id, **kwargs)
    return gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point", **kwargs)


def assert_names_the_option(face, name, env_id, option, value) -> None:
    try:
        with bounded():
            _build(face, name, env_id, {option: value})
    except (ValueError, TypeError) as exc:
        msg = str(exc)
        assert "ambiguous" not in msg, (option, value, msg)
        assert option in msg, (option, value, msg)
        return
    # a few wrong-typed values are values of another kind the option takes (a Box-valued
    # scenario of the stealth env is an H matrix); only those may build
    raise AssertionError(f"{face} {name} {option}={value!r} built an env")


@settings(max_examples=examples(150), deadline=None)
@given(data=st.data())
def test_a_wrong_option_value_is_an_error_naming_the_option(data):
    face, name, env_id, option = data.draw(st.sampled_from(CASES), label="case")
    value = data.draw(wrong_values(name, option), label=option)
    assert_names_the_option(face, name, env_id, option, value)


# the red team's cases, on every constructor each applies to
RED_TEAM = [np.array(["chi2", "lnr"]), np.array([1, 2]), None, -1]


@pytest.mark.parametrize(("face", "name", "env_id", "option"), CASES, ids=str)
def test_arrays_none_and_negative_ints_are_errors_naming_the_option(face, name, env_id, option):
    none_ok, _ = ENUMERATED.get(option, (option == "device", False))
    for value in RED_TEAM:
        if value is None and (none_ok or (name, option) in NONE_OK):
            continue
        assert_names_the_option(face, name, env_id, option, value)
