"""Properties of the action paths, of extreme-noise systems and of the AEC turn order.

- Action paths: the single env and the native numpy vector env (member by member) accept
  exactly what the action space's own ``contains`` accepts (``Discrete``: a Python int, True
  included, or a numpy integer scalar or 0-d array of a dtype that casts safely to int64, never
  a float, a ``np.bool_`` or a shape-(1,) array; ``MultiBinary``: 0/1 of any dtype); everything
  else is a ``ValueError`` naming the player, and the env stays usable.
- Extreme noise: a tracking system scaled by any factor in [1e-150, 1e150] has the scaled
  steady state; the detection game on the tracking scenario steps with finite rewards at every
  power up to 1e300, and OBDD's threshold is finite for every strong attack;
  water-filling spends exactly the power asked at every power in [1e-300, 1e300].
- AEC turn order: whatever mix of valid and invalid actions is sent, an invalid one is refused
  on its own turn without moving the selection, valid ones alternate attacker, defender, and
  the rewards equal the parallel env's for the same valid actions.
"""

from __future__ import annotations

import importlib
import math

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st
from prop_support import bounded, prop_settings

import fdia_env  # noqa: F401 - registers the ids
from baselines.covariance import det_optimal, kkt_residuals
from fdia_env.kalman import steady_state
from fdia_env.systems import tracking_system

pytestmark = pytest.mark.filterwarnings("ignore")

DTYPES = ["int8", "uint8", "int32", "int64", "float32", "float64", "bool"]


@st.composite
def discrete_candidates(draw, n: int):
    """Integers, numpy scalars of every dtype, 0-d and shape-(1,) arrays, floats, bools."""
    value = draw(st.integers(-2, n + 1))
    kind = draw(st.sampled_from(["int", "float", "bool", "np_scalar", "array0", "array1"]))
    if kind == "int":
        return value
    if kind == "float":
        return float(value)
    if kind == "bool":
        return bool(value % 2)
    dtype = draw(st.sampled_from(DTYPES))
    with np.errstate(over="ignore"):
        if kind == "np_scalar":
            return np.array(value).astype(dtype)[()]
        arr = np.array(value).astype(dtype)
    return arr if kind == "array0" else arr.reshape(1)


@st.composite
def multibinary_candidates(draw, m: int):
    """Length-m arrays (sometimes m ± 1) of 0/1 or other values in every dtype."""
    size = draw(st.sampled_from([m, m, m, m - 1, m + 1]))
    values = draw(st.lists(st.sampled_from([0, 1, 1, 0, 2, -1, 0.5]), min_size=size, max_size=size))
    dtype = draw(st.sampled_from(DTYPES))
    with np.errstate(over="ignore", invalid="ignore"):
        return np.array(values).astype(dtype)


def _accepts(step, action) -> bool:
    """True if ``step(action)`` steps; False for a ``ValueError`` naming the attacker."""
    try:
        with bounded():
            step(action)
    except ValueError as exc:
        assert "attacker" in str(exc), exc
        return False
    return True


@prop_settings(60)
@given(action=discrete_candidates(8))
def test_discrete_actions_are_accepted_exactly_as_the_space_contains_them(action):
    env = gym.make("fdia_env/SparseAttack-v0")
    env.reset(seed=0)
    expected = env.action_space.contains(action)  # Gymnasium's rule: True is action 1
    assert _accepts(env.step, action) == expected, (action, type(action))
    env.step(0)  # still usable
    venv = gym.make_vec(
        "fdia_env/SparseAttack-v0", num_envs=2, vectorization_mode="vector_entry_point"
    )
    venv.reset(seed=0)
    batch = np.stack([np.asarray(action)] * 2)  # (2,) or (2, 1)
    member_ok = env.action_space.contains(batch[0])  # each member by the same rule
    assert _accepts(venv.step, batch) == member_ok, (action, batch.dtype, batch.shape)


@prop_settings(60)
@given(action=multibinary_candidates(3))
def test_multibinary_actions_are_accepted_exactly_as_the_space_contains_them(action):
    env = gym.make("fdia_env/SparseAttack-v0", action="multibinary")
    env.reset(seed=0)
    expected = env.action_space.contains(action)
    assert _accepts(env.step, action) == expected, (action, action.dtype)
    venv = gym.make_vec(
        "fdia_env/SparseAttack-v0",
        num_envs=2,
        vectorization_mode="vector_entry_point",
        action="multibinary",
    )
    venv.reset(seed=0)
    assert _accepts(venv.step, np.stack([action, action])) == expected, (action, action.dtype)


@prop_settings(40)
@given(
    log_c=st.floats(-150.0, 150.0),
    sigma_v=st.floats(0.05, 5.0),
    sigma_w=st.lists(st.floats(0.5, 20.0), min_size=1, max_size=3),
)
def test_a_scaled_tracking_system_has_the_scaled_steady_state(log_c, sigma_v, sigma_w):
    c = 10.0**log_c
    with bounded():
        ref = steady_state(tracking_system(sigma_v, sigma_w))
        scaled = steady_state(tracking_system(sigma_v * c, [s * c for s in sigma_w]))
    for got, want in zip(scaled[:2], ref[:2], strict=True):
        np.testing.assert_allclose(got / c**2, want, rtol=1e-9)
    np.testing.assert_allclose(scaled[2], ref[2], rtol=1e-9)


@prop_settings(15)
@given(log_power=st.floats(-2.0, 300.0), statistic=st.sampled_from(["chi2", "quadratic"]))
def test_detection_game_on_tracking_steps_at_every_power(log_power, statistic):
    from baselines.detection import obdd, tracking_problem
    from fdia_env import detection_game_v0

    power = 10.0**log_power
    env = detection_game_v0.parallel_env(scenario="ch3-tracking", power=power, statistic=statistic)
    with bounded():
        env.reset(seed=0)
        attack = detection_game_v0.default_opponent(env, "defender").predict(None)[0]
        _, rewards, *_ = env.step({"attacker": attack, "defender": np.zeros(1, np.float32)})
        threshold = obdd(tracking_problem("ch3-tracking", power=power)).threshold
    assert math.isfinite(rewards["attacker"]) and rewards["attacker"] >= 0.0
    assert not math.isnan(threshold)  # +inf (never detect) is the documented weak-attack case
    if log_power >= 12.0:  # a strong attack is worth detecting: a finite threshold
        assert math.isfinite(threshold)


@prop_settings(40)
@given(
    log_power=st.floats(-300.0, 300.0),
    scenario=st.sampled_from(["ch2-position", "ch2-pv-1", "ch2-pv-2"]),
)
def test_water_filling_spends_the_power_asked_at_every_power(log_power, scenario):
    power = 10.0**log_power
    with bounded():
        result = det_optimal(scenario, power=power)
    assert result.info["s"].sum() == pytest.approx(power, rel=1e-12)
    assert math.isfinite(result.value)
    if scenario != "ch2-position":  # two position sensors: W has rank one (see below)
        assert kkt_residuals(result).worst < 1e-9


def test_kkt_residuals_of_a_rank_one_gain_stay_finite_at_huge_power():
    # kkt_residuals raised LinAlgError (P + W Σ W' singular in float64) from ~1e58 on; the
    # residual itself loses accuracy above ~1e10 when W has rank one (ch2-position)
    result = det_optimal("ch2-position", power=10.0**58.125)
    assert math.isfinite(kkt_residuals(result).worst)


# --- AEC turn order ------------------------------------------------------------------------

AEC = {
    "sensor_game_v0": {"rounds": 4},
    "detection_game_v0": {"horizon": 4},
}


@st.composite
def turn_scripts(draw):
    """A list of (valid?, index) moves; invalid moves are outside the space."""
    return draw(st.lists(st.tuples(st.booleans(), st.integers(0, 10**6)), min_size=1, max_size=14))


def _valid(space: gym.Space, index: int):
    if isinstance(space, gym.spaces.Discrete):
        return int(space.start + index % space.n)
    rng = np.random.default_rng(index)
    return rng.uniform(space.low, space.high).astype(space.dtype)


def _invalid(space: gym.Space, index: int):
    bad = [-1, None, "a", [0, 0, 0], np.full(7, 0.5), 1.5 + 2j]
    if isinstance(space, gym.spaces.Box):
        bad.append(np.full(space.shape, 9.0, dtype=space.dtype))
    return bad[index % len(bad)]


@pytest.mark.parametrize("name", sorted(AEC))
@prop_settings(12)
@given(script=turn_scripts())
def test_aec_turn_order_survives_any_mix_of_valid_and_invalid_actions(name, script):
    module = importlib.import_module(f"fdia_env.{name}")
    aec = module.env(**AEC[name])
    par = module.parallel_env(**AEC[name])
    aec.reset(seed=3)
    par.reset(seed=3)
    round_actions: dict = {}
    for valid, index in script:
        while aec.agents and (
            aec.terminations[aec.agent_selection] or aec.truncations[aec.agent_selection]
        ):
            aec.step(None)  # the AEC protocol: done agents step with None
        if not aec.agents:
            break
        agent = aec.agent_selection
        assert agent == ("attacker" if not round_actions else "defender")
        space = aec.action_space(agent)
        if not valid:
            with pytest.raises((ValueError, TypeError), match=agent):
                aec.step(_invalid(space, index))
            assert aec.agent_selection == agent  # refused on its own turn, nothing moved
            continue
        action = _valid(space, index)
        aec.step(action)
        round_actions[agent] = action
        if len(round_actions) == 2:  # the round completed: the parallel env gets the same
            _, rewards, *_ = par.step(round_actions)
            assert aec.rewards == pytest.approx(rewards)
            round_actions = {}
    agent = aec.agent_selection
    if aec.agents and not (aec.terminations[agent] or aec.truncations[agent]):
        aec.step(_valid(aec.action_space(agent), 0))  # never stuck: a valid action is accepted
