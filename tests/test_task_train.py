"""``train.py attacker|defender --task NAME``: the task's env, its learners, one score scale."""

import json
import sys
from pathlib import Path

import pytest
from stable_baselines3.common.vec_env import DummyVecEnv

from agents.algos import build_model
from agents.bench.score import main as score_main
from agents.config import TrainConfig, algo_kwargs
from agents.training import env_thunk, task_setup
from fdia_env import tasks

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # train.py lives at the root
TINY = ["--no-progress-bar", "--final-eval-episodes", "2", "--eval-freq", "0"]
STEPS = ["--total-timesteps", "128", "--n-steps", "64", "--batch-size", "32", "--n-epochs", "1"]
NON_GAME = [n for n in tasks.names() if not tasks.get(n).is_game]
GAME = next(n for n in tasks.names() if tasks.get(n).is_game)


def train_main(argv):
    import train

    return train.main(argv)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    return tmp_path_factory.mktemp("task-runs")


@pytest.mark.parametrize(
    ("command", "task", "algo"),
    [
        ("attacker", "sparse/ch4-position-v0", "MaskablePPO"),
        ("attacker", "system-family/tracking-m6-v0", "PPO"),
        ("attacker", "covariance/ch2-position-v0", "PPO"),
        ("defender", "detection-game/ch3-static-defender-v0", "PPO"),
        ("defender", "stealth/ch4-position-dynamic-protect-defender-v0", "A2C"),
        ("attacker", "covariance/ch2-pv-1-v0", "torch-ppo"),
        # every other learner that fits an action space: Discrete, Box, MultiBinary
        ("attacker", "sparse/tracking-m6-1000004-v0", "DQN"),
        ("attacker", "sparse/ch4-pv-case1-logdet-v0", "A2C"),
        ("attacker", "sparse/tracking-m6-1000004-v0", "torch-ppo"),
        ("attacker", "system-family/tracking-m6-v0", "torch-ppo"),
        ("attacker", "covariance/ch2-pv-2-v0", "SAC"),
        ("attacker", "covariance/ch2-position-logdet-v0", "A2C"),
        ("attacker", "stealth/ieee14-b3-v0", "PPO"),
    ],
)
def test_a_task_run_scores_as_agents_bench_score_on_its_folder(
    command, task, algo, runs, tmp_path, capsys
):
    replay = ["--learning-starts", "16", "--batch-size", "16"]  # gradient steps within 64
    extra = {
        "A2C": ["--n-steps", "8"],
        "DQN": replay,
        "SAC": replay,
        "torch-ppo": ["--num-envs", "8", "--n-steps", "4"],
    }.get(algo, [])
    steps = STEPS if algo in ("PPO", "MaskablePPO") else ["--total-timesteps", "64"]
    result = train_main(
        [command, "--task", task, "--algo", algo, *steps, *extra, *TINY, "--runs-root", str(runs)]
    )
    printed = capsys.readouterr().out
    scores = json.loads((result.run_dir / "scores.json").read_text())
    config = json.loads((result.run_dir / "config.json").read_text())
    # PPO: 2 rollouts of 64; torch-ppo: 2 iterations of 8 members x 4 steps
    assert scores["num_timesteps"] == (128 if algo in ("PPO", "MaskablePPO") else 64)
    assert config["resolved"]["task"] == task
    assert config["resolved"]["gym_id"] == tasks.get(task).env_id
    out = tmp_path / "bench.json"
    assert score_main(["--task", task, "--agent", str(result.run_dir), "--json", str(out)]) == 0
    bench = json.loads(out.read_text())
    # the same seeds, episodes and loader: the same numbers, to the last digit
    assert scores["task"]["normalised"] == bench["normalised"]
    assert scores["task"]["normalised_ci"] == bench["normalised_ci"]
    assert scores["task"]["mean"] == bench["mean"]
    assert scores["task"]["per_seed"] == bench["per_seed"]
    assert result.task_score.normalised == bench["normalised"]
    assert f"normalised {bench['normalised']:.4f}" in printed
    # the normalised score is printed before the table of raw returns
    assert printed.index("normalised") < printed.index("mean ± 95% CI")


def test_a_task_run_is_refused_on_another_task(runs, capsys):
    result = train_main(
        ["attacker", "--task", "sparse/ch4-position-v0", *STEPS, *TINY, "--runs-root", str(runs)]
    )
    capsys.readouterr()
    code = score_main(["--task", "sparse/ch4-position-long-v0", "--agent", str(result.run_dir)])
    assert code == 2
    assert "trained on task 'sparse/ch4-position-v0'" in capsys.readouterr().err
    config_path = result.run_dir / "config.json"
    config = json.loads(config_path.read_text())
    config["resolved"]["env_kwargs"]["budget"] = 4  # not the task's
    config_path.write_text(json.dumps(config))
    assert score_main(["--task", "sparse/ch4-position-v0", "--agent", str(result.run_dir)]) == 2
    assert "other env options" in capsys.readouterr().err


@pytest.mark.parametrize("name", NON_GAME)
def test_every_single_player_task_builds_its_env_and_learner(name):
    task = tasks.get(name)
    setup = task_setup(TrainConfig(agent=task.player, task=name))
    assert setup.entry.gym_id == task.env_id
    thunk = env_thunk(setup.entry.gym_id, setup.env_kwargs, make=setup.entry.make_env)
    vec = DummyVecEnv([thunk])
    try:
        model = build_model(setup.algo, vec, algo_kwargs(setup.algo, setup.hp), 0)
        assert model.action_space == task.make_env().action_space
        assert vec.envs[0].unwrapped.spec.id == task.env_id
    finally:
        vec.close()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["attacker", "--task", "sparse/ch4-postion-v0"], "close names: sparse/ch4-position-v0"),
        (["defender", "--task", "sparse/ch4-position-v0"], "train.py attacker --task"),
        (["attacker", "--task", GAME], "train.py game"),
        (["attacker", "--task", "sparse/ch4-position-v0", "--env", "sparse_attack_v0"], "--env "),
        (["attacker", "--task", "sparse/ch4-position-v0", "--scenario", "ch4-random"], "--scenar"),
        (
            ["attacker", "--task", "sparse/ch4-position-v0", "--env-kwargs", "budget", "4"],
            "--env-kwargs",
        ),
        (["attacker", "--task", "sparse/ch4-position-v0", "--algo", "SAC"], "--algo 'SAC'"),
        (["attacker", "--task", "covariance/ch2-position-v0", "--algo", "DQN"], "--algo 'DQN'"),
        (["attacker", "--task", "covariance/ch2-position-v0", "--algo", "Foo"], "is no learner"),
        (
            ["attacker", "--task", "covariance/ch2-position-v0", "--algo", "DQN"],
            "learners that fit: --algo SAC, PPO, A2C, torch-ppo, and --backend rllib (PPO)",
        ),
        (
            [
                "defender",
                "--task",
                "stealth/ch4-position-dynamic-protect-defender-v0",
                "--algo",
                "torch-ppo",
            ],
            "--algo 'torch-ppo' does not fit the action space of task "
            "stealth/ch4-position-dynamic-protect-defender-v0 (MultiBinary(3)); learners that "
            "fit: --algo PPO, A2C",
        ),
        (["attacker", "--task", "sparse/ch4-position-v0", "--num-envs", "4"], "--num-envs"),
        (
            [
                "defender",
                "--task",
                "detection-game/ch3-static-defender-v0",
                "--opponent",
                "equilibrium",
            ],
            "--opponent cannot be combined with --task",
        ),
        (["attacker", "--task", "sparse/ch4-position-v0", "--resume"], "nothing to resume"),
    ],
)
def test_bad_task_options_name_the_option(argv, message, tmp_path):
    with pytest.raises(ValueError, match=None) as info:
        train_main([*argv, "--runs-root", str(tmp_path)])
    assert message in str(info.value)
    assert not list(tmp_path.iterdir())  # refused before a run folder exists


def test_a_scenario_run_on_a_tasks_env_prints_that_tasks_normalised_score(runs, tmp_path, capsys):
    # the default attacker run (sparse_attack_v2, ch4-position: budget 5, horizon 6, trace) is
    # the env of sparse/ch4-position-v0: one scale, the one agents.bench score prints
    result = train_main(["attacker", *STEPS, *TINY, "--runs-root", str(runs)])
    printed = capsys.readouterr().out
    scores = json.loads((result.run_dir / "scores.json").read_text())
    out = tmp_path / "bench.json"
    task = "sparse/ch4-position-v0"
    assert score_main(["--task", task, "--agent", str(result.run_dir), "--json", str(out)]) == 0
    bench = json.loads(out.read_text())
    assert scores["task"]["task"] == task
    assert scores["task"]["normalised"] == bench["normalised"]
    assert f"the run's env is task {task}: normalised" in printed
    assert f"normalised {bench['normalised']:.4f}" in printed
    # another budget is no task's env: no task score, the table's ratio labelled as such
    capsys.readouterr()
    other = train_main(
        ["attacker", "--env-kwargs", "budget", "4", *STEPS, *TINY, "--runs-root", str(runs)]
    )
    printed = capsys.readouterr().out
    assert "task" not in json.loads((other.run_dir / "scores.json").read_text())
    assert "normalised" not in printed
    assert "% of reference" in printed


DISCRETE = ("MaskablePPO", "PPO", "A2C", "DQN", "torch-ppo")
BOX = ("SAC", "PPO", "A2C", "torch-ppo")
MULTI_BINARY = ("PPO", "A2C")
# (learners of --algo, whether --backend rllib fits), by task
LEARNERS = {
    "sparse/": (DISCRETE, True),
    "system-family/": (DISCRETE, True),
    "covariance/": (BOX, True),
    "detection-game/": (BOX, True),
    "stealth/ieee14-b3-v0": (MULTI_BINARY, False),
    "stealth/ieee14-box-": (MULTI_BINARY, False),
    "stealth/ch4-position-dynamic-bias-v0": (BOX, True),
    "stealth/ch4-position-dynamic-protect-defender-v0": (MULTI_BINARY, False),
}


def learners(name):
    found = [v for k, v in LEARNERS.items() if name.startswith(k)]
    assert len(found) == 1, f"a new task family: add {name} to LEARNERS"
    return found[0]


@pytest.mark.parametrize("name", NON_GAME)
def test_the_learners_that_fit_each_task(name):
    from agents.task_runs import algorithms_for, rllib_fits

    algos, rllib = learners(name)
    env = tasks.get(name).make_env()
    try:
        assert algorithms_for(env.action_space) == algos
        assert rllib_fits(env.action_space) is rllib
    finally:
        env.close()


TORCH_TASKS = [n for n in NON_GAME if "torch-ppo" in learners(n)[0]]


@pytest.mark.parametrize("name", TORCH_TASKS)
def test_torch_ppo_trains_on_every_task_whose_actions_it_fits(name):
    import numpy as np
    import torch

    from agents.task_runs import has_native_torch_env, task_torch_env
    from agents.torch_ppo import TorchPPOConfig, train_torch_ppo
    from agents.torch_vector import TorchVectorOf

    torch.set_num_threads(1)
    task = tasks.get(name)
    venv = task_torch_env(task, dict(task.env_kwargs), 2, "cpu")
    try:
        # the system family's env is an entry point: copies of it, the others natively
        assert isinstance(venv, TorchVectorOf) is (task.entry_point is not None)
        assert has_native_torch_env(task) is (task.entry_point is None)
        config = TorchPPOConfig(
            total_timesteps=8, num_envs=2, num_steps=4, num_minibatches=1, update_epochs=1
        )
        result = train_torch_ppo(venv, config, seed=0)
    finally:
        venv.close()
    assert result.timesteps == 8
    env = task.make_env()
    try:
        obs, info = env.reset(seed=0)
        masks = info.get("action_mask")
        action, _ = result.policy.predict(obs, deterministic=True, action_masks=masks)
        assert env.action_space.contains(np.asarray(action, dtype=env.action_space.dtype))
        if masks is not None:
            assert masks[int(action)]
    finally:
        env.close()


RESUMED = [
    # a generated tracking system: its scenario is an object that config.json records as text
    ("sparse/tracking-m6-1000004-v0", "PPO", STEPS, 128, 256),
    # the system family: an entry point env, trained on copies of it
    (
        "system-family/tracking-m6-v0",
        "torch-ppo",
        ["--num-envs", "4", "--n-steps", "8", "--total-timesteps", "32"],
        32,
        64,
    ),
]


@pytest.mark.parametrize(("task", "algo", "steps", "first", "total"), RESUMED)
def test_a_resumed_task_run_keeps_its_task_and_scores_as_agents_bench_score(
    task, algo, steps, first, total, runs, tmp_path, capsys
):
    argv = ["attacker", "--task", task, "--algo", algo, *steps, *TINY, "--runs-root", str(runs)]
    started = train_main(argv)
    scores = json.loads((started.run_dir / "scores.json").read_text())
    assert scores["num_timesteps"] == first
    capsys.readouterr()
    # resumed without --task: the run's task is kept (config.json's), its env rebuilt
    resumed = train_main(
        ["attacker", "--resume", "--run-dir", str(started.run_dir), "--total-timesteps", str(total)]
    )
    printed = capsys.readouterr().out
    assert resumed.run_dir == started.run_dir and resumed.resumed
    assert f"resuming {started.run_dir} from its " in printed
    scores = json.loads((resumed.run_dir / "scores.json").read_text())
    config = json.loads((resumed.run_dir / "config.json").read_text())
    assert scores["num_timesteps"] == total
    assert config["config"]["task"] == task and config["resolved"]["task"] == task
    out = tmp_path / "bench.json"
    assert score_main(["--task", task, "--agent", str(resumed.run_dir), "--json", str(out)]) == 0
    bench = json.loads(out.read_text())
    assert scores["task"]["normalised"] == bench["normalised"]
    assert scores["task"]["per_seed"] == bench["per_seed"]
    assert resumed.task_score.normalised == bench["normalised"]
    assert f"normalised {bench['normalised']:.4f}" in printed


def test_a_resume_refuses_another_task_naming_the_option(runs, capsys):
    task, other = "covariance/ch2-pv-1-v0", "covariance/ch2-pv-2-v0"
    steps = ["--algo", "PPO", "--total-timesteps", "64", "--n-steps", "64", "--batch-size", "32"]
    run = train_main(["attacker", "--task", task, *steps, *TINY, "--runs-root", str(runs)])
    plain = train_main(
        ["attacker", "--env", "covariance_attack_v0", "--scenario", "ch2-pv-1", *steps, *TINY,
         "--runs-root", str(runs)]
    )  # fmt: skip
    capsys.readouterr()
    before = (run.run_dir / "scores.json").read_text()
    resume = ["attacker", "--resume", "--total-timesteps", "128"]
    with pytest.raises(ValueError) as info:
        train_main([*resume, "--run-dir", str(run.run_dir), "--task", other])
    assert f"--task {other}: {run.run_dir} was trained on task {task}" in str(info.value)
    with pytest.raises(ValueError) as info:
        train_main([*resume, "--run-dir", str(plain.run_dir), "--task", task])
    assert f"--task {task}: {plain.run_dir} was trained without --task" in str(info.value)
    # a config.json whose record is not the task's env cannot rebuild it
    config_path = run.run_dir / "config.json"
    config = json.loads(config_path.read_text())
    config["resolved"]["env_kwargs"]["power"] = 100.0
    config_path.write_text(json.dumps(config))
    with pytest.raises(ValueError) as info:
        train_main([*resume, "--run-dir", str(run.run_dir)])
    assert f"records another env than task {task} builds" in str(info.value)
    assert (run.run_dir / "scores.json").read_text() == before  # nothing trained or rewritten


def test_rllib_on_a_task_without_ray_names_the_extra(monkeypatch, tmp_path):
    import importlib.util

    from agents.rllib import MissingExtraError

    real = importlib.util.find_spec
    monkeypatch.setattr(
        importlib.util,
        "find_spec",
        lambda name, *a: None if name.split(".")[0] == "ray" else real(name, *a),
    )
    argv = ["attacker", "--task", "sparse/ch4-position-v0", "--backend", "rllib"]
    with pytest.raises(MissingExtraError, match=r"fdia-env\[rllib\]"):
        train_main([*argv, "--runs-root", str(tmp_path)])
    assert not list(tmp_path.iterdir())
