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
    ],
)
def test_a_task_run_scores_as_agents_bench_score_on_its_folder(
    command, task, algo, runs, tmp_path, capsys
):
    extra = {"A2C": ["--n-steps", "8"], "torch-ppo": ["--num-envs", "8"]}.get(algo, [])
    steps = STEPS if algo in ("PPO", "MaskablePPO") else ["--total-timesteps", "64"]
    result = train_main(
        [command, "--task", task, "--algo", algo, *steps, *extra, *TINY, "--runs-root", str(runs)]
    )
    printed = capsys.readouterr().out
    scores = json.loads((result.run_dir / "scores.json").read_text())
    config = json.loads((result.run_dir / "config.json").read_text())
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
            ["attacker", "--task", "system-family/tracking-m6-v0", "--algo", "torch-ppo"],
            "--algo torch-ppo on --task system-family/tracking-m6-v0",
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
        (["attacker", "--task", "sparse/ch4-position-v0", "--resume"], "--resume"),
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
