"""``train.py game --task NAME``: a game task's game, both players, its player's score.

The run's ``scores.json`` carries the task's normalised score computed by the code of
``python -m agents.bench score``, which scores the game run folder (its player's final mix) to
the same number; exact double oracle, the default, reaches the stored game value.
"""

import contextlib
import io
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from agents.bench.score import main as score_main
from fdia_env import tasks

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # train.py lives at the root
TINY = ["--no-progress-bar", "--final-eval-episodes", "4"]
GAMES = [n for n in tasks.names() if tasks.get(n).is_game]
INFORMED = "incomplete-information/ch5-game-informed-attacker-v0"


def train_main(argv):
    import train

    return train.main(argv)


def bench(task, run_dir, out):
    """``python -m agents.bench score --task TASK --agent RUN_DIR --json OUT``'s JSON."""
    assert score_main(["--task", task, "--agent", str(run_dir), "--json", str(out)]) == 0
    return json.loads(out.read_text())


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    return tmp_path_factory.mktemp("game-task-runs")


def train_printed(argv):
    """``train_main(argv)`` and what it printed."""
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        result = train_main(argv)
    return result, out.getvalue()


@pytest.fixture(scope="module")
def ch5_run(runs):
    return train_printed(
        ["game", "--task", "sensor-game/ch5-game-attacker-v0", *TINY, "--runs-root", str(runs)]
    )


@pytest.mark.parametrize(
    "task",
    [
        "sensor-game/ch5-game-attacker-v0",
        "sensor-game/m10-strong-defender-v0",
        "incomplete-information/ch5-game-informed-attacker-v0",
    ],
)
def test_exact_double_oracle_reaches_the_game_value_and_scores_as_the_bench(
    task, ch5_run, runs, tmp_path
):
    if task == "sensor-game/ch5-game-attacker-v0":
        result, printed = ch5_run
    else:
        result, printed = train_printed(["game", "--task", task, *TINY, "--runs-root", str(runs)])
    spec = tasks.get(task)
    config = json.loads((result.run_dir / "config.json").read_text())
    assert config["resolved"]["task"] == task
    assert config["resolved"]["gym_id"] == spec.env_id
    assert config["resolved"]["algo"] == "exact"  # the default under --task
    assert config["resolved"]["env_kwargs"] == json.loads(json.dumps(dict(spec.env_kwargs)))
    scores = json.loads((result.run_dir / "scores.json").read_text())
    got = bench(task, result.run_dir, tmp_path / "bench.json")
    # the same loader, seeds and episodes: the same numbers, to the last digit
    for key in ("normalised", "normalised_ci", "per_seed", "mean", "raw", "extras"):
        assert scores["task"][key] == got[key], key
    assert result.task_score.normalised == got["normalised"]
    # double oracle stops at its fixed point, an equilibrium of the full game: the final mix's
    # worst-case return is the stored (independently computed) game value
    assert got["normalised"] >= 0.99
    assert got["normalised"] == pytest.approx(1.0, abs=1e-12)
    value = spec.references.optimum.value
    assert got["raw"] == pytest.approx(value, rel=1e-9)
    assert abs(scores["value"]) == pytest.approx(abs(value), rel=1e-9)  # the run's own LP
    last = result.history[-1]
    assert last["nash_conv"] <= 1e-9 * abs(value)
    assert len(result.history) < 40  # stopped at the fixed point, not at a cap
    # the printed score line comes before the final table
    assert f"task {task}: normalised {got['normalised']:.4f}" in printed
    assert printed.index("normalised") < printed.index("mean ± 95% CI")


def test_a_game_run_scores_the_other_player_of_its_game_and_no_other_task(
    ch5_run, tmp_path, capsys
):
    run_dir = ch5_run[0].run_dir
    other = bench("sensor-game/ch5-game-defender-v0", run_dir, tmp_path / "defender.json")
    assert other["normalised"] == pytest.approx(1.0, abs=1e-12)  # the defender's final mix
    final = json.loads((run_dir / "scores.json").read_text())
    assert f"{np.count_nonzero(final['x'])} of 7 actions" in other["description"]
    capsys.readouterr()
    assert score_main(["--task", "sensor-game/m10-attacker-v0", "--agent", str(run_dir)]) == 2
    assert "whose game is not task sensor-game/m10-attacker-v0's" in capsys.readouterr().err
    assert score_main(["--task", "sparse/ch4-position-v0", "--agent", str(run_dir)]) == 2
    assert "is not a game: score the run on a game task" in capsys.readouterr().err


def test_learned_best_responses_are_selectable_and_score_as_the_bench(runs, tmp_path, capsys):
    task = "sensor-game/ch5-game-defender-v0"
    argv = ["game", "--task", task, "--algo", "PPO", "--iterations", "2"]
    argv += ["--steps-per-iteration", "64", "--n-steps", "32", "--batch-size", "32"]
    result = train_main([*argv, "--n-epochs", "1", *TINY, "--runs-root", str(runs)])
    capsys.readouterr()
    assert len(result.history) == 2  # --iterations as given
    config = json.loads((result.run_dir / "config.json").read_text())
    assert (config["resolved"]["algo"], config["resolved"]["task"]) == ("PPO", task)
    scores = json.loads((result.run_dir / "scores.json").read_text())
    got = bench(task, result.run_dir, tmp_path / "bench.json")
    assert scores["task"]["normalised"] == got["normalised"]
    assert scores["task"]["normalised_ci"] == got["normalised_ci"]
    # the score is the final defender mix's exploitability on the task's matrix
    expl = result.history[-1]["defender"]
    assert got["extras"]["exploitability"] == pytest.approx(max(expl, 0.0), abs=1e-9)


def test_a_plain_game_run_on_a_tasks_game_scores_on_that_task(runs, tmp_path, capsys):
    argv = ["game", "--algo", "exact", "--scenario", "ch5-game", "--iterations", "3"]
    result = train_main([*argv, *TINY, "--runs-root", str(runs)])
    capsys.readouterr()
    got = bench("sensor-game/ch5-game-attacker-v0", result.run_dir, tmp_path / "bench.json")
    spec = tasks.get("sensor-game/ch5-game-attacker-v0")
    expected = spec.normalise_exploitability(max(result.history[-1]["attacker"], 0.0))
    assert got["normalised"] == pytest.approx(expected, abs=1e-9)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["game", "--task", "sensor-game/ch5-gme-attacker-v0"], "close names: sensor-game/ch5"),
        (["game", "--task", "sparse/ch4-position-v0"], "train.py attacker --task sparse/ch4"),
        (
            ["game", "--task", "sensor-game/ch5-game-attacker-v0", "--scenario", "game-m10"],
            "--scenario cannot be combined with --task",
        ),
        (
            ["game", "--task", "sensor-game/ch5-game-attacker-v0", "--env-kwargs", "power", "5"],
            "--env-kwargs cannot be combined with --task",
        ),
        (
            ["game", "--task", "sensor-game/ch5-game-attacker-v0", "--env", "fdia_v0"],
            "--env cannot be combined with --task",
        ),
        (
            ["game", "--task", "sensor-game/ch5-game-attacker-v0", "--algo", "SAC"],
            "--algo 'SAC' does not fit task sensor-game/ch5-game-attacker-v0",
        ),
        (
            ["game", "--task", INFORMED, "--algo", "PPO"],
            "it trains with --algo exact",
        ),
        (
            ["game", "--task", "sensor-game/ch5-game-attacker-v0", "--backend", "rllib"],
            "--backend rllib is not supported with --task",
        ),
        (["game", "--task", "sensor-game/ch5-game-attacker-v0", "--resume"], "--resume"),
        (["attacker", "--task", "sensor-game/m10-strong-defender-v0"], "train.py game --task"),
        (["defender", "--task", "sensor-game/m10-strong-defender-v0"], "train.py game --task"),
    ],
)
def test_bad_game_task_options_name_the_option(argv, message, tmp_path):
    with pytest.raises(ValueError) as info:
        train_main([*argv, "--runs-root", str(tmp_path)])
    assert message in str(info.value)
    assert not list(tmp_path.iterdir())  # refused before a run folder exists


@pytest.mark.parametrize("name", GAMES)
def test_every_game_task_builds_its_game_as_the_task_builds_it(name):
    from agents.config import GameConfig
    from agents.game_task_runs import game_task_setup

    setup = game_task_setup(GameConfig(task=name))
    spec = tasks.get(name)
    assert setup.algo == "exact"
    player = setup.entries[spec.player]
    assert player.gym_id == spec.env_id
    with player.make_resolved(setup.env_kwargs) as env, spec.make_env() as own:
        assert env.spec.id == own.spec.id
        assert env.spec.kwargs == own.spec.kwargs  # the task's options, no train.py preset
        assert env.action_space == own.action_space
    other = "defender" if spec.player == "attacker" else "attacker"
    with setup.entries[other].make_resolved(setup.env_kwargs) as env:
        assert env.unwrapped.agent == other


@pytest.mark.parametrize(("scenario", "most"), [("ch5-game", 10), ("game-m10", 40)])
def test_double_oracle_on_the_informed_game_ends_at_the_bayesian_lp_equilibrium(scenario, most):
    from agents.informed_game import run_informed_population
    from baselines.game import bayesian_game

    game = bayesian_game(scenario, ("independent", "dependent"), (0.5, 0.5), "informed", 100.0)
    history = run_informed_population("psro", game, 1000, converge=True)
    assert len(history) <= most  # its fixed point (ch5-game: 6 iterations, game-m10: 13)
    x, y = np.array(history[-1]["x"]), np.array(history[-1]["y"])
    assert y.shape == (2, game.matrices.shape[2])  # one mix per type
    value = game.solution.value  # the LP of baselines.game.lp.solve_bayesian
    assert game.payoff(x, y) == pytest.approx(value, rel=1e-9)
    assert game.defender_worst_case(x) == pytest.approx(value, rel=1e-9)
    assert game.attacker_worst_case(y) == pytest.approx(value, rel=1e-9)


def test_fictitious_play_on_the_informed_game_approaches_the_equilibrium():
    from agents.informed_game import run_informed_population
    from baselines.game import bayesian_game

    game = bayesian_game("ch5-game", ("independent", "dependent"), (0.5, 0.5), "informed", 100.0)
    history = run_informed_population("fsp", game, 200, converge=True)
    assert len(history) == 200  # the average moves with every answer: no fixed point
    nash_conv = [rec["nash_conv"] for rec in history]
    # 7.36 after the first answers, 0.30 (3 % of the value 9.727) after 200
    assert nash_conv[-1] < 0.05 * game.solution.value < nash_conv[0]
