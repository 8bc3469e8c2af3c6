"""Power-grid systems (docs/math.md §7): the DC measurement model against pandapower, the presets,
every env and baseline on them, and the large-M action and strategy-set options."""

import dataclasses
import sys

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from pettingzoo.test import api_test, parallel_api_test

import fdia_env
from baselines.game import payoff_matrix, solve_double_oracle, solve_zero_sum
from baselines.sparse import dp, exhaustive, lowrank, sbs, sfs, sfs_ss
from baselines.sparse.problem import make_problem
from fdia_env import (
    detection_game_v0,
    scenarios,
    sensor_game_v0,
    sparse_attack_v0,
)
from fdia_env.attacks.base import bits_to_mask, mask_array_to_bits, mask_to_bits
from fdia_env.attacks.subsets import game_subsets, subsets
from fdia_env.envs.opponents import FixedMix
from fdia_env.kalman import steady_state, steady_state_iterate
from fdia_env.registration import ENV_NAMES, GYM_IDS, load
from fdia_env.systems import grid_system
from fdia_env.systems.grid import GRID_CASES, dc_network, grid_model
from fdia_env.systems.grid.cases import IEEE14_BRANCHES

pp = pytest.importorskip("pandapower")
pn = pytest.importorskip("pandapower.networks")

CASES_300 = {case.name: case.pandapower for case in GRID_CASES.values()}  # the table of cases
MODULES = [load(name) for name in ENV_NAMES]  # every entry of the table of environments


# --- the measurement model against pandapower's own DC power flow ---------------------------


def pandapower_reference(case):
    """pandapower's rundcpp angles (rad) and its result tables for ``case``."""
    net = getattr(pn, CASES_300[case])()
    pp.rundcpp(net)
    return net


def reference_measurements(net, model):
    """Each meter's value from pandapower's result tables, per unit of net.sn_mva."""
    columns = {"line": ("p_from_mw", "p_to_mw"), "trafo": ("p_hv_mw", "p_lv_mw")}
    out = []
    for meter in model.meters:
        if meter.kind == "injection":
            # res_bus.p_mw is the bus's demand (load convention, shunt included): injection = −it
            out.append(-net.res_bus.p_mw.at[model.network.buses[meter.bus]])
        else:
            table, index = model.network.branches[meter.branch]
            column = columns[table][meter.end == "to"]
            out.append(net[f"res_{table}"][column].at[index])
    return np.array(out) / net.sn_mva


def model_error(model, net):
    """Largest |H θ + offset − pandapower| relative to the largest reference value."""
    theta = np.deg2rad(net.res_bus.va_degree.loc[model.network.buses].to_numpy())
    ref = reference_measurements(net, model)
    return float(np.abs(model.measure(theta) - ref).max() / np.abs(ref).max())


@pytest.mark.parametrize("case", sorted(CASES_300))
def test_measurements_equal_pandapower_dc_flows_and_injections(case):
    """Every flow (both ends) and every injection: H θ = rundcpp's results to 1e-9 relative."""
    net = pandapower_reference(case)
    model = grid_model(case, flow_ends="both")
    assert model_error(model, net) < 1e-9
    if case == "ieee300":
        return  # the 1,122-meter LinearSystem holds 1,122 (299, 299) information matrices
    # the state part: H (slack column removed) applied to the angles relative to the slack
    theta = np.deg2rad(net.res_bus.va_degree.loc[model.network.buses].to_numpy())
    x = (theta - theta[model.network.slack])[np.arange(len(theta)) != model.network.slack]
    ref = reference_measurements(net, model)
    np.testing.assert_allclose(model.system.H @ x, ref, rtol=0, atol=1e-9 * np.abs(ref).max())
    np.testing.assert_allclose(model.system.x0, x, rtol=0, atol=1e-12)  # prior mean: DC angles


@pytest.mark.parametrize("case", sorted(CASES_300))
def test_the_table_of_grid_cases_counts_what_pandapower_builds(case):
    """Buses, branches, meters and states of each case as the table states them."""
    entry = GRID_CASES[case]
    network = dc_network(case)
    assert (network.n_buses, len(network.branches)) == (entry.buses, entry.branches)
    if case != "ieee300":  # its 711-meter LinearSystem is slow to build
        system = grid_model(case).system
        assert (system.M, system.n) == (entry.meters, entry.states)


def test_the_pandapower_free_ieee14_branches_are_pandapowers_case14():
    """IEEE14_BRANCHES (dc_grid14's data): case14's branches, reactances to 1e-4 relative."""
    network = dc_network("ieee14")
    bus = {int(b): i + 1 for i, b in enumerate(network.buses)}  # pandapower index -> 1-based
    got = {
        (bus[int(network.buses[f])], bus[int(network.buses[t])]): x
        for f, t, x in zip(network.from_bus, network.to_bus, network.x, strict=True)
    }
    table = {(i, j): x for i, j, x in IEEE14_BRANCHES}
    assert set(table) == set(got)
    np.testing.assert_allclose([got[k] for k in table], list(table.values()), rtol=1e-4)


def test_a_wrong_reactance_fails_the_comparison():
    """Negative control: one branch's reactance off by 1 % in H breaks the match."""
    net = pandapower_reference("ieee14")
    network = dc_network("ieee14")
    x = network.x.copy()
    x[3] *= 1.01
    wrong = grid_model(dataclasses.replace(network, x=x), flow_ends="both")
    assert model_error(wrong, net) > 1e-4
    assert model_error(grid_model(network, flow_ends="both"), net) < 1e-9


def test_branch_susceptances_follow_the_pandapower_tables():
    """Independent per-unit check: lines b = 1/x_pu; case14's transformers b = 1/(x_pu τ)."""
    net = pn.case14()
    network = dc_network("ieee14")
    b = dict(zip(network.branches, network.b, strict=True))
    for index, line in net.line.iterrows():
        z_base = net.bus.vn_kv.at[line.from_bus] ** 2 / net.sn_mva
        x_pu = line.x_ohm_per_km * line.length_km / line.parallel / z_base
        assert b[("line", index)] == pytest.approx(1.0 / x_pu, rel=1e-12)
    for index, trafo in net.trafo.iterrows():
        x_pu = np.sqrt(trafo.vk_percent**2 - trafo.vkr_percent**2) / 100 * net.sn_mva / trafo.sn_mva
        tap = 1.0
        if trafo.tap_side == "hv" and not np.isnan(trafo.tap_pos):
            tap = 1.0 + (trafo.tap_pos - trafo.tap_neutral) * trafo.tap_step_percent / 100
        assert b[("trafo", index)] == pytest.approx(1.0 / (x_pu * tap), rel=1e-9)
    assert sorted(set(np.round(network.tap, 3))) == [0.932, 0.969, 0.978, 1.0]


def test_bus_grouping_stacks_each_buses_injection_and_flows_into_one_sensor():
    """sensors="bus": one RTU per bus, its injection then the flows metered at its end."""
    meters = grid_model("ieee14", flow_ends="both")
    rtu = grid_model("ieee14", sensors="bus")
    network = rtu.network
    assert rtu.system.M == network.n_buses == 14
    assert rtu.system.nz == network.n_buses + 2 * len(network.branches) == 54
    row = 0
    for s, sensor in enumerate(rtu.system.sensors):
        rows = [m for m in rtu.meters[row : row + sensor.dim]]
        assert {m.bus for m in rows} == {s} and rows[0].kind == "injection"
        assert np.array_equal(sensor.R, np.diag(np.diag(sensor.R)))
        row += sensor.dim
    # the same rows as the meter-level model, permuted
    key = {m: r for r, m in enumerate(meters.meters)}
    perm = [key[m] for m in rtu.meters]
    np.testing.assert_array_equal(rtu.system.H, meters.system.H[perm])


def test_defaults_random_walk_and_noise():
    system = grid_system("ieee14")
    assert (system.n, system.M, system.nz) == (13, 34, 34)
    np.testing.assert_array_equal(system.F, np.eye(13))
    np.testing.assert_array_equal(system.Q, 1e-6 * np.eye(13))
    np.testing.assert_allclose(np.diag(system.R)[:14], 0.02**2)  # injections first
    np.testing.assert_allclose(np.diag(system.R)[14:], 0.01**2)  # then from-end flows
    own = grid_system("ieee14", q=4e-6, sigma_flow=0.02, F=0.5 * np.eye(13))
    np.testing.assert_array_equal(own.Q, 4e-6 * np.eye(13))
    np.testing.assert_array_equal(own.F, 0.5 * np.eye(13))


@pytest.mark.parametrize("name", ["grid-ieee14", "grid-ieee118"])
def test_steady_state_dare_equals_fixed_point_iteration(name):
    system = scenarios.get(name).system
    P_pred, P_post, _ = steady_state(system)
    it_pred, it_post, _ = steady_state_iterate(system)
    np.testing.assert_allclose(P_post, it_post, rtol=0, atol=1e-9 * np.abs(P_post).max())
    np.testing.assert_allclose(P_pred, it_pred, rtol=0, atol=1e-9 * np.abs(P_pred).max())
    # nontrivial: prediction and measurements both matter (docs/math.md §7)
    static = np.trace(np.linalg.inv(system.H.T @ np.linalg.solve(system.R, system.H)))
    assert 0.2 < np.trace(P_post) / static < 0.5


def test_presets_table():
    sizes = {}
    for name in ["grid-ieee14", "grid-ieee30", "grid-ieee57", "grid-ieee118"]:
        sc = scenarios.get(name)
        assert scenarios.get(name) is sc  # built once, cached
        sizes[name] = (sc.system.n, sc.system.M, sc.budget, sc.horizon, sc.power)
    assert sizes == {
        "grid-ieee14": (13, 34, 6, 6, 0.01),
        "grid-ieee30": (29, 71, 6, 4, 0.01),
        "grid-ieee57": (56, 137, 6, 3, 0.01),
        "grid-ieee118": (117, 304, 6, 3, 0.01),
    }


# --- bad input ----------------------------------------------------------------------------


def islanded_net():
    net = pn.case14()
    a = pp.create_bus(net, vn_kv=135.0)
    b = pp.create_bus(net, vn_kv=135.0)
    pp.create_line_from_parameters(net, a, b, 1.0, 0.1, 1.0, 0.0, 1.0)
    return net


def no_line_net():
    net = pp.create_empty_network()
    a = pp.create_bus(net, vn_kv=110.0)
    pp.create_bus(net, vn_kv=110.0)
    pp.create_ext_grid(net, a)
    return net


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: grid_system("ieee15"), r"case must be one of \['ieee118', 'ieee14'"),
        (lambda: grid_system(3.0), r"case must be one of .* or a pandapower network"),
        (lambda: grid_system(islanded_net()), r"islands"),
        (lambda: grid_system(no_line_net()), r"no in-service lines"),
        (lambda: grid_system("ieee14", injections=[0, 99]), r"injections must be .* bus indices"),
        (lambda: grid_system("ieee14", flows=[("line", 99)]), r"flows must be .* \(table, index\)"),
        (lambda: grid_system("ieee14", flows=["line0"]), r"flows must be"),
        (lambda: grid_system("ieee14", injections="some"), r"injections must be one of"),
        (lambda: grid_system("ieee14", sigma_flow=0.0), r"sigma_flow must be a finite number > 0"),
        (lambda: grid_system("ieee14", sigma_injection=-1), r"sigma_injection must be"),
        (lambda: grid_system("ieee14", q=0.0), r"q must be a finite number > 0"),
        (lambda: grid_system("ieee14", sensors="rtu"), r"sensors must be one of"),
        (lambda: grid_system("ieee14", flow_ends="to"), r"flow_ends must be one of"),
        (lambda: grid_system("ieee14", injections="none", flows="none"), r"select no meter"),
        (lambda: grid_system("ieee14", injections=[0], flows="none"), r"not make the .* observ"),
        (lambda: grid_system("ieee14", noise=1), r"unknown options \['noise'\]"),
    ],
)
def test_bad_input_raises_value_error_naming_the_parameter(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_missing_pandapower_names_the_grid_extra(monkeypatch):
    monkeypatch.setitem(sys.modules, "pandapower", None)
    monkeypatch.setitem(sys.modules, "pandapower.networks", None)
    with pytest.raises(ImportError, match=r"fdia-env\[grid\]"):
        grid_system("ieee14")


# --- every env and Gymnasium id on the presets ------------------------------------------------


def step_a_few(env, steps):
    env.reset(seed=0)
    rewards = []
    for _ in range(steps):
        actions = {a: env.action_space(a).sample() for a in env.agents}
        _, r, term, _, _ = env.step(actions)
        rewards.append(r["attacker"])
        if all(term.values()):
            break
    assert all(np.isfinite(rewards))
    return rewards


@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.NAME)
@pytest.mark.parametrize("dynamics", ["expected", "sampled"])
def test_every_env_steps_on_grid_ieee14(module, dynamics):
    step_a_few(module.parallel_env(scenario="grid-ieee14", dynamics=dynamics), 3)


@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.NAME)
def test_every_env_steps_on_grid_ieee118(module):
    # the detection game integrates its expected reward over 304 measurements (~20 s a step);
    # its sampled dynamics exercise the same construction and spaces
    dynamics = "sampled" if module is detection_game_v0 else "expected"
    step_a_few(module.parallel_env(scenario="grid-ieee118", dynamics=dynamics), 1)


@pytest.mark.parametrize("env_id", sorted(GYM_IDS))
@pytest.mark.parametrize("scenario", ["grid-ieee14", "grid-ieee118"])
def test_every_gym_id_steps_on_the_grid_presets(env_id, scenario):
    kwargs = {"scenario": scenario}
    if "Detection" in env_id and scenario == "grid-ieee118":
        kwargs["dynamics"] = "sampled"  # see test_every_env_steps_on_grid_ieee118
    env = gym.make(env_id, **kwargs)
    env.reset(seed=0)
    env.action_space.seed(0)
    _, reward, *_ = env.step(env.action_space.sample())
    assert np.isfinite(reward)


@pytest.mark.parametrize("module", MODULES, ids=lambda m: m.NAME)
@pytest.mark.filterwarnings("ignore::UserWarning")
def test_pettingzoo_api_on_grid_ieee14(module):
    parallel_api_test(module.parallel_env(scenario="grid-ieee14"), num_cycles=20)
    api_test(module.env(scenario="grid-ieee14"), num_cycles=10)


@pytest.mark.parametrize("env_id", sorted(GYM_IDS))
def test_gymnasium_check_env_on_grid_ieee14(env_id):
    gym_check_env(gym.make(env_id, scenario="grid-ieee14").unwrapped, skip_render_check=True)


# --- the sparse attack's large-M actions ------------------------------------------------------


def test_sparse_action_formats_and_trimming_rule():
    env = sparse_attack_v0.parallel_env(scenario="grid-ieee14", budget=3)
    assert isinstance(env.action_space("attacker"), gym.spaces.MultiBinary)
    obs, _ = env.reset(seed=0)
    assert isinstance(obs["attacker"], np.ndarray)  # no mask: a plain Box observation
    action = np.zeros(34, dtype=np.int64)
    action[[5, 1, 30, 7]] = 1
    _, _, _, _, infos = env.step({"attacker": action})
    attacked = np.flatnonzero(infos["attacker"]["attacked"]).tolist()
    assert attacked == [1, 5, 7]  # trimmed to the lowest-numbered three
    _, _, _, _, infos = env.step({"attacker": action})
    assert not infos["attacker"]["attacked"].any() and infos["attacker"]["budget_left"] == 0
    single = sparse_attack_v0.parallel_env(scenario="grid-ieee14", budget=1, action="single")
    assert single.action_space("attacker") == gym.spaces.Discrete(35)
    obs, _ = single.reset(seed=0)
    assert obs["attacker"]["action_mask"].tolist() == [1] * 35
    obs, _, _, _, infos = single.step({"attacker": 8})
    assert np.flatnonzero(infos["attacker"]["attacked"]).tolist() == [7]
    assert obs["attacker"]["action_mask"].tolist() == [1] + [0] * 34  # budget spent
    _, _, _, _, infos = single.step({"attacker": 3})
    assert np.flatnonzero(infos["attacker"]["attacked"]).tolist() == []
    with pytest.raises(ValueError, match=r"0/1 array of shape \(34,\)"):
        env.reset(seed=0)
        env.step({"attacker": np.full(34, 2)})
    with pytest.raises(ValueError, match="at most 16 sensors"):
        sparse_attack_v0.parallel_env(scenario="grid-ieee14", action="bitmask")
    # the literature's presets keep Discrete(2**M)
    assert sparse_attack_v0.parallel_env().action_space("attacker") == gym.spaces.Discrete(8)


def test_solver_plan_replayed_in_the_env_reproduces_its_value():
    result = sfs_ss("grid-ieee14")
    env = gym.make("fdia_env/SparseAttack-v0", scenario="grid-ieee14")
    policy = result.policy()
    obs, _ = env.reset(seed=0)
    total, done = 0.0, False
    while not done:
        obs, reward, done, _, _ = env.step(policy.predict(obs)[0])
        total += reward
    assert total == pytest.approx(result.value, rel=1e-12)


@pytest.mark.parametrize("dynamics", ["expected", "sampled"])
def test_native_vector_env_equals_sync_vector_env_on_grid_ieee14(dynamics):
    kwargs = {"scenario": "grid-ieee14", "dynamics": dynamics, "reward_mode": "per_step"}
    B = 4
    venv = gym.make_vec(
        "fdia_env/SparseAttack-v0", num_envs=B, vectorization_mode="vector_entry_point", **kwargs
    )
    sync = gym.vector.SyncVectorEnv(
        [lambda: gym.make("fdia_env/SparseAttack-v0", **kwargs) for _ in range(B)]
    )
    o1, _ = venv.reset(seed=3)
    o2, _ = sync.reset(seed=3)
    rng = np.random.default_rng(0)
    for _ in range(8):  # through an autoreset
        np.testing.assert_allclose(o1, o2, rtol=1e-12, atol=1e-12)
        actions = (rng.random((B, 34)) < 0.1).astype(np.int64)
        o1, r1, t1, _, _ = venv.step(actions)
        o2, r2, t2, _, _ = sync.step(actions)
        np.testing.assert_allclose(r1, r2, rtol=1e-12, atol=0)
        np.testing.assert_array_equal(t1, t2)


def test_bitmasks_beyond_int64():
    mask = np.zeros(300, dtype=bool)
    mask[[0, 5, 63, 64, 299]] = True
    bits = mask_to_bits(mask)
    np.testing.assert_array_equal(bits_to_mask(bits, 300), mask)
    assert mask_array_to_bits(np.stack([mask, ~mask]))[0] == bits


# --- baselines at grid scale --------------------------------------------------------------


@pytest.mark.parametrize("objective", ["trace", "logdet"])
def test_rank_one_toggles_equal_the_full_recursion(objective):
    problem = make_problem("grid-ieee14", None, None, objective)
    assert lowrank.applies(problem)
    rng = np.random.default_rng(1)
    flats = np.arange(problem.size)
    for density in (0.0, 0.1, 0.6):
        attacked = rng.random(problem.size) < density
        masks = np.repeat(attacked[None], problem.size, axis=0)
        masks[flats, flats] ^= True
        full = problem.evaluate_masks(masks.reshape(-1, problem.horizon, problem.M))
        fast = lowrank.toggle_values(problem, attacked, flats)
        np.testing.assert_allclose(fast, full, rtol=1e-10, atol=0)


@pytest.mark.parametrize("name", ["grid-ieee14", "grid-ieee30", "grid-ieee57", "grid-ieee118"])
def test_greedy_and_dp_solvers_run_on_every_grid_preset(name):
    sc = scenarios.get(name)
    forward, improved, table = sfs(sc), sfs_ss(sc), dp(sc)
    problem = make_problem(sc, None, None)
    for result in (forward, improved, table):
        assert len(result.attacks) == sc.budget
        assert result.value == pytest.approx(problem.evaluate(result.attacks), rel=1e-12)
        assert result.value > np.trace(problem.P_start)  # attacking raises the error
    assert improved.value >= forward.value * (1 - 1e-12)


def test_sbs_runs_on_grid_ieee30():
    result = sbs("grid-ieee30")
    assert len(result.attacks) == 6
    assert result.value >= sfs("grid-ieee30").value * 0.9


def test_exhaustive_refuses_huge_instances_and_runs_when_told():
    with pytest.raises(ValueError, match=r"92,944,609,660 sets \(estimated .*max_sets=None"):
        exhaustive("grid-ieee14")
    with pytest.raises(ValueError, match=r"C\(M·N = 34, c = 2\) = 561 sets"):
        exhaustive("grid-ieee14", budget=2, horizon=1, max_sets=100)
    best = exhaustive("grid-ieee14", budget=2, horizon=1, max_sets=None)
    problem = make_problem("grid-ieee14", 2, 1)
    brute = max(problem.evaluate([(0, i), (0, j)]) for i in range(34) for j in range(i + 1, 34))
    assert best.value == pytest.approx(brute, rel=1e-12)
    assert sfs_ss("grid-ieee14", budget=2, horizon=1).value <= best.value * (1 + 1e-12)


# --- the sensor game's strategy sets ------------------------------------------------------


def test_strategy_sets_keep_size_then_lexicographic_order():
    assert subsets(4, max_size=2) == subsets(4)[:10]
    assert game_subsets(4, 1, "attacker") == [(0,), (1,), (2,), (3,)]
    assert game_subsets(4, 1, "defender") == [
        (0, 1, 2),
        (0, 1, 3),
        (0, 2, 3),
        (1, 2, 3),
        (0, 1, 2, 3),
    ]
    assert game_subsets(3, None, "defender") == subsets(3)


def test_double_oracle_equals_the_lp_on_the_restricted_grid_game():
    L = payoff_matrix("grid-ieee14", max_subset_size=1)
    assert L.shape == (35, 34)
    _, _, value = solve_zero_sum(L)
    result = solve_double_oracle("grid-ieee14", max_subset_size=1)
    assert result.value == pytest.approx(value, rel=1e-9)
    assert result.gap <= 1e-9 * value
    assert len(result.attacker) > 1  # a mixed equilibrium: the game is not trivial
    assert result.strategy("defender").shape == (35,)


def test_sensor_game_env_pays_the_payoff_matrix_entries():
    L = payoff_matrix("grid-ieee14", max_subset_size=1)
    env = sensor_game_v0.parallel_env(scenario="grid-ieee14", max_subset_size=1)
    assert env.action_space("attacker").n == 34 and env.action_space("defender").n == 35
    for d, a in [(34, 0), (0, 33), (5, 5), (12, 20)]:
        env.reset(seed=0)
        _, rewards, *_ = env.step({"attacker": a, "defender": d})
        assert rewards["attacker"] == pytest.approx(L[d, a], rel=1e-9)
    view = gym.make(
        "fdia_env/SensorGameDefender-v0", scenario="grid-ieee14", opponent=FixedMix.uniform(595)
    )
    assert view.action_space.n == 596  # the preset's k = 2
    assert fdia_env.__version__
