"""The batched engine's low-rank covariance update on large grids (n >= 40, steady start).

It must give the covariances of the full update (docs/math.md §1): checked member by member
against the engine with the low-rank form switched off and against the single engine.
"""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.vector import SyncVectorEnv

from fdia_env import scenarios
from fdia_env.defenses.base import FilterInput
from fdia_env.envs.engine import BatchedSimulation
from fdia_env.envs.simulation import Simulation
from fdia_env.episode import EpisodeSpec


def _masks(rng: np.random.Generator, B: int, M: int, most: int) -> np.ndarray:
    """(B, M) used sensors: each member drops 0 to ``most`` sensors."""
    mask = np.ones((B, M), dtype=bool)
    for row in mask:
        row[rng.choice(M, size=rng.integers(0, most + 1), replace=False)] = False
    return mask


@pytest.mark.parametrize("objective", ["trace", "logdet"])
def test_low_rank_update_equals_full_update_on_ieee57(objective):
    system = scenarios.get("grid-ieee57").system
    spec = EpisodeSpec(horizon=6, objective=objective)
    B = 5
    fast = BatchedSimulation(system, spec, B)
    full = BatchedSimulation(system, spec, B)
    full._lr_max = 0  # the full (I + P J)⁻¹ P update for every member
    full._lr_on = False
    assert fast._lr_on and fast._lr_max == 56 // 4
    rng = np.random.default_rng(3)
    masks = [_masks(rng, B, system.M, 2) for _ in range(5)]  # rank <= 5 + 4 * 2 <= 14
    masks[2][1] = True  # a member dropping nothing stays at the steady state
    masks[0][0, :3] = False  # and three rows dropped at once
    for t, mask in enumerate(masks):
        if t == 3:  # a partial reset keeps the other members' low-rank state
            where = np.array([True, False, False, True, False])
            fast.reset(where)
            full.reset(where)
        phi_fast = fast.step(mask, None, None, False)
        phi_full = full.step(mask, None, None, False)
        np.testing.assert_allclose(fast.P, full.P, rtol=1e-9, atol=1e-12 * np.abs(full.P).max())
        np.testing.assert_allclose(phi_fast, phi_full, rtol=1e-9)
        out_fast = np.zeros((1 + 56 + 56 * 55 // 2, B), np.float32)
        out_full = np.zeros((1 + 56 + 56 * 55 // 2, B), np.float32)
        assert fast.features(out_fast) == full.features(out_full)
        np.testing.assert_allclose(out_fast, out_full, rtol=1e-5, atol=1e-6)
    assert fast._lr_on  # the whole run used the low-rank form
    assert 0 < fast._lr_W.shape[2] <= fast._lr_max
    assert fast._lr_W.shape[2] == fast._lr_live.sum(1).max()  # padding columns dropped


def test_low_rank_update_matches_the_single_engine_on_ieee118():
    system = scenarios.get("grid-ieee118").system
    spec = EpisodeSpec(horizon=3)
    B = 3
    batch = BatchedSimulation(system, spec, B)
    singles = [Simulation(system, spec) for _ in range(B)]
    for one in singles:
        one.reset(np.random.default_rng(0))
    rng = np.random.default_rng(0)
    for _ in range(3):
        mask = _masks(rng, B, system.M, 4)
        batch.step(mask, None, None, False)
        for i, one in enumerate(singles):
            one.step(FilterInput(used=sum(1 << int(j) for j in np.flatnonzero(mask[i]))))
            np.testing.assert_allclose(
                batch.P[i], one.P, rtol=1e-9, atol=1e-12 * np.abs(one.P).max()
            )
    assert batch._lr_on


def test_rank_above_the_cap_falls_back_to_the_full_update():
    system = scenarios.get("grid-ieee57").system
    spec = EpisodeSpec(horizon=4)
    fast = BatchedSimulation(system, spec, 2)
    full = BatchedSimulation(system, spec, 2)
    full._lr_max, full._lr_on = 0, False
    rng = np.random.default_rng(1)
    for t in range(3):
        mask = _masks(rng, 2, system.M, 3)
        if t == 1:  # member 0 drops 20 rows: above n / 4 = 14
            mask[0, 10:30] = False
        fast.step(mask, None, None, False)
        full.step(mask, None, None, False)
        np.testing.assert_allclose(fast.P, full.P, rtol=1e-9, atol=1e-12 * np.abs(full.P).max())
    assert not fast._lr_on
    fast.reset()
    assert fast._lr_on and fast._lr_W.shape == (2, 56, 0)


@pytest.mark.parametrize("dynamics", ["expected", "sampled"])
def test_native_vector_env_matches_sync_on_ieee57(dynamics):
    env_id, kwargs, B = "fdia_env/SparseAttack-v0", {"scenario": "grid-ieee57"}, 3
    kwargs["dynamics"] = dynamics
    native = gym.make_vec(env_id, num_envs=B, vectorization_mode="vector_entry_point", **kwargs)
    sync = SyncVectorEnv([lambda: gym.make(env_id, **kwargs) for _ in range(B)])
    obs_n, _ = native.reset(seed=5)
    obs_s, _ = sync.reset(seed=5)
    rng = np.random.default_rng(2)
    n_space = native.single_action_space
    assert isinstance(n_space, gym.spaces.MultiBinary)
    for _ in range(7):  # horizon 3: two autoresets
        actions = (rng.random((B, n_space.n)) < 0.03).astype(np.int8)
        obs_n, r_n, te_n, tr_n, _ = native.step(actions)
        obs_s, r_s, te_s, tr_s, _ = sync.step(actions)
        assert native.unwrapped.sim._lr_on  # the low-rank update ran
        np.testing.assert_allclose(obs_n, obs_s, rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(r_n, r_s, rtol=1e-9, atol=1e-15)
        np.testing.assert_array_equal(te_n, te_s)
        np.testing.assert_array_equal(tr_n, tr_s)


@pytest.mark.parametrize("backend", ["numpy", "torch"])
@pytest.mark.parametrize("case", ["dc-ieee14-50", "random"])
def test_general_update_steps_only_the_active_members_and_leaves_the_others(backend, case):
    # the vector envs pass active=False for members being reset or held (the sequential
    # formats' members that do not commit): the (I + P J)⁻¹ P update runs on the active ones
    # alone, each exactly as in the step of the whole batch, and the others keep their P
    from conftest import random_system

    from fdia_env.backend import get_backend

    xp = get_backend(backend)
    if case == "random":  # F ≠ I: the prediction's products, on the active members only
        system = random_system(3, 4, [1, 2, 1, 1, 2, 1], 4, 0.9)
    else:
        system = scenarios.get(case).system  # 13 states, F = I: the general update
    assert system.n > 2
    spec = EpisodeSpec(horizon=6)
    B = 6
    whole, part = BatchedSimulation(system, spec, B, xp), BatchedSimulation(system, spec, B, xp)
    rng = np.random.default_rng(5)
    for t in range(4):
        used = xp.asarray(_masks(rng, B, system.M, 3))
        active = np.array([True, False, True, True, False, t == 2])
        before = xp.to_numpy(part.P).copy()
        whole.step(used, None, None, False)
        part.step(used, None, None, False, active=xp.asarray(active))
        P_whole, P_part = xp.to_numpy(whole.P), xp.to_numpy(part.P)
        phi_whole, phi_part = xp.to_numpy(whole.phi)[active], xp.to_numpy(part.phi)[active]
        if backend == "numpy":  # bit for bit: numpy's solve runs member by member
            np.testing.assert_array_equal(P_part[active], P_whole[active])
            np.testing.assert_array_equal(phi_part, phi_whole)
        else:  # torch's batched solve may pick another kernel for another batch size (1 ulp)
            np.testing.assert_allclose(P_part[active], P_whole[active], rtol=1e-14, atol=0)
            np.testing.assert_allclose(phi_part, phi_whole, rtol=1e-14, atol=0)
        np.testing.assert_array_equal(P_part[~active], before[~active])
        for sim in (whole, part):  # continue both from the same state
            sim._set_P(xp.asarray(P_whole))
    part.step(used, None, None, False, active=xp.asarray(np.zeros(B, dtype=bool)))
    np.testing.assert_array_equal(xp.to_numpy(part.P), P_whole)  # nobody active: nothing moves
