"""train.py: every command end to end with a tiny budget, resume, and the errors users see."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # train.py lives at the root

import train
from baselines.game import exploitability, payoff_matrix

TINY = ["--no-progress-bar", "--final-eval-episodes", "3", "--eval-episodes", "2"]
TINY_PPO = ["--n-steps", "64", "--batch-size", "32", "--n-epochs", "2"]


def run(tmp_path, *args):
    return train.main([*args, "--runs-root", str(tmp_path / "runs")])


@pytest.mark.filterwarnings("error")  # the default env is the newest: no out-of-date notice
def test_attacker_command_writes_a_complete_run_folder(tmp_path, capsys):
    result = run(
        tmp_path, "attacker", "--total-timesteps", "128", "--eval-freq", "64",
        "--checkpoint-freq", "64", *TINY, *TINY_PPO,
    )  # fmt: skip
    run_dir = result.run_dir
    assert run_dir.parent == tmp_path / "runs"
    assert run_dir.name.startswith("sparse_attack_v2-MaskablePPO-s0-")
    for name in ("config.json", "scores.json", "learning_curve.png", "model.json", "model.pt"):
        assert (run_dir / name).is_file(), name
    assert list((run_dir / "tb").glob("events.out.tfevents.*"))
    assert json.loads((run_dir / "checkpoints" / "state.json").read_text())["timesteps"] == 128
    config = json.loads((run_dir / "config.json").read_text())
    assert config["resolved"]["algo"] == "MaskablePPO"
    assert config["resolved"]["hyperparameters"]["n_steps"] == 64
    scores = json.loads((run_dir / "scores.json").read_text())["evaluations"]
    assert {"learned (MaskablePPO)", "EXS", "random"} <= set(scores)
    assert scores["EXS"]["score"] == pytest.approx(1.0, rel=1e-12)
    history = [
        json.loads(line) for line in (run_dir / "evaluations.jsonl").read_text().splitlines()
    ]
    assert [h["timesteps"] for h in history] == [64, 128]
    out = capsys.readouterr().out
    assert "reference (EXS)" in out and "learned (MaskablePPO)" in out and "100.00%" in out


def test_covariance_attacker_trains_with_sac(tmp_path):
    result = run(
        tmp_path, "attacker", "--env", "covariance_attack_v0", "--algo", "sac",
        "--total-timesteps", "96", "--learning-starts", "32", "--batch-size", "16",
        "--eval-freq", "0", *TINY,
    )  # fmt: skip
    assert result.model.num_timesteps == 96
    assert result.evaluations["trace-optimal"].score == pytest.approx(1.0, rel=1e-12)
    assert (result.run_dir / "checkpoints" / "replay_buffer_96.npz").is_file()


def test_defender_command_scores_exploitability(tmp_path):
    result = run(
        tmp_path, "defender", "--algo", "DQN", "--total-timesteps", "64",
        "--learning-starts", "16", "--eval-freq", "0", *TINY,
    )  # fmt: skip
    learned = result.evaluations["learned (DQN)"]
    assert result.run_dir.name.startswith("sensor_game_v0-defender-DQN-s0-")
    assert learned.score_name == "exploitability"
    assert result.evaluations["game value (LP)"].score == pytest.approx(0.0, abs=1e-9)
    L = payoff_matrix("ch5-game")
    pure = learned.strategy
    assert pure.sum() == 1 and pure.max() == 1  # a deterministic policy is a pure strategy
    assert learned.score == pytest.approx((pure @ L).max() - 8.106030777100386, abs=1e-6)


def test_game_command_reports_exploitability_every_iteration(tmp_path, capsys):
    result = run(
        tmp_path, "game", "--method", "psro", "--iterations", "2",
        "--steps-per-iteration", "64", *TINY_PPO, "--no-progress-bar",
        "--final-eval-episodes", "3",
    )  # fmt: skip
    L = payoff_matrix("ch5-game")
    assert [h["iteration"] for h in result.history] == [1, 2]
    for h in result.history:
        e = exploitability(L, h["x"], h["y"])
        assert h["nash_conv"] == pytest.approx(e.nash_conv, abs=1e-9)
    assert np.allclose(result.x, result.history[-1]["x"])
    assert (result.run_dir / "learning_curve.png").is_file()
    assert len(list((result.run_dir / "policies").glob("*.pt"))) == 4
    out = capsys.readouterr().out
    assert out.count("NashConv") >= 3 and "defender LP equilibrium" in out


def test_resume_continues_the_same_run(tmp_path):
    args = ["attacker", "--algo", "PPO", "--eval-freq", "0", "--checkpoint-freq", "64",
            *TINY, *TINY_PPO]  # fmt: skip
    first = run(tmp_path, *args, "--total-timesteps", "128")
    adam_steps = first.model.policy.optimizer.state_dict()["state"][0]["step"].item()
    updates = first.model._n_updates
    second = run(tmp_path, "attacker", "--algo", "PPO", "--resume", "--total-timesteps", "256")
    assert second.resumed and second.run_dir == first.run_dir
    assert second.model.num_timesteps == 256
    assert second.model._n_updates == 2 * updates  # same schedule, continued
    assert second.model.policy.optimizer.state_dict()["state"][0]["step"].item() == 2 * adam_steps
    state = json.loads((first.run_dir / "checkpoints" / "state.json").read_text())
    assert state["timesteps"] == 256
    assert len(list((tmp_path / "runs").iterdir())) == 1


def test_resume_refuses_different_options(tmp_path):
    first = run(tmp_path, "attacker", "--total-timesteps", "64", "--eval-freq", "0", *TINY,
                *TINY_PPO)  # fmt: skip
    with pytest.raises(ValueError, match="n-steps: saved 64, given 32"):
        run(tmp_path, "attacker", "--resume", "--run-dir", str(first.run_dir), "--n-steps", "32")


def test_a_run_of_an_older_sparse_version_still_resumes(tmp_path):
    args = ["--algo", "PPO", "--eval-freq", "0", "--checkpoint-freq", "64", *TINY, *TINY_PPO]
    first = run(tmp_path, "attacker", "--env", "sparse_attack_v0", *args,
                "--total-timesteps", "64")  # fmt: skip
    assert first.run_dir.name.startswith("sparse_attack_v0-PPO-s0-")
    # the latest run of the default env (the newest version) is another prefix
    with pytest.raises(ValueError, match=r"no run folder .*sparse_attack_v2-PPO-s0-\*"):
        run(tmp_path, "attacker", "--resume", *args)
    # by name, or by its folder (whose saved options, the env's name included, are the defaults)
    second = run(tmp_path, "attacker", "--env", "sparse_attack_v0", "--resume", *args,
                 "--total-timesteps", "128")  # fmt: skip
    third = run(tmp_path, "attacker", "--resume", "--run-dir", str(first.run_dir), *args,
                "--total-timesteps", "192")  # fmt: skip
    assert second.run_dir == third.run_dir == first.run_dir
    assert (second.model.num_timesteps, third.model.num_timesteps) == (128, 192)
    config = json.loads((first.run_dir / "config.json").read_text())
    assert config["config"]["env"] == "sparse_attack_v0"


def test_an_existing_run_folder_is_an_error_without_resume(tmp_path):
    (tmp_path / "taken").mkdir()
    with pytest.raises(FileExistsError, match="pass --resume"):
        run(tmp_path, "attacker", "--run-dir", str(tmp_path / "taken"), *TINY)
    with pytest.raises(ValueError, match="nothing to resume"):
        run(tmp_path, "attacker", "--resume", *TINY)


def test_detection_defender_is_scored_against_obdd(tmp_path):
    result = run(
        tmp_path, "defender", "--env", "detection_game_v0", "--algo", "SAC",
        "--total-timesteps", "48", "--learning-starts", "16", "--batch-size", "16",
        "--eval-freq", "0", *TINY,
    )  # fmt: skip
    assert result.run_dir.name.startswith("detection_game_v0-defender-SAC-s0-")
    obdd = result.evaluations["OBDD α (Bayes cost)"]
    assert obdd.score == pytest.approx(1.0, rel=1e-7)  # α through a float32 action
    learned = result.evaluations["learned (SAC)"]
    assert 0.0 < learned.score <= 1.0 + 1e-7  # optimal cost / learned cost: α is optimal


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["attacker", "--env", "nope"], "unknown env 'nope'; envs with a learning attacker: "),
        (["defender", "--env", "covariance_attack_v0"], "learning defender: "),
        (["attacker", "--scenario", "ch5-game"], "valid scenarios: ch4-position"),
        (["attacker", "--algo", "SAC"], "valid algorithms: MaskablePPO, PPO, A2C, DQN"),
        (["game", "--env", "sparse_attack_v0"], "valid games: sensor_game_v0"),
        (["game", "--algo", "SAC"], "valid algorithms: PPO, A2C, DQN"),
    ],
)
def test_unknown_names_are_errors_listing_the_valid_ones(tmp_path, args, message):
    with pytest.raises(ValueError, match=message):
        run(tmp_path, *args)
    assert not (tmp_path / "runs").exists()  # nothing written


def test_help_lists_every_option_with_its_default(capsys):
    with pytest.raises(SystemExit) as exc:
        train.main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for option in ("--total-timesteps", "--resume", "--learning-rate", "--method",
                   "--steps-per-iteration", "--run-dir", "--scenario"):  # fmt: skip
        assert option in out, option
    flat = " ".join(out.split())  # the help is wrapped to the terminal's width
    assert "(default: 100000)" in flat and "(default: psro)" in flat
    assert "--trust-checkpoint" in out


def test_game_resume_continues_the_iterations(tmp_path):
    args = ["game", "--steps-per-iteration", "64", *TINY_PPO, "--no-progress-bar",
            "--final-eval-episodes", "3"]  # fmt: skip
    first = run(tmp_path, *args, "--iterations", "1")
    second = run(tmp_path, "game", "--resume", "--iterations", "2")
    assert second.run_dir == first.run_dir
    assert [h["iteration"] for h in second.history] == [1, 2]
    assert second.history[0] == first.history[0]
    assert len(second.populations["attacker"]) == 2
