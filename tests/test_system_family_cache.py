"""SystemFamilyEnv's per-system cache: a system drawn again replays exactly as when fresh."""

from __future__ import annotations

import numpy as np
import pytest

from fdia_env.envs import system_family
from fdia_env.envs.grid_family import GridFamily
from fdia_env.envs.system_family import SystemFamilyEnv, TrackingFamily

pytest.importorskip("pandapower")


def _episodes(env: SystemFamilyEnv, episodes: int, seed: int) -> list:
    """Observations, rewards and infos of seeded episodes with random legal actions."""
    rng = np.random.default_rng(seed)
    out = []
    obs, info = env.reset(seed=seed)
    for _ in range(episodes):
        out.append((obs.copy(), info["system_seed"], info["slot_sensors"]))
        done = False
        while not done:
            legal = np.flatnonzero(env.action_masks())
            obs, reward, term, trunc, info = env.step(int(rng.choice(legal)))
            out.append((obs.copy(), reward, info["phi"] if term else None))
            done = term or trunc
        obs, info = env.reset()
    return out


@pytest.mark.parametrize(
    ("family", "kwargs"),
    [
        (TrackingFamily(num_sensors=6), {"action": "bitmask", "sort_sensors": True}),
        (TrackingFamily(num_sensors=6), {"action": "sequential", "objective": "logdet"}),
        (
            TrackingFamily(num_sensors=4, budget=3, horizon=2),
            {"reward_reference": lambda system, budget, horizon: 0.5 + system.M},
        ),
        (GridFamily(budget=4, horizon=2), {"action": "sequential", "sort_sensors": True}),
    ],
)
def test_a_cached_system_replays_bit_for_bit_as_a_fresh_one(monkeypatch, family, kwargs):
    # three systems, so the 12 episodes draw each several times (cache hits)
    cached = _episodes(SystemFamilyEnv(family, system_seeds=range(3), **kwargs), 12, seed=5)
    monkeypatch.setattr(system_family, "CACHED_SYSTEMS", 0)  # every reset prepares afresh
    fresh_env = SystemFamilyEnv(family, system_seeds=range(3), **kwargs)
    fresh = _episodes(fresh_env, 12, seed=5)
    assert len(fresh_env._cache) == 0
    assert len(cached) == len(fresh)
    for a, b in zip(cached, fresh, strict=True):
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)


def test_the_cache_keeps_at_most_cached_systems_least_recent_dropped(monkeypatch):
    monkeypatch.setattr(system_family, "CACHED_SYSTEMS", 2)
    env = SystemFamilyEnv(TrackingFamily(num_sensors=3, budget=2, horizon=2))
    for k in (7, 8, 7, 9):
        env.reset(options={"system_seed": k})
    assert list(env._cache) == [7, 9]


def test_the_reward_reference_is_called_once_per_system():
    calls = []

    def reference(system, budget, horizon):
        calls.append(system.name)
        return 2.0

    env = SystemFamilyEnv(
        TrackingFamily(num_sensors=3, budget=2, horizon=2),
        system_seeds=range(2),
        reward_reference=reference,
    )
    env.reset(seed=0)
    for _ in range(10):
        env.reset()
    assert sorted(calls) == sorted(env.family.system(k).name for k in env._cache)
    assert len(calls) == len(env._cache) == 2
