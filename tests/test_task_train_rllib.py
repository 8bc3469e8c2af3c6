"""``train.py attacker|defender --task NAME --backend rllib``: RLlib PPO on a task's env.

Needs the fdia-env[rllib] extra (skipped without it; tests/test_task_train.py checks the error
without Ray). One local Ray with 2 CPUs serves the module; each run is one PPO iteration of 64
steps, scored as ``python -m agents.bench score`` scores its folder.
"""

import json
import sys
from pathlib import Path

import pytest

from agents.bench.score import main as score_main

pytest.importorskip("ray.rllib", reason="needs the fdia-env[rllib] extra (ray[rllib])")

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # train.py lives at the root
TINY = ["--no-progress-bar", "--final-eval-episodes", "2", "--eval-freq", "0"]
STEPS = ["--n-steps", "64", "--batch-size", "32", "--n-epochs", "1"]


@pytest.fixture(scope="module")
def local_ray():
    import ray

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


def train_main(argv):
    import train

    return train.main(argv)


def bench_score(task, run_dir, out):
    assert score_main(["--task", task, "--agent", str(run_dir), "--json", str(out)]) == 0
    return json.loads(out.read_text())


@pytest.mark.parametrize(
    "task",
    [
        "sparse/ch4-position-v0",  # masked Discrete actions
        "system-family/tracking-m6-v0",  # an entry point env (no Gymnasium view)
        "detection-game/ch3-static-defender-v0",  # Box actions, the defender
    ],
)
def test_an_rllib_task_run_scores_as_agents_bench_score(task, local_ray, tmp_path, capsys):
    from fdia_env import tasks

    player = tasks.get(task).player
    argv = [player, "--task", task, "--backend", "rllib", "--total-timesteps", "64", *STEPS]
    result = train_main([*argv, *TINY, "--runs-root", str(tmp_path / "runs")])
    printed = capsys.readouterr().out
    assert result.timesteps == 64
    config = json.loads((result.run_dir / "config.json").read_text())
    assert config["resolved"]["backend"] == "rllib"
    assert config["resolved"]["task"] == task
    assert config["resolved"]["env"] == tasks.get(task).env_id
    scores = json.loads((result.run_dir / "scores.json").read_text())
    bench = bench_score(task, result.run_dir, tmp_path / "bench.json")
    assert scores["task"]["normalised"] == bench["normalised"]
    assert scores["task"]["per_seed"] == bench["per_seed"]
    assert result.task_score.normalised == bench["normalised"]
    assert f"task {task}: normalised {bench['normalised']:.4f}" in printed


def test_an_rllib_task_run_resumes_on_its_task(local_ray, tmp_path, capsys):
    task = "sparse/ch4-position-v0"
    runs = ["--runs-root", str(tmp_path / "runs")]
    argv = ["attacker", "--task", task, "--backend", "rllib", *STEPS, *TINY, *runs]
    first = train_main([*argv, "--total-timesteps", "64"])
    with pytest.raises(ValueError) as info:  # another task: refused, naming the option
        train_main(
            ["attacker", "--backend", "rllib", "--resume", "--run-dir", str(first.run_dir),
             "--task", "sparse/ch4-position-long-v0", "--total-timesteps", "128"]
        )  # fmt: skip
    assert f"--task sparse/ch4-position-long-v0: {first.run_dir} was trained on task {task}" in (
        str(info.value)
    )
    capsys.readouterr()
    resumed = train_main(
        ["attacker", "--backend", "rllib", "--resume", "--run-dir", str(first.run_dir),
         "--total-timesteps", "128"]
    )  # fmt: skip
    printed = capsys.readouterr().out
    assert resumed.run_dir == first.run_dir and resumed.resumed
    assert "from its state after 1 iteration, 64 steps" in printed
    assert resumed.timesteps == 128 and len(resumed.history) == 2
    scores = json.loads((resumed.run_dir / "scores.json").read_text())
    assert scores["timesteps"] == 128
    bench = bench_score(task, resumed.run_dir, tmp_path / "bench.json")
    assert scores["task"]["normalised"] == bench["normalised"]
    assert scores["task"]["per_seed"] == bench["per_seed"]


def test_rllib_refuses_a_task_whose_actions_it_does_not_fit(local_ray, tmp_path):
    task = "stealth/ch4-position-dynamic-protect-defender-v0"
    with pytest.raises(ValueError) as info:
        train_main(["defender", "--task", task, "--backend", "rllib", "--runs-root", str(tmp_path)])
    assert (
        f"--backend rllib (PPO) does not fit the action space of task {task} (MultiBinary(3)); "
        "learners that fit: --algo PPO, A2C (--backend sb3)"
    ) in str(info.value)
    assert not list(tmp_path.iterdir())
