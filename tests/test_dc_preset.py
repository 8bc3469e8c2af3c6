"""The ``dc-ieee14-50`` scenario preset: the 300-pair DC IEEE 14 instance, trainable by train.py.

The preset is :func:`fdia_env.systems.grid.dc14.dc_grid14` with 50 meters, c = 5, N = 6 (the
trace: the sparse env's default objective); branch and bound proves its optimum (meters 6, 7,
13, 27 and 47, 0-based, at the last window step), and SFS's set keeps a single one of them.
"""

import json
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # train.py lives at the root

import train
from agents.config import SCENARIO_DEFAULTS, SPARSE_ENVS, Hyperparameters
from agents.training import run_setup
from baselines.sparse import exhaustive, make_problem, testbeds
from fdia_env import scenarios
from fdia_env.envs.sequential import PlanOrderPolicy
from fdia_env.systems.grid import dc14

OPTIMUM = 0.00017685454306509148  # branch and bound's proved optimum (tests/test_bnb.py)
BNB_SET = ((5, 6), (5, 7), (5, 13), (5, 27), (5, 47))
SFS_SET = ((5, 8), (5, 12), (5, 13), (5, 30), (5, 33))


def test_the_preset_is_the_testbed_system():
    sc = scenarios.get("dc-ieee14-50")
    assert (sc.name, sc.budget, sc.horizon, sc.steady_state) == ("dc-ieee14-50", 5, 6, True)
    assert testbeds.dc_grid14 is dc14.dc_grid14  # one builder, re-exported for the benchmarks
    built = dc14.dc_grid14(50)
    assert sc.system.name == built.name == "dc-ieee14-50"
    for attr in ("F", "Q", "H", "R", "x0", "P0", "J"):
        np.testing.assert_array_equal(getattr(sc.system, attr), getattr(built, attr))
    assert (sc.system.M, sc.system.n) == (50, 13)
    # the model's own numbers: bus 1's injection row is b_12 + b_15 on θ2's and θ5's columns
    assert sc.system.sensors[0].H[0, 0] == pytest.approx(-1 / 0.05917)
    assert sc.system.R[0, 0] == pytest.approx(0.02**2)


def _play(env: gym.Env, attacks) -> float:
    policy = PlanOrderPolicy(attacks, num_sensors=50, horizon=6)
    obs, _ = env.reset(seed=0)
    total, done = 0.0, False
    while not done:
        action, _ = policy.predict(obs)
        obs, reward, terminated, truncated, _ = env.step(int(action))
        total, done = total + float(reward), terminated or truncated
    return total


def test_the_env_on_the_preset_returns_the_certified_values():
    env = gym.make("fdia_env/SparseAttack-v2", scenario="dc-ieee14-50")
    assert env.action_space.n == 6 * 50 + 1  # the plan-first order over 300 pairs, then stop
    problem = make_problem(testbeds.dc_grid14(50), 5, 6)
    assert _play(env, BNB_SET) == pytest.approx(OPTIMUM, rel=1e-10)
    assert _play(env, SFS_SET) == pytest.approx(problem.evaluate(list(SFS_SET)), rel=1e-10)
    assert _play(env, SFS_SET) / OPTIMUM == pytest.approx(0.98508, abs=1e-5)


def test_train_py_takes_the_preset_with_its_table_defaults():
    defaults = SCENARIO_DEFAULTS["sparse_attack_v2", "dc-ieee14-50"]
    for env in SPARSE_ENVS:  # every version trains the preset in the same format
        setup = run_setup(env, "attacker", "dc-ieee14-50", {}, None, Hyperparameters())
        assert setup.env_kwargs == {
            "scenario": "dc-ieee14-50", "action": "sequential", "order": "plan", "groups": "state",
        }  # fmt: skip
        assert setup.algo == defaults.algo and setup.normalize_reward
        for name, value in defaults.hyperparameters.items():
            if name in ("norm_obs",):  # torch-ppo only
                continue
            assert getattr(setup.hp, name) == value
    assert defaults.hyperparameters["ent_coef"] == 0.05  # the grid presets' 0.01 otherwise
    torch = run_setup("sparse_attack_v2", "attacker", "dc-ieee14-50", {}, "torch-ppo",
                      Hyperparameters())  # fmt: skip
    assert (torch.hp.ent_coef, torch.hp.norm_obs) == (0.05, False)
    # without the groups (the plan-first order pair by pair) the rest of the table still applies
    pairs = run_setup("sparse_attack_v2", "attacker", "dc-ieee14-50", {"groups": None}, None,
                      Hyperparameters())  # fmt: skip
    assert pairs.env_kwargs["groups"] is None and pairs.hp.ent_coef == 0.05
    # the command line wins over the table
    given = run_setup(
        "sparse_attack_v2", "attacker", "dc-ieee14-50", {}, "PPO", Hyperparameters(ent_coef=0.0)
    )
    assert (given.algo, given.hp.ent_coef) == ("PPO", 0.0)


def test_attacker_command_trains_on_the_preset(tmp_path, capsys):
    # a smaller window of the same system (c = 2, N = 1: EXS over 50 meters is the reference;
    # the preset's own c = 5, N = 6 takes branch and bound, about 15-25 s here)
    result = train.main(
        [
            "attacker", "--scenario", "dc-ieee14-50", "--env-kwargs", "budget", "2", "horizon",
            "1", "--total-timesteps", "64", "--n-steps", "32", "--batch-size", "16",
            "--n-epochs", "1", "--no-progress-bar", "--final-eval-episodes", "2",
            "--eval-freq", "0", "--runs-root", str(tmp_path / "runs"),
        ]
    )  # fmt: skip
    config = json.loads((result.run_dir / "config.json").read_text())["resolved"]
    assert config["env_kwargs"]["scenario"] == "dc-ieee14-50"
    assert (config["env_kwargs"]["action"], config["env_kwargs"]["order"]) == ("sequential", "plan")
    assert config["env_kwargs"]["groups"] == "state"  # the state groups of the table
    assert config["hyperparameters"]["ent_coef"] == 0.05  # the table's, not MaskablePPO's 0.01
    best = exhaustive(testbeds.dc_grid14(50), budget=2, horizon=1).value
    norm = config["reward_normalization"]
    assert norm["shift"] + norm["scale"] == pytest.approx(best, rel=1e-12)
    rows = result.evaluations
    assert rows["EXS"].score == pytest.approx(1.0, rel=1e-12)
    assert 0.3 < rows[f"learned ({config['algo']})"].score <= 1.0 + 1e-12
    assert "reference (EXS)" in capsys.readouterr().out


def test_a_run_made_before_the_groups_resumes_with_its_own_options(tmp_path, capsys, monkeypatch):
    """train.py's defaults for the preset changed (the state groups, 8 native members); a run
    saved under the former ones resumes with what it was trained with, and says so."""
    from dataclasses import replace

    key = ("sparse_attack_v2", "dc-ieee14-50")
    today = SCENARIO_DEFAULTS[key]
    former = replace(today, env_kwargs={"action": "sequential", "order": "plan"}, num_envs=None)
    args = [
        "attacker", "--scenario", "dc-ieee14-50", "--env-kwargs", "budget", "2", "horizon", "1",
        "--total-timesteps", "64", "--n-epochs", "1", "--no-progress-bar",
        "--final-eval-episodes", "2", "--eval-freq", "0", "--run-dir", str(tmp_path / "run"),
    ]  # fmt: skip
    with monkeypatch.context() as patch:
        patch.setitem(SCENARIO_DEFAULTS, key, former)
        first = train.main(args)
    saved = json.loads((first.run_dir / "config.json").read_text())["resolved"]
    assert "groups" not in saved["env_kwargs"] and saved["num_envs"] is None
    assert saved["hyperparameters"]["n_steps"] == 512  # one env's rollout
    capsys.readouterr()
    again = train.main(["attacker", "--run-dir", str(first.run_dir), "--resume"])
    out = capsys.readouterr().out
    assert again.resumed and again.run_dir == first.run_dir
    assert "resuming with the run's own env options" in out and "'groups': 'state'" in out
    assert "resuming with the run's own native vector env members None" in out
    assert "'n_steps': 512" in out and "'n_steps': 128" in out  # saved, and today's default
    resumed = json.loads((again.run_dir / "config.json").read_text())["resolved"]
    for name in ("env_kwargs", "num_envs", "hyperparameters"):
        assert resumed[name] == saved[name]
    # the run's own options given again, --env-kwargs included, resume it as well
    assert train.main([*args, "--resume"]).run_dir == first.run_dir
    with pytest.raises(ValueError, match=r"options differ from its config\.json"):
        train.main([*args[:5], "3", *args[6:], "--resume"])  # budget 3: not the run's
    # a new run takes today's defaults
    fresh = train.main([*args[:-2], "--run-dir", str(tmp_path / "new")])
    config = json.loads((fresh.run_dir / "config.json").read_text())["resolved"]
    assert config["env_kwargs"]["groups"] == "state" and config["num_envs"] == 8


def test_torch_ppo_command_takes_the_table_and_a_resume_keeps_the_runs_own(
    tmp_path, capsys, monkeypatch
):
    """--algo torch-ppo trains with the preset's hyperparameters (ent_coef 0.05, no observation
    normalisation) and env options; a run saved under other defaults resumes with its own."""
    from dataclasses import replace

    import agents.torch_ppo_train as runner

    key = ("sparse_attack_v2", "dc-ieee14-50")
    today = SCENARIO_DEFAULTS[key]
    former = replace(today, hyperparameters={"ent_coef": 0.02, "norm_obs": True})
    args = [
        "attacker", "--scenario", "dc-ieee14-50", "--algo", "torch-ppo", "--device", "cpu",
        "--num-envs", "8", "--env-kwargs", "budget", "2", "horizon", "1",
        "--total-timesteps", "192", "--final-eval-episodes", "2", "--eval-freq", "0",
    ]  # fmt: skip
    fresh = train.main([*args, "--run-dir", str(tmp_path / "new")])
    config = json.loads((fresh.run_dir / "config.json").read_text())["resolved"]
    assert (config["hyperparameters"]["ent_coef"], config["hyperparameters"]["norm_obs"]) == (
        0.05,
        False,
    )
    assert config["env_kwargs"]["groups"] == "state"
    # a run stopped under former defaults resumes with its own hyperparameters, and says so
    real = runner.train_torch_ppo
    stopped = lambda *a, **k: real(*a, **{**k, "stop": lambda: True})  # noqa: E731
    with monkeypatch.context() as patch:
        patch.setitem(SCENARIO_DEFAULTS, key, former)
        patch.setattr(runner, "train_torch_ppo", stopped)
        first = train.main([*args, "--run-dir", str(tmp_path / "run")])
    saved = json.loads((first.run_dir / "config.json").read_text())["resolved"]
    assert saved["hyperparameters"]["ent_coef"] == 0.02 and saved["hyperparameters"]["norm_obs"]
    assert first.timesteps < 192
    capsys.readouterr()
    again = train.main(["attacker", "--run-dir", str(first.run_dir), "--resume"])
    out = capsys.readouterr().out
    assert again.resumed and again.timesteps == 192
    assert "resuming with the run's own hyperparameters" in out and "'ent_coef': 0.02" in out
    resumed = json.loads((again.run_dir / "config.json").read_text())["resolved"]
    assert resumed["hyperparameters"] == saved["hyperparameters"]
