"""The ``sparse_grid`` result table: the solver replay, the instance checks and the quick run."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from agents.evaluate import evaluate
from baselines.sparse import exhaustive, sfs
from experiments.results import sparse_grid
from experiments.results.sparse_grid import Budget, Instance, ratio


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    """The quick run (one small grid instance, 1 seed, short training), once for the module."""
    out = tmp_path_factory.mktemp("sparse_grid")
    text = sparse_grid.run(quick=True, seed=0, out=out)
    rows = json.loads((out / "sparse_grid.json").read_text())
    return text, rows


def test_plan_policy_replays_exs_set_exactly_in_the_learners_env():
    best = exhaustive("ch4-position", budget=3, horizon=4)
    inst = Instance("ieee14-rtu", 3, 4, "trace")  # only c, N and Φ are read with a system
    from fdia_env.scenarios import get

    env = sparse_grid.make_env(get("ch4-position").system, inst)
    assert env.action_space.n == 3 * 4 + 1  # plan-first: the (sensor, step) pairs and stop
    result = evaluate(sparse_grid.plan_policy(best), env, 2, seed=0, reference=best.value)
    assert result.mean == pytest.approx(best.value, rel=1e-12)
    assert result.score == pytest.approx(1.0, rel=1e-12)


def test_training_env_rescales_as_train_py_nothing_0_optimum_1():
    from fdia_env.scenarios import get

    best = exhaustive("ch4-position", budget=3, horizon=4)
    inst = Instance("ieee14-rtu", 3, 4, "trace")
    system = get("ch4-position").system
    venv = sparse_grid.training_env(system, inst, reference=best.value)
    (env,) = venv.envs
    optimum = evaluate(sparse_grid.plan_policy(best), env, 1, seed=0, reference=1.0).mean
    empty = exhaustive("ch4-position", budget=0, horizon=4)  # attacking nothing
    nothing = evaluate(sparse_grid.plan_policy(empty), env, 1, seed=0, reference=1.0).mean
    assert optimum == pytest.approx(1.0, abs=1e-12)
    assert nothing == pytest.approx(0.0, abs=1e-12)
    # without a reference (or one no better than nothing) SB3's running normalisation
    assert type(sparse_grid.training_env(system, inst)).__name__ == "VecNormalize"
    useless = sparse_grid.training_env(system, inst, reference=empty.value)
    assert type(useless).__name__ == "VecNormalize"


def test_results_train_maskable_ppo_with_train_py_grid_hyperparameters():
    from agents.config import Hyperparameters, resolved_hyperparameters
    from agents.training import run_setup

    # the results train one env: train.py's settings with --num-envs 1
    setup = run_setup(
        "sparse_attack_v0", "attacker", "grid-ieee14", {}, None, Hyperparameters(), num_envs=1
    )
    assert setup.algo == "MaskablePPO" and setup.normalize_reward
    assert setup.env_kwargs["order"] == "increasing"
    ours = resolved_hyperparameters("MaskablePPO", sparse_grid.train_py_hyperparameters())
    assert ours == resolved_hyperparameters("MaskablePPO", setup.hp)


@pytest.mark.parametrize("inst", sparse_grid.FULL_INSTANCES, ids=lambda i: i.system)
@pytest.mark.parametrize("algo", ["MaskablePPO", "torch-ppo"])
def test_each_rows_learners_take_train_pys_options_and_hyperparameters_there(inst, algo):
    """The env options (dc-ieee14-50: plan order, state groups) and hyperparameters of train.py."""
    from agents.config import Hyperparameters, resolved_hyperparameters
    from agents.training import run_setup

    preset = "grid-ieee14-rtu" if inst.system == "ieee14-rtu" else inst.system
    setup = run_setup(
        "sparse_attack_v0", "attacker", preset, {}, algo, Hyperparameters(), num_envs=1
    )
    system = sparse_grid.SYSTEMS[inst.system][2]() if inst.system == "ieee14-rtu" else None
    ours = sparse_grid.env_kwargs(system, inst)
    for key in ("action", "order", "groups"):
        assert ours.get(key) == setup.env_kwargs.get(key), key
    assert ours.get("groups") == ("state" if inst.system == "dc-ieee14-50" else None)
    hp = sparse_grid.train_py_hyperparameters(inst, setup.algo)
    assert resolved_hyperparameters(setup.algo, hp) == resolved_hyperparameters(
        setup.algo, setup.hp
    )
    # an explicit order (the decision-order study) leaves the preset's other options out
    assert "groups" not in sparse_grid.env_kwargs(system, inst, "time")


def test_plan_policy_picks_the_lowest_pair_not_yet_planned_batched():
    best = exhaustive("ch4-position", budget=2, horizon=3)
    policy = sparse_grid.plan_policy(best)
    slots = sorted(k * 3 + i for k, i in best.attacks)
    obs = np.zeros((2, 5 + 9 + 1), dtype=np.float32)
    obs[1, 5 + slots[0]] = 1.0  # member 1 has planned the first pair
    actions, _ = policy.predict(obs)
    assert actions.tolist() == [slots[0] + 1, slots[1] + 1]
    obs[0, 5 + np.array(slots)] = 1.0
    assert policy.predict(obs[0])[0] == 0  # everything planned: stop


@pytest.mark.parametrize(
    ("kwargs", "name"),
    [
        (dict(system="ieee15"), "system"),
        (dict(budget=0), "budget"),
        (dict(horizon=True), "horizon"),
        (dict(objective="max"), "objective"),
        (dict(bnb_limit=-1.0), "bnb_limit"),
    ],
)
def test_instance_rejects_bad_input_by_name(kwargs, name):
    base = dict(system="ieee14-rtu", budget=3, horizon=3, objective="trace")
    with pytest.raises(ValueError, match=name):
        Instance(**{**base, **kwargs})


def test_budget_rejects_bad_input_by_name():
    with pytest.raises(ValueError, match="maskable_steps"):
        Budget(maskable_steps=0, torch_steps=10)
    with pytest.raises(ValueError, match="torch_envs"):
        Budget(maskable_steps=10, torch_steps=10, torch_envs=0)


def test_ratio_is_the_det_ratio_for_logdet():
    assert ratio(-2.0, -1.0, "logdet") == pytest.approx(math.exp(-1.0))
    assert ratio(0.5, 2.0, "trace") == 0.25


def test_quick_run_heuristics_below_certified_optimum_equal_to_exs(quick):
    _, rows = quick
    (row,) = rows
    assert row["proved"] and row["exs"] is not None
    assert row["optimum"] == pytest.approx(row["exs"], rel=1e-12)
    for name, score in row["heuristic_scores"].items():
        assert score <= 1 + 1e-12, name
    # measured at seed 0 (quick instance ieee14-rtu c=3 N=3 logdet): SBS stops at 76.5 %
    assert row["heuristic_scores"]["SBS"] == pytest.approx(0.7651, abs=1e-3)


def test_quick_run_instances_are_identical_for_solvers_and_learners(quick):
    _, rows = quick
    (row,) = rows
    sfs_value = row["values"]["SFS"]
    # SFS's set played in the sparse env itself and in the learners' env (plan-first order)
    assert row["sfs_native_return"] == pytest.approx(sfs_value, rel=1e-12)
    assert row["sfs_plan_return"] == pytest.approx(sfs_value, rel=1e-12)
    assert row["bnb_plan_return"] == pytest.approx(row["optimum"], rel=1e-12)
    # and an independent SFS run on a freshly built system gives the same value
    system = sparse_grid.SYSTEMS[row["system"]][2]()
    again = sfs(system, row["budget"], row["horizon"], row["objective"]).value
    assert again == pytest.approx(sfs_value, rel=1e-12)


def test_quick_run_learned_policy_beats_random_play(quick):
    text, rows = quick
    (row,) = rows
    torch_ppo = row["learners"]["torch-ppo"]
    # measured at seed 0 (the env's plan-first order): torch PPO 100 % of the optimum without
    # observation normalisation (74.1 % with it), MaskablePPO 76.5 % with train.py's reward
    # scale (15.6 % with VecNormalize), random 0.9 %
    assert row["random_score"] < 0.05
    assert torch_ppo["mean"] >= 0.9
    assert row["learners"]["MaskablePPO"]["mean"] >= 0.5
    for name, learner in row["learners"].items():
        assert len(learner["scores"]) == 1 and math.isnan(learner["ci95"]), name  # one seed
        assert max(learner["scores"]) <= 1 + 1e-12, name  # feasible: never above the optimum
    assert "| ieee14-rtu | bus | 14, 13 | 3, 3 | logdet | 42 |" in text


def test_order_study_rows_per_instance_order_and_seed(monkeypatch):
    from fdia_env.scenarios import get

    # a small system under the instance's key: the study's loop, not the grid build, is tested
    small = ("ch4-position", "meter", lambda: get("ch4-position").system)
    monkeypatch.setitem(sparse_grid.SYSTEMS, "ieee14-rtu", small)
    inst = Instance("ieee14-rtu", 1, 2, "trace")
    rows = sparse_grid.order_study((inst,), orders=("time",), seeds=(0,), steps=64)
    assert [(r["order"], r["seed"]) for r in rows] == [("time", 0)]
    for r in rows:
        assert r["instance"] == "ieee14-rtu c=1 N=2 trace"
        assert 0 < r["score"] <= 1 + 1e-12 and 0 < r["sfs"] <= 1 + 1e-12


def test_plot_curves_writes_the_learning_curve_figure(tmp_path):
    row = {
        "optimum": 2.0,
        "objective": "trace",
        "instance": "toy",
        "heuristic_scores": {"SFS": 0.9},
        "learners": {
            "MaskablePPO": {"runs": [{"curve": [[10, 1.0], [100, 1.8]]}]},
            "torch PPO": {"runs": [{"curve": [[10, 0.5], [100, 2.0]]}]},
        },
    }
    path = sparse_grid.plot_curves(row, tmp_path / "curve.png")
    assert path == tmp_path / "curve.png"
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.parametrize("objective", ["trace", "logdet"])
def test_last_step_values_equal_the_problem_evaluation_of_every_set(objective):
    from baselines.sparse import make_problem
    from baselines.sparse.testbeds import dc_grid14

    system = dc_grid14(14)
    sets, values = sparse_grid.last_step_values(system, 3, 2, objective)
    assert sets.shape == (math.comb(14, 3), 3)
    problem = make_problem(system, 3, 2, objective)
    expected = [problem.evaluate([(1, int(i)) for i in s]) for s in sets]
    np.testing.assert_allclose(values, expected, rtol=1e-10)
    with pytest.raises(ValueError, match="budget"):
        sparse_grid.last_step_values(system, 0, 2)
    with pytest.raises(ValueError, match="objective"):
        sparse_grid.last_step_values(system, 2, 2, "max")


def test_landscape_of_dc_ieee14_50_has_one_set_at_99_percent():
    text = sparse_grid.landscape("dc-ieee14-50")
    # the best last-step set is branch and bound's proved optimum (tests/test_bnb.py)
    assert "best 0.000176854543 (sensors [6, 7, 13, 27, 47], 0-based), SFS 98.51%" in text
    assert "4 sets beat SFS, 1 reach 99 %" in text
    # 3 of the 4 meters that see bus 8 are worth at most 59.85 %, all 4 at least 96.32 %
    assert "| 3 | 4,140 | 59.85% | 43.73% |" in text
    assert "| 4 | 46 | 100.00% | 96.32% |" in text


def test_the_replay_in_v0_returns_sfs_value_without_an_out_of_date_notice():
    import warnings

    inst = sparse_grid.QUICK_INSTANCE
    system = sparse_grid.SYSTEMS[inst.system][2]()
    result = sfs(system, inst.budget, inst.horizon, inst.objective)
    with warnings.catch_warnings():
        warnings.simplefilter("error", DeprecationWarning)  # v0 is built on purpose
        value = sparse_grid.replay_native(result, system, inst)
    assert value == pytest.approx(result.value, rel=1e-12)
