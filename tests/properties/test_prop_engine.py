"""Property: one engine behind every face.

Random configurations of every Kalman-filter env (every scenario family incl. a grid preset, both
dynamics, every action format incl. the sparse attacker's sequential, masked format of
``sparse_attack_v1``/``v2`` in each order (the plan-first ones with and without the state groups),
the typed (incomplete-information) sensor game, the sensor game's sequential, masked format (both
players, ``max_subset_size``, a subset-format opponent asked once per round), every attack × defense
pair of ``fdia_v0``, random (masked) actions, batch sizes and seeds): the single env (through
Gymnasium's ``SyncVectorEnv``), the native vector env on numpy and on torch (CPU) give the same
observations, rewards, terminations, truncations and infos. numpy equals the single env bit for bit
in every case: the single env is the engine's batch of one, the 2-state kernels (the single env's
floats, the history table, the closed form on component arrays) are one sequence of IEEE operations
with numpy's logarithm, and every product a member goes through is computed member by member (a (B,
w) @ (w, n) BLAS product rounds a row differently at B = 1, a three-operand einsum too). torch
equals numpy to 1e-10 in expected dynamics and in distribution in sampled dynamics (its own device
generator; the typed sensor game's types too, so member by member only under a degenerate prior).

Not covered here, and to round-off only (docs/benchmarks.md says why): systems of n >= 40 states
from the steady state on numpy (their low-rank form pads each member to the batch's widest rank
and leaves the form when the widest member exceeds its cap), and information sums whose (M, n²)
matrix exceeds ``fdia_env.envs.engine.MEMBER_PRODUCT_SIZE`` (one BLAS product for the batch).

Without a native vector env (checked against ``SyncVectorEnv`` only, whose members equal single
envs seeded ``seed + i``): the system-family env. The stealth envs' defender views have none
either (see tests/test_stealth*.py).
"""

from __future__ import annotations

import math
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import AutoresetMode, SyncVectorEnv
from hypothesis import given, settings
from hypothesis import strategies as st

from fdia_env.envs.opponents import FixedMix
from fdia_env.envs.single_agent import make_single_agent
from fdia_env.vector.env import make_vector

pytestmark = pytest.mark.filterwarnings("ignore")

SMALL = ["ch4-position", "ch2-pv-2", "ch3-tracking", "ch4-pv-case1"]
GRID = "grid-ieee14"


def _sparse(draw, window):
    scenario = draw(st.sampled_from([*SMALL, GRID]))
    formats = ["auto", "multibinary", "single"] + (["bitmask"] if scenario != GRID else [])
    return (
        "fdia_env.sparse_attack_v0",
        "attacker",
        {
            "scenario": scenario,
            "action": draw(st.sampled_from(formats)),
            "budget": draw(st.integers(0, window)),
            "objective": draw(st.sampled_from(["trace", "logdet"])),
            "horizon": window,
        },
    )


def _sequential(draw, window):
    # the sparse attacker's sequential, masked format (its own native vector env), in each of
    # its orders, on v1 and v2 (v2: the same env with order="plan" by default); the plan-first
    # orders with or without the state groups
    scenario = draw(st.sampled_from([*SMALL, GRID]))
    order = draw(st.sampled_from(["time", "plan", "increasing"]))
    groups = None if order == "time" else draw(st.sampled_from([None, "state"]))
    return (
        draw(st.sampled_from(["fdia_env.sparse_attack_v1", "fdia_env.sparse_attack_v2"])),
        "attacker",
        {
            "scenario": scenario,
            "action": "sequential",
            "order": order,
            "groups": groups,
            "budget": draw(st.integers(1, window)),
            "objective": draw(st.sampled_from(["trace", "logdet"])),
            "horizon": window,
        },
    )


def _covariance(draw, window):
    return (
        "fdia_env.covariance_attack_v0",
        "attacker",
        {
            "scenario": draw(st.sampled_from(["ch4-position", "ch2-pv-2", "ch4-pv-case1"])),
            "power": draw(st.sampled_from([1.0, 25.0, 1e6])),
            "power_mode": draw(st.sampled_from(["per_step", "budget"])),
            "structure": draw(st.sampled_from(["full", "diagonal"])),
            "objective": draw(st.sampled_from(["trace", "logdet"])),
            "horizon": window,
        },
    )


def _sensor_game(draw, window):
    kwargs = {
        "scenario": draw(st.sampled_from(["ch4-position", "ch5-game"])),
        "power": draw(st.sampled_from([1.0, 25.0])),
        "rounds": window,
    }
    if draw(st.booleans()):
        kwargs["allocation"] = draw(st.sampled_from(["independent", "dependent"]))
    else:  # incomplete information: nature draws the attacker's type (torch: from its own
        # generator, so member by member against numpy only under a degenerate prior)
        kwargs["types"] = ("independent", "dependent")
        kwargs["priors"] = draw(st.sampled_from([(0.5, 0.5), (1.0, 0.0), (0.0, 1.0)]))
    return "fdia_env.sensor_game_v0", draw(st.sampled_from(["attacker", "defender"])), kwargs


def _sensor_game_sequential(draw, window):
    # the sensor game's sequential, masked format: one sensor per decision, both players
    module, agent, kwargs = _sensor_game(draw, window)
    kwargs["action"] = "sequential"
    kwargs["max_subset_size"] = draw(st.sampled_from([None, 1, 2]))
    kwargs["illegal_action"] = draw(st.sampled_from(["trim", "noop"]))
    return module, agent, kwargs


def _detection_game(draw, window):
    scenario = draw(st.sampled_from(["ch3-tracking", "ch3-static", "ch2-pv-2"]))
    return (
        "fdia_env.detection_game_v0",
        draw(st.sampled_from(["attacker", "defender"])),
        {
            "scenario": scenario,
            "power": draw(st.sampled_from([1.0, 25.0])),
            "statistic": draw(st.sampled_from(["quadratic", "chi2"])),
            "on_detect": draw(st.sampled_from(["discard", "incorporate"])),
            "criterion": draw(st.sampled_from(["mse", "bayes_cost"])),
            "horizon": window,
        },
    )


def _composed(draw, window):
    attack = draw(st.sampled_from(["sparse", "covariance", "subset", "probabilistic"]))
    defense = draw(st.sampled_from(["perfect_detection", "unaware", "sensor_selection"]))
    if attack == "sparse":
        attack_kwargs = {"budget": draw(st.integers(0, window))}
    else:
        attack_kwargs = {"power": draw(st.sampled_from([1.0, 25.0]))}
    # the subset models need scalar sensors; a learning defender needs a discrete opponent
    scalar = attack == "subset" or defense == "sensor_selection"
    players = ["attacker"]
    if defense == "sensor_selection" and attack in ("sparse", "subset"):
        players.append("defender")
    scenarios = ["ch4-position"] if scalar else ["ch4-position", "ch2-pv-2"]
    return (
        "fdia_env.fdia_v0",
        draw(st.sampled_from(players)),
        {
            "scenario": draw(st.sampled_from(scenarios)),
            "attack": attack,
            "defense": defense,
            "attack_kwargs": attack_kwargs,
            "horizon": window,
        },
    )


FAMILIES = {
    "sparse": _sparse,
    "covariance": _covariance,
    "sensor_game": _sensor_game,
    "sensor_game_sequential": _sensor_game_sequential,
    "sequential": _sequential,
    "detection_game": _detection_game,
    "fdia": _composed,
}


@st.composite
def configs(draw, family: str):
    """(module, agent, kwargs, B, seed, pure opponent) of one random env of ``family``."""
    window = draw(st.integers(1, 4))
    module, agent, kwargs = FAMILIES[family](draw, window)
    kwargs["dynamics"] = draw(st.sampled_from(["expected", "sampled"]))
    if kwargs["dynamics"] == "sampled" and "objective" in kwargs:
        kwargs["objective"] = "trace"  # a sampled error has no log-determinant
    kwargs["reward_mode"] = draw(st.sampled_from(["terminal", "shaped", "per_step"]))
    if not family.startswith("sensor_game") and kwargs["scenario"] != GRID:
        static = kwargs["scenario"] == "ch3-static"  # no steady state: F = I, Q = 0
        kwargs["warmup"] = draw(st.sampled_from([None, 0, 2] + ([] if static else ["steady"])))
    if family == "detection_game" and kwargs["dynamics"] == "expected":
        if kwargs["scenario"] != "ch3-static":  # a moving state: one step keeps it Gaussian
            kwargs["horizon"] = 1
    grid = kwargs["scenario"] == GRID  # 34 sensors: two members at most, a short window
    if grid:
        kwargs["horizon"] = min(kwargs["horizon"], 2)
    return (
        module,
        agent,
        kwargs,
        draw(st.integers(1, 2 if grid else 3)),
        draw(st.integers(0, 2**16)),
    )


def _opponent(module, agent, kwargs, pure):
    """A fixed opponent for a two-player env: a pure action (deterministic) or the uniform mix.

    Each call gives a new policy (each single env draws from its own).
    """
    parallel = __import__(module, fromlist=["parallel_env"]).parallel_env(**kwargs)
    others = [a for a in parallel.possible_agents if a != agent]
    if not others or not isinstance(parallel.action_space(others[0]), gym.spaces.Discrete):
        return None  # none, or the module's default (a fixed action)
    n = int(parallel.action_space(others[0]).n)
    if hasattr(parallel, "models"):  # the sequential sensor game: a policy over the subsets
        n = len(parallel.models[others[0]].subsets)
    if not pure:
        return FixedMix.uniform(n)
    probs = np.zeros(n)
    probs[(n - 1) // 2] = 1.0
    return FixedMix(probs)


def _actions(space, rng, B, mask):
    if isinstance(space, gym.spaces.Discrete):
        if mask is None:
            return rng.integers(space.n, size=B)
        return np.array([rng.choice(np.flatnonzero(m)) for m in mask])
    if isinstance(space, gym.spaces.MultiBinary):
        return rng.integers(0, 2, size=(B, *space.shape)).astype(space.dtype)
    return rng.uniform(-1, 1, size=(B, *space.shape)).astype(np.float32)


def assert_same_infos(native, sync, where, exact):
    """Vector infos equal key by key: values (bit for bit when ``exact``), dtypes, masks."""
    assert sorted(native) == sorted(sync), f"{where}: keys {sorted(native)} != {sorted(sync)}"
    for key in sync:
        n, s = native[key], sync[key]
        if isinstance(s, dict):
            assert_same_infos(n, s, f"{where}/{key}", exact)
            continue
        if s.dtype == object:  # final_obs / final_info: None or the member's value
            for a, b in zip(n, s, strict=True):
                assert (a is None) == (b is None), f"{where}/{key}"
            continue
        assert n.dtype == s.dtype, f"{where}/{key}: dtype {n.dtype} != {s.dtype}"
        assert n.shape == s.shape, f"{where}/{key}: shape {n.shape} != {s.shape}"
        if exact or not np.issubdtype(s.dtype, np.floating):
            np.testing.assert_array_equal(n, s, err_msg=f"{where}/{key}")
        else:
            np.testing.assert_allclose(n, s, rtol=1e-9, atol=1e-9, err_msg=f"{where}/{key}")


def _engine(native):
    """The engine of a native vector env (the sequential format's wraps an FdiaVectorEnv)."""
    return getattr(native, "inner", native).sim


def _check_native_equals_single(module, agent, kwargs, B, seed, pure):
    # bit for bit, in the history table or out of it (see the module doc)
    opp = _opponent(module, agent, kwargs, pure)
    sync = SyncVectorEnv(
        [
            lambda: make_single_agent(
                module, agent, opponent=_opponent(module, agent, kwargs, pure), **kwargs
            )
            for _ in range(B)
        ],
        autoreset_mode=AutoresetMode.NEXT_STEP,
    )
    native = make_vector(module, B, agent=agent, opponent=opp, **kwargs)
    obs_s, info_s = sync.reset(seed=seed)
    obs_n, info_n = native.reset(seed=seed)
    if kwargs["dynamics"] == "expected" and _engine(native).system.n == 2:
        assert _engine(native).shares_histories, "a 2-state expected env starts in the table"
    np.testing.assert_array_equal(obs_n, obs_s)
    assert_same_infos(info_n, info_s, "reset", True)
    rng = np.random.default_rng(seed)
    window = kwargs.get("horizon", kwargs.get("rounds", 1))
    if kwargs.get("action") == "sequential":  # up to budget + 1 decisions per time step
        window *= kwargs["budget"] + 2 if "budget" in kwargs else native.M + 2
    trace = []
    for t in range(2 * window + 1):  # through an autoreset
        actions = _actions(sync.single_action_space, rng, B, info_s.get("action_mask"))
        out_s = sync.step(actions)
        out_n = native.step(actions)
        where = f"step {t}"
        for i in range(4):  # observations, rewards, terminations, truncations
            np.testing.assert_array_equal(out_n[i], out_s[i], err_msg=where)
        assert_same_infos(out_n[4], out_s[4], where, True)
        info_s = out_s[4]
        trace.append((actions, out_n))
    return opp, trace


def _check_torch_equals_numpy(module, agent, kwargs, B, seed, opp, trace):
    torch = pytest.importorskip("torch")
    on_torch = make_vector(module, B, agent=agent, opponent=opp, backend="torch", **kwargs)
    on_torch.reset(seed=seed)
    for t, (actions, out_n) in enumerate(trace):
        out_t = on_torch.step(torch.as_tensor(actions))
        where = f"torch step {t}"
        np.testing.assert_array_equal(out_t[2].numpy(), out_n[2], err_msg=where)
        np.testing.assert_array_equal(out_t[3].numpy(), out_n[3], err_msg=where)
        np.testing.assert_allclose(out_t[0].numpy(), out_n[0], rtol=1e-5, atol=1e-6, err_msg=where)
        np.testing.assert_allclose(
            out_t[1].numpy(), out_n[1], rtol=1e-10, atol=1e-10, err_msg=where
        )


def _torch_capable(module, kwargs):
    # a typed sensor game's types come from torch's generator: equal only when nature is sure
    return "types" not in kwargs or max(kwargs["priors"]) == 1.0


@pytest.mark.parametrize("family", sorted(FAMILIES))
@settings(max_examples=6, deadline=None)
@given(data=st.data())
def test_single_native_numpy_and_torch_are_one_engine(family, data):
    module, agent, kwargs, B, seed = data.draw(configs(family), label="config")
    pure = data.draw(st.booleans(), label="pure opponent")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        opp, trace = _check_native_equals_single(module, agent, kwargs, B, seed, pure)
        # torch draws from its own generator: member by member only where nothing is drawn
        deterministic = kwargs["dynamics"] == "expected" and (opp is None or pure)
        if deterministic and _torch_capable(module, kwargs):
            _check_torch_equals_numpy(module, agent, kwargs, B, seed, opp, trace)


# --- sampled dynamics on torch: equal to numpy in distribution ----------------------------------
DISTRIBUTION_CASES = {
    "sparse": ("fdia_env.sparse_attack_v0", {"scenario": "ch4-position", "budget": 2}),
    "covariance": ("fdia_env.covariance_attack_v0", {"scenario": "ch2-pv-2", "power": 25.0}),
    "detection": ("fdia_env.detection_game_v0", {"scenario": "ch3-static", "power": 25.0}),
}


@pytest.mark.parametrize("case", sorted(DISTRIBUTION_CASES))
def test_torch_sampled_dynamics_equal_numpy_in_distribution(case):
    # the same fixed action for every member over a 3-step window; the per-step mean reward of
    # B members on torch lies within 5 standard errors of numpy's (both are unbiased estimates)
    torch = pytest.importorskip("torch")
    module, kwargs = DISTRIBUTION_CASES[case]
    kwargs = {**kwargs, "dynamics": "sampled", "reward_mode": "per_step", "horizon": 3}
    B = 2000
    envs = {
        backend: make_vector(module, B, backend=backend, **kwargs) for backend in ("numpy", "torch")
    }
    space = envs["numpy"].single_action_space
    action = space.n - 1 if isinstance(space, gym.spaces.Discrete) else np.full(space.shape, 0.5)
    rewards = {}
    for backend, env in envs.items():
        env.reset(seed=3)
        batch = np.repeat(np.asarray(action)[None], B, axis=0)
        if backend == "torch":
            batch = torch.as_tensor(batch)
        rewards[backend] = [np.asarray(env.step(batch)[1], dtype=float) for _ in range(3)]
    for t in range(3):
        a, b = rewards["numpy"][t], rewards["torch"][t]
        se = np.sqrt(a.var() / B + b.var() / B)
        assert se > 0, f"{case} step {t}: no spread in the sampled rewards"
        assert abs(a.mean() - b.mean()) < 5 * se, (case, t, a.mean(), b.mean(), se)


# --- the single env's closed-form 2x2 kernel against the engine's step ----------------------------
@settings(max_examples=25, deadline=None)
@given(
    scenario=st.sampled_from(["ch4-position", "ch2-pv-2", "ch3-tracking", "ch5-game"]),
    objective=st.sampled_from(["trace", "logdet"]),
    warmup=st.sampled_from([None, "steady", 0, 3]),
    steps=st.lists(
        st.tuples(st.integers(0, 2**10), st.sampled_from([None, 0.5, 30.0]), st.booleans()),
        min_size=1,
        max_size=8,
    ),
)
def test_kernel_of_the_single_env_equals_the_engine_step(scenario, objective, warmup, steps):
    # Simulation(fast=True) runs the closed-form kernel on floats while no bias reached the
    # filter and hands its state to the engine at a leaking bias or a steady restart (and back
    # once consistent); fast=False runs the engine at every step: the same values throughout,
    # bit for bit (the engine's 2-state update is the float kernel on component arrays)
    from fdia_env import sparse_attack_v0
    from fdia_env.defenses.base import FilterInput
    from fdia_env.envs.simulation import Simulation

    sc, spec = sparse_attack_v0.episode_spec(
        scenario, horizon=len(steps), objective=objective, warmup=warmup
    )
    system = sc.system
    fast, engine = Simulation(system, spec), Simulation(system, spec, fast=False)
    for sim in (fast, engine):
        sim.reset(np.random.default_rng(0))
    assert fast.features() == engine.features()
    for used, power, steady in steps:
        used %= 2**system.M
        leak = None if power is None else power * np.eye(system.nz)
        steady = steady and used != 0  # a steady state needs a sensor
        fi = FilterInput(used=used, leaked_sigma=leak, steady=steady)
        a, b = fast.step(fi), engine.step(fi)
        assert a == b or (math.isnan(a) and math.isnan(b))
        np.testing.assert_array_equal(fast.P, engine.P)
        np.testing.assert_array_equal(fast.M, engine.M)
        np.testing.assert_array_equal(fast.features(), engine.features())
        assert fast.consistent == engine.consistent


# --- formats without a native vector env: SyncVectorEnv against the single envs ------------------
def _family_env():
    from fdia_env.envs.system_family import SystemFamilyEnv, TrackingFamily

    family = TrackingFamily(num_sensors=4, budget=2, horizon=3)
    return SystemFamilyEnv(family=family, system_seeds=range(5), objective="trace")


NO_NATIVE = {
    # the system-family env (a random tracking system at every reset): no native vector env
    "system_family": _family_env,
}


@pytest.mark.parametrize("case", sorted(NO_NATIVE))
def test_formats_without_a_native_vector_env_run_in_sync_vector_env(case):
    # SyncVectorEnv's members equal single envs seeded seed + i, stepped with the same (masked)
    # random actions
    make = NO_NATIVE[case]
    B, seed = 3, 11
    sync = SyncVectorEnv([make] * B, autoreset_mode=AutoresetMode.NEXT_STEP)
    singles = [make() for _ in range(B)]
    obs, info = sync.reset(seed=seed)
    for i, env in enumerate(singles):
        o, _ = env.reset(seed=seed + i)
        np.testing.assert_array_equal(obs[i], o)
    rng = np.random.default_rng(seed)
    ended = np.zeros(B, bool)
    for t in range(12):
        masks = info.get("action_mask")
        actions = _actions(sync.single_action_space, rng, B, masks)
        obs, reward, term, trunc, info = sync.step(actions)
        for i, env in enumerate(singles):
            if ended[i]:  # NEXT_STEP: this step reset the member
                o, _ = env.reset()
                np.testing.assert_array_equal(obs[i], o, err_msg=f"{case} reset {t}")
                ended[i] = False
                continue
            o, r, te, tr, _ = env.step(actions[i])
            np.testing.assert_array_equal(obs[i], o, err_msg=f"{case} step {t}")
            assert reward[i] == r and term[i] == te and trunc[i] == tr, (case, t, i)
            ended[i] = te or tr
