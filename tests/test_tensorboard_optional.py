"""TensorBoard is the ``tensorboard`` extra: training without it is the same run, minus tb/."""

import json
import sys
from pathlib import Path

import pytest
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # train.py lives at the root

import train
from agents import lifecycle

TINY = ["--no-progress-bar", "--final-eval-episodes", "2", "--eval-episodes", "1"]
TINY_PPO = ["--algo", "PPO", "--n-steps", "64", "--batch-size", "32", "--n-epochs", "1"]
ATTACKER = ["attacker", *TINY_PPO, "--total-timesteps", "128", "--eval-freq", "64",
            "--checkpoint-freq", "64", *TINY]  # fmt: skip
GAME = ["game", "--method", "psro", "--algo", "exact", "--iterations", "2", *TINY[:3]]


def without_tensorboard(monkeypatch):
    """Make ``tensorboard`` (and torch's wrapper of it) unimportable, as in a core install."""
    for name in ("tensorboard", "torch.utils.tensorboard"):
        monkeypatch.setitem(sys.modules, name, None)
    lifecycle._notice_no_tensorboard.cache_clear()


def history(run_dir: Path) -> list[dict]:
    """evaluations.jsonl without the wall times."""
    lines = (run_dir / "evaluations.jsonl").read_text().splitlines()
    return [{k: v for k, v in json.loads(s).items() if k != "train_seconds"} for s in lines]


def test_training_without_tensorboard_is_the_same_run_without_tb_and_one_notice(
    tmp_path, monkeypatch, capsys
):
    pytest.importorskip("tensorboard")  # the reference run writes the logs
    logged = train.main([*ATTACKER, "--runs-root", str(tmp_path / "with")])
    assert list((logged.run_dir / "tb").glob("events.out.tfevents.*"))
    assert lifecycle.TENSORBOARD_NOTICE not in capsys.readouterr().err

    without_tensorboard(monkeypatch)
    assert not lifecycle.tensorboard_installed()
    bare = train.main([*ATTACKER, "--runs-root", str(tmp_path / "without")])
    game = train.main([*GAME, "--runs-root", str(tmp_path / "without")])
    err = capsys.readouterr().err
    assert err.count(lifecycle.TENSORBOARD_NOTICE) == 1, err
    assert 'pip install "fdia-env[tensorboard]"' in lifecycle.TENSORBOARD_NOTICE
    assert not (bare.run_dir / "tb").exists() and not (game.run_dir / "tb").exists()
    assert sys.modules["torch.utils.tensorboard"] is None  # never imported

    # the same weights, checkpoints, evaluations and scores
    assert bare.model.num_timesteps == logged.model.num_timesteps == 128
    theirs = logged.model.policy.state_dict()
    for key, value in bare.model.policy.state_dict().items():
        assert torch.equal(value, theirs[key]), key
    files = {p.name for p in (logged.run_dir / "checkpoints").iterdir()}
    assert files == {p.name for p in (bare.run_dir / "checkpoints").iterdir()}
    assert [h["timesteps"] for h in history(bare.run_dir)] == [64, 128]
    assert history(bare.run_dir) == history(logged.run_dir)
    assert bare.evaluations.keys() == logged.evaluations.keys()
    for name, ev in bare.evaluations.items():
        ref = logged.evaluations[name]
        assert (ev.mean, ev.score, list(ev.returns)) == (ref.mean, ref.score, list(ref.returns))
    assert [h["iteration"] for h in game.history] == [1, 2]
    assert (game.run_dir / "state.json").is_file()
