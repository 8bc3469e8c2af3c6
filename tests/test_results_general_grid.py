"""The grid family (random IEEE 14-bus loads and meter noise) and the ``general_grid`` table."""

from __future__ import annotations

import math

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

pytest.importorskip("pandapower")

from baselines.sparse import branch_and_bound, exhaustive, sfs
from experiments.results import general, general_grid
from fdia_env.envs.grid_family import GridFamily
from fdia_env.envs.system_family import SystemFamilyEnv, description_size
from fdia_env.systems import grid_system

# quick run, seed 0 (measured 2026-11-23): family + description 90.7 %, no description 95.7 %,
# random play 89.5 % of the per-system optimum (random play is high: c = 3 of 68 pairs)
QUICK_MARGIN = 0.005  # learned (family + description) minus random play, mean score
QUICK_MARGIN_BLIND = 0.04  # learned (family, no description) minus random play


def test_grid_family_is_reproducible_and_systems_differ():
    family = GridFamily()
    a, b, c = family.system(7), family.system(7), family.system(8)
    assert np.array_equal(a.R, b.R) and np.array_equal(a.x0, b.x0)
    assert not np.allclose(a.R, c.R)
    assert not np.allclose(a.x0, c.x0)
    assert (a.n, a.M, family.state_size, family.num_sensors) == (13, 34, 13, 34)


def test_grid_family_scales_each_meter_sigma_as_documented():
    family = GridFamily(noise_scale=(0.5, 2.0), load_scale=(0.5, 1.5))
    nominal = grid_system("ieee14")
    for k in (0, 11):
        rng = np.random.default_rng(k)
        rng.uniform(0.5, 1.5, size=11)  # the 11 load factors of case14
        f = np.exp(rng.uniform(math.log(0.5), math.log(2.0), size=34))
        sys = family.system(k)
        np.testing.assert_allclose(np.diag(sys.R), np.diag(nominal.R) * f**2, rtol=1e-12)
        np.testing.assert_array_equal(sys.H, nominal.H)  # DC: H does not depend on the loads
        np.testing.assert_array_equal(sys.F, nominal.F)
        np.testing.assert_array_equal(sys.Q, nominal.Q)
        ratio = np.sqrt(np.diag(sys.R) / np.diag(nominal.R))
        assert ratio.min() >= 0.5 and ratio.max() <= 2.0 and ratio.max() / ratio.min() > 2.0


def test_grid_family_prior_mean_is_pandapowers_dc_power_flow_of_the_scaled_loads():
    import pandapower
    import pandapower.networks

    family = GridFamily()
    for k in (3, 4):
        rng = np.random.default_rng(k)
        load = rng.uniform(0.5, 1.5, size=11)
        net = pandapower.networks.case14()
        net.load["p_mw"] = net.load["p_mw"].to_numpy() * load
        pandapower.rundcpp(net)
        va = np.deg2rad(net.res_bus.va_degree.to_numpy())
        expected = (va - va[0])[1:]  # slack is bus 0; the state: buses 1..13
        np.testing.assert_allclose(family.system(k).x0, expected, rtol=1e-9, atol=1e-12)
        assert np.abs(expected - grid_system("ieee14").x0).max() > 1e-3  # loads did move it


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        ({"case": "ieee999"}, "case"),
        ({"load_scale": (1.5, 0.5)}, "load_scale"),
        ({"load_scale": (0.0, 1.0)}, "load_scale"),
        ({"noise_scale": (0.5,)}, "noise_scale"),
        ({"noise_scale": (0.5, math.inf)}, "noise_scale"),
        ({"budget": -1}, "budget"),
        ({"budget": 69}, "budget"),
        ({"horizon": 0}, "horizon"),
    ],
)
def test_grid_family_rejects_bad_parameters_by_name(kwargs, name):
    with pytest.raises(ValueError, match=name):
        GridFamily(**kwargs)


def test_grid_family_rejects_bad_seed_and_factors_by_name():
    family = GridFamily()
    with pytest.raises(ValueError, match="seed"):
        family.system(-1)
    with pytest.raises(ValueError, match="rng"):
        family.draw(3)
    with pytest.raises(ValueError, match="noise_factors"):
        family.build(np.ones(11), np.zeros(34))
    with pytest.raises(ValueError, match="load_factors"):
        family.build(np.ones(3), np.ones(34))


def test_grid_family_optimum_equals_exhaustive_search_and_bounds_sfs():
    family = GridFamily()
    for k in (1_000_000, 1_000_001):
        sc = family.scenario(k)
        best = branch_and_bound(sc, family.budget, family.horizon)
        exs = exhaustive(sc, family.budget, family.horizon)
        greedy = sfs(sc, family.budget, family.horizon)
        assert best.proved_optimal
        assert best.value == pytest.approx(exs.value, rel=1e-10)
        assert greedy.value <= exs.value * (1 + 1e-12)


def test_family_env_on_grids_passes_the_checker_and_replays_the_optimum():
    family = GridFamily()
    env = SystemFamilyEnv(family, action="sequential", system_seeds=range(10, 20))
    check_env(env, skip_render_check=True)
    obs, _ = env.reset(options={"system_seed": 1_000_002})
    d_sparse = 2 + 13 + 13 * 12 // 2
    assert obs.shape == (d_sparse + 34 + description_size(13, 34),) == (1023,)
    best = branch_and_bound(family.scenario(1_000_002), family.budget, family.horizon)
    for bitmask in best.actions():
        for j in range(34):
            if int(bitmask) >> j & 1:
                assert env.action_masks()[j + 1]
                env.step(j + 1)
        _, _, term, _, info = env.step(0)
    assert term
    assert info["phi"] == pytest.approx(best.value, rel=1e-12)
    with pytest.raises(ValueError, match="max_sensors"):
        SystemFamilyEnv(family, action="bitmask")  # 2**34 actions: refused


@pytest.fixture(scope="module")
def quick():
    return general.general_table(general_grid.QUICK, seed=0)


def test_quick_grid_run_learned_beats_random_and_references_are_consistent(quick):
    summary, per_system, extras = quick
    rows = {r["policy"]: r for r in summary}
    assert len(per_system) == 100 and extras["all_proved"]
    assert all(r["sfs"] <= r["optimum"] * (1 + 1e-12) for r in per_system)
    learned = rows[general.POLICY_NAMES[0]]["mean"]
    blind = rows[general.POLICY_NAMES[1]]["mean"]
    random_play = rows["random play"]["mean"]
    assert learned >= random_play + QUICK_MARGIN
    assert blind >= random_play + QUICK_MARGIN_BLIND
    for name in general.POLICY_NAMES:  # nobody beats a proved optimum
        assert rows[name]["mean"] <= 1.0 + 1e-9
        assert all(r[name] <= 1.0 + 1e-9 for r in per_system)
