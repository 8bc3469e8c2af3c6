"""Systems at any accepted scale: exact, finite, and refused by name beyond float64's reach.

The Kalman recursion is scale-equivariant: scaling Q, R and P0 by s scales every covariance by
s, so the envs' traces scale by s, their log-determinants shift by n·log s, and observations
(log-variance ratios, correlations, normalised innovations, budgets) do not change. The
answer at scale s is therefore the answer at s = 1, rescaled: the oracle here, on every face
(the single env, the native vector env on numpy and on torch) of the sparse attack envs (v0, v1
and v2 in their sequential formats), the covariance attack and the detection game, for a
2-state system (the closed-form kernels) and a 3-state one (the generic batched algebra).

At 1e±200 the 2-state kernels divided by an underflowed ``a d − b²`` (``ZeroDivisionError``) or
overflowed it (NaN traces, −inf log-determinants), and the correlation feature ``b / sqrt(a d)``
read 0 (a sum of a huge bias covariance too: the detection game at power 1e300). The scales
beyond float64's reach are refused when the system is built (tests/test_system_validation.py).
"""

from __future__ import annotations

import functools
import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import fdia_env  # noqa: F401 - registers the ids
from fdia_env import (
    covariance_attack_v0,
    detection_game_v0,
    sparse_attack_v0,
    sparse_attack_v1,
    sparse_attack_v2,
)
from fdia_env.systems import LinearSystem, Sensor, tracking_system

torch = pytest.importorskip("torch")

pytestmark = pytest.mark.filterwarnings("ignore")


def two_state(s: float) -> LinearSystem:
    """The red team's system: Q, R and P0 scaled by ``s``."""
    return LinearSystem(
        F=np.array([[-0.22, -0.09], [-0.46, -0.36]]),
        Q=np.array([[1.7, -0.8], [-0.8, 0.8]]) * s,
        sensors=(
            Sensor(H=np.array([[0.4, -0.4]]), R=np.array([[1.9 * s]])),
            Sensor(H=np.array([[0.26, -1.41]]), R=np.array([[0.28 * s]])),
        ),
        P0=np.eye(2) * s,
    )


def three_state(s: float) -> LinearSystem:
    """A 3-state system (the engine's generic algebra), a 2-row sensor among its three."""
    return LinearSystem(
        F=np.array([[0.5, 0.2, 0.0], [-0.1, 0.4, 0.3], [0.2, 0.0, -0.6]]),
        Q=np.array([[1.0, 0.2, 0.1], [0.2, 0.8, -0.3], [0.1, -0.3, 1.5]]) * s,
        sensors=(
            Sensor(H=np.array([[1.0, 0.0, 0.5]]), R=np.array([[0.7 * s]])),
            Sensor(
                H=np.array([[0.0, 1.0, -1.0], [0.3, 0.2, 1.0]]),
                R=np.array([[0.5, 0.1], [0.1, 0.9]]) * s,
            ),
            Sensor(H=np.array([[0.2, -0.6, 1.1]]), R=np.array([[1.3 * s]])),
        ),
        P0=np.diag([1.0, 2.0, 0.5]) * s,
    )


SYSTEMS = {"2-state": two_state, "3-state": three_state}

# The accepted scales of these systems: their largest covariance entry (1.9 s, 1.5 s) and their
# largest information entry (1.41² / 0.28 / s, ...) at most MAX_COVARIANCE = 1e304. Envs whose
# attack power scales with s stop where the power reaches its own limit, 1e300.
LOWEST, HIGHEST, POWER_HIGHEST = -303.0, 303.0, 300.0

# name -> (module, gym id of the native vector env, env kwargs at scale s, power scales with s,
#          whose reward (+1: pays Φ, -1: pays -Φ; the vector env's player first), sampled).
# Rewards are Φ of every window step ("per_step"), except in the sequential formats, whose stop
# may play several window steps (and pay their sum): there Φ of the last one ("terminal").
CASES = {
    "sparse_v0": (
        sparse_attack_v0,
        "fdia_env/SparseAttack-v0",
        lambda s: {"budget": 3, "horizon": 4},
        False,
        1,
        False,
    ),
    "sparse_v1_sequential": (
        sparse_attack_v1,
        "fdia_env/SparseAttack-v1",
        lambda s: {"budget": 3, "horizon": 4, "action": "sequential", "reward_mode": "terminal"},
        False,
        1,
        False,
    ),
    "sparse_v2_sequential": (
        sparse_attack_v2,
        "fdia_env/SparseAttack-v2",
        lambda s: {"budget": 3, "horizon": 4, "action": "sequential", "reward_mode": "terminal"},
        False,
        1,
        False,
    ),
    "sparse_v0_sampled": (
        sparse_attack_v0,
        "fdia_env/SparseAttack-v0",
        lambda s: {"budget": 3, "horizon": 4, "dynamics": "sampled"},
        False,
        1,
        True,
    ),
    "covariance": (
        covariance_attack_v0,
        "fdia_env/CovarianceAttack-v0",
        lambda s: {"power": 0.5 * s, "horizon": 3},
        True,
        1,
        False,
    ),
    "covariance_budget": (
        covariance_attack_v0,
        "fdia_env/CovarianceAttack-v0",
        lambda s: {"power": 0.5 * s, "horizon": 3, "power_mode": "budget"},
        True,
        1,
        False,
    ),
    "detection": (
        detection_game_v0,
        "fdia_env/DetectionDefender-v0",
        lambda s: {"power": 0.5 * s},
        True,
        -1,
        False,
    ),
    "detection_sampled": (
        detection_game_v0,
        "fdia_env/DetectionDefender-v0",
        lambda s: {"power": 0.5 * s, "horizon": 3, "dynamics": "sampled"},
        True,
        -1,
        True,
    ),
}
OBJECTIVES = {"sampled": ["trace"], "expected": ["trace", "logdet"]}


def _action(space: gym.Space, k: int, member: int = 0):
    """Step ``k``'s action of ``member``: drawn from a generator of (k, member), so every scale
    plays the same ones (the sparse formats stop or attack nothing every third step)."""
    rng = np.random.default_rng(100 * k + member)
    if isinstance(space, gym.spaces.Discrete):
        return int(rng.integers(space.n)) if k % 3 != 2 else 0
    return rng.uniform(space.low, space.high).astype(space.dtype)


def _flat(obs) -> np.ndarray:
    """An observation (a Box, a Dict with its mask, a tensor) as float64, without masks."""
    if isinstance(obs, dict):
        return np.concatenate([_flat(v) for k, v in sorted(obs.items()) if k != "action_mask"])
    if isinstance(obs, torch.Tensor):
        obs = obs.numpy()
    return np.asarray(obs, dtype=np.float64).ravel()


def _assert_finite(infos, where: str) -> None:
    """Every float of ``infos`` finite (the detector's threshold may be +inf: never detect)."""
    if isinstance(infos, dict):
        for key, value in infos.items():
            if key != "threshold":
                _assert_finite(value, f"{where}[{key!r}]")
        return
    if isinstance(infos, torch.Tensor):
        infos = infos.numpy()
    arr = np.asarray(infos)
    if arr.dtype.kind == "f":
        assert np.isfinite(arr).all(), f"{where} = {infos!r}"


def _run(case: str, system: str, s: float, objective: str, face: str):
    """(rewards, observations) of a fixed action sequence at scale ``s`` on ``face``.

    Rewards: (steps, agents) for the single env (agents sorted), (steps, 3 members) for the
    native vector envs; infos are checked finite on the way.
    """
    module, gym_id, kwargs, _, _, _ = CASES[case]
    kw = {"scenario": SYSTEMS[system](s), "objective": objective, "reward_mode": "per_step"}
    kw.update(kwargs(s))
    rewards, observations = [], []
    if face == "single":
        env = module.parallel_env(**kw)
        obs, infos = env.reset(seed=0)
        observations.append(_flat(obs))
        for k in range(12):
            actions = {a: _action(env.action_space(a), k) for a in env.agents}
            obs, rew, _, _, infos = env.step(actions)
            _assert_finite(infos, f"step {k} infos")
            rewards.append([rew[a] for a in sorted(rew)])
            observations.append(_flat(obs))
            if not env.agents:
                break
        return np.array(rewards, dtype=np.float64), observations
    env = gym.make_vec(
        gym_id, num_envs=3, vectorization_mode="vector_entry_point", backend=face, **kw
    )
    obs, _ = env.reset(seed=0)
    observations.append(_flat(obs))
    space = env.single_action_space
    for k in range(5):  # past the horizon: the members' autoreset steps too
        batch = np.stack([np.asarray(_action(space, k, j)) for j in range(3)])
        obs, rew, _, _, infos = env.step(torch.as_tensor(batch) if face == "torch" else batch)
        _assert_finite(infos, f"step {k} infos")
        rewards.append(_flat(rew))
        observations.append(_flat(obs))
    return np.array(rewards), observations


@functools.cache
def _reference(case: str, system: str, objective: str, face: str):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return _run(case, system, 1.0, objective, face)


def _check_scaled(case: str, system: str, exponent: float, objective: str, face: str) -> None:
    """The rewards at s = 10**exponent are those at s = 1 rescaled; observations unchanged."""
    _, _, _, _, sign, sampled = CASES[case]
    s = 10.0**exponent
    want_rewards, want_obs = _reference(case, system, objective, face)
    rewards, observations = _run(case, system, s, objective, face)
    assert np.isfinite(rewards).all(), rewards
    # sampled dynamics: an innovation (the difference of two nearly equal terms) carries the
    # rounding of its terms relative to itself, ~1e-9 here
    rtol = 1e-6 if sampled else 1e-9
    if objective == "trace":
        np.testing.assert_allclose(rewards, want_rewards * s, rtol=rtol, atol=0.0)
    else:
        n = SYSTEMS[system](1.0).n
        shift = np.where(want_rewards == 0.0, 0.0, n * math.log(s))  # 0: nothing paid
        if face == "single" and case.startswith("detection"):
            shift = shift * np.array([1.0, -1.0])  # attacker, defender
        else:
            shift = sign * shift
        np.testing.assert_allclose(
            rewards, want_rewards + shift, rtol=0.0, atol=1e-9 * (1 + n * abs(math.log(s)))
        )
    assert len(observations) == len(want_obs)
    for got, want in zip(observations, want_obs, strict=True):
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)


EXPONENTS = st.floats(LOWEST, HIGHEST)


@pytest.mark.parametrize("face", ["single", "numpy", "torch"])
@pytest.mark.parametrize("case", list(CASES))
@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(exponent=EXPONENTS, data=st.data())
@example(exponent=-300.0, data=None).via("the red team's 1e-300")
@example(exponent=300.0, data=None).via("the red team's 1e300")
def test_every_face_is_scale_equivariant_at_every_accepted_scale(case, face, exponent, data):
    """Trace ×s, log det + n log s, the same observations, finite infos: at 1e-303..1e303."""
    _, _, _, power_scaled, _, sampled = CASES[case]
    if power_scaled:
        exponent = min(exponent, POWER_HIGHEST)
    objectives = OBJECTIVES["sampled" if sampled else "expected"]
    system = data.draw(st.sampled_from(list(SYSTEMS)), label="system") if data else "2-state"
    objective = data.draw(st.sampled_from(objectives), label="objective") if data else "trace"
    _check_scaled(case, system, exponent, objective, face)


@pytest.mark.parametrize("system", list(SYSTEMS))
@pytest.mark.parametrize("exponent", [LOWEST, -200.0, 200.0, HIGHEST])
def test_the_ends_of_the_accepted_range_in_every_env_and_objective(system, exponent):
    """The single env at the extremes, both objectives, 2 and 3 states (the first defects)."""
    for case, (_, _, _, power_scaled, _, sampled) in CASES.items():
        e = min(exponent, POWER_HIGHEST) if power_scaled else exponent
        for objective in OBJECTIVES["sampled" if sampled else "expected"]:
            _check_scaled(case, system, e, objective, "single")


# the kernel's steps, a leak (the engine's step), a steady restart and the kernel's again
STEPS = [(3, None, False), (1, None, False), (2, 0.5, False), (3, None, False), (1, None, True)]


@settings(max_examples=10, deadline=None)
@given(
    exponent=st.floats(LOWEST, HIGHEST),
    objective=st.sampled_from(["trace", "logdet"]),
    steps=st.lists(
        st.tuples(st.integers(0, 3), st.sampled_from([None, 0.5, 3e4]), st.booleans()),
        min_size=1,
        max_size=6,
    ),
)
@example(exponent=-300.0, objective="logdet", steps=STEPS)
@example(exponent=300.0, objective="trace", steps=STEPS)
def test_the_float_kernel_equals_the_engine_bit_for_bit_at_any_scale(exponent, objective, steps):
    """The single env's float kernel and the engine step: one sequence of IEEE operations, also
    where the closed forms run on power-of-two-scaled components (leaks and steady restarts
    hand the state over and back)."""
    from fdia_env.defenses.base import FilterInput
    from fdia_env.envs.simulation import Simulation

    s = 10.0**exponent
    system = two_state(s)
    _, spec = sparse_attack_v0.episode_spec(system, horizon=len(steps), objective=objective)
    fast, engine = Simulation(system, spec), Simulation(system, spec, fast=False)
    for sim in (fast, engine):
        sim.reset(np.random.default_rng(0))
    assert fast.features() == engine.features()
    for used, power, steady in steps:
        leak = None if power is None else power * s * np.eye(system.nz)
        fi = FilterInput(used=used, leaked_sigma=leak, steady=steady and used != 0)
        a, b = fast.step(fi), engine.step(fi)
        assert a == b and math.isfinite(a), (a, b)
        np.testing.assert_array_equal(fast.P, engine.P)
        np.testing.assert_array_equal(fast.M, engine.M)
        assert fast.features() == engine.features()
        assert all(math.isfinite(v) for v in fast.features())


@pytest.mark.parametrize("exponent", [-300.0, -200.0, 200.0, 300.0])
def test_a_native_numpy_member_equals_its_single_env_bit_for_bit_at_extreme_scales(exponent):
    """Member 0 of the numpy vector env plays the single env's actions: the same bits (the
    history table's nodes, the closed forms' scaled branch and the float kernel agree)."""
    s = 10.0**exponent
    kw = {"scenario": two_state(s), "budget": 3, "horizon": 4, "reward_mode": "per_step"}
    for objective in ("trace", "logdet"):
        single = sparse_attack_v0.parallel_env(objective=objective, **kw)
        single.reset(seed=0)
        venv = gym.make_vec(
            "fdia_env/SparseAttack-v0",
            num_envs=2,
            vectorization_mode="vector_entry_point",
            objective=objective,
            **kw,
        )
        venv.reset(seed=0)
        for k in range(4):
            a = _action(single.action_space("attacker"), k)
            obs, rew, *_ = single.step({"attacker": a})
            v_obs, v_rew, *_ = venv.step(np.array([a, 1]))
            assert v_rew[0] == rew["attacker"]
            np.testing.assert_array_equal(v_obs[0], obs["attacker"]["observation"])


@pytest.mark.parametrize(
    ("sigma_v", "sigma_w"), [(1e-150, [3.0]), (1e-150, [1e-150]), (1e150, [1e150, 1e150])]
)
def test_tracking_models_at_extreme_noise_step_with_finite_rewards(sigma_v, sigma_w):
    """σ_v = 1e-150 (the detection guide's extreme index: Q of 1e-300 next to R = 9) and the
    tracking model scaled to variances of 1e±300 (a ZeroDivisionError and NaN traces before)."""
    system = tracking_system(sigma_v, sigma_w)
    for module, kw in ((sparse_attack_v0, {"budget": 1}), (detection_game_v0, {})):
        for objective in ("trace", "logdet"):
            env = module.parallel_env(scenario=system, objective=objective, horizon=1, **kw)
            obs, _ = env.reset(seed=0)
            actions = {a: env.action_space(a).sample() for a in env.agents}
            obs, rewards, _, _, _ = env.step(actions)
            assert all(math.isfinite(r) for r in rewards.values()), rewards
            assert all(np.isfinite(_flat(o)).all() for o in obs.values()), obs


@pytest.mark.parametrize("face", ["single", "numpy", "torch"])
def test_the_detection_game_correlation_of_a_huge_bias_is_its_rank_one_limit(face):
    """A bias covariance of 1e300 that the filter incorporates: M is rank one to float64, its
    correlation feature ±1 as at 1e200 (it read 0: the product of the variances overflowed)."""
    got = {}
    for power in (1e200, 1e300):
        kw = {"scenario": "ch3-tracking", "power": power, "on_detect": "incorporate"}
        if face == "single":
            env = detection_game_v0.parallel_env(**kw)
            env.reset(seed=0)
            attack = np.full(env.action_space("attacker").shape, 0.7, np.float32)
            obs = env.step({"attacker": attack, "defender": np.zeros(1, np.float32)})[0]
            got[power] = obs["defender"]
        else:
            env = gym.make_vec(
                "fdia_env/DetectionDefender-v0",
                num_envs=2,
                vectorization_mode="vector_entry_point",
                backend=face,
                **kw,
            )
            env.reset(seed=0)
            batch = np.zeros((2, 1), np.float32)
            obs = env.step(torch.as_tensor(batch) if face == "torch" else batch)[0]
            got[power] = _flat(obs).reshape(2, -1)[0]
    corr = got[1e300][-1]
    assert abs(corr) == 1.0, got
    np.testing.assert_array_equal(got[1e300], got[1e200])
