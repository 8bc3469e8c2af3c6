"""experiments: one command line over the result tables and the literature reproduction."""

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from experiments import cli

ROOT = Path(__file__).resolve().parent.parent


def test_reproduce_runs_through_the_one_command_line(tmp_path, capsys):
    output = tmp_path / "reproduction.md"
    assert cli.main(["reproduce", "ch2", "--quick", "--output", str(output)]) == 0
    text = output.read_text()
    # the section records the command as the user types it
    assert "Command: `python -m experiments reproduce ch2 --quick --output" in text
    assert "## Chapter 2: attack covariances" in text and "**NO**" not in text
    assert "Chapter 2" in capsys.readouterr().out


def test_results_runs_through_the_one_command_line(capsys):
    with pytest.raises(SystemExit):  # argparse: unknown table, named in the message
        cli.main(["results", "nope"])
    assert "invalid choice: 'nope'" in capsys.readouterr().err


def test_unknown_command_is_named(capsys):
    with pytest.raises(SystemExit):
        cli.main(["train"])
    err = capsys.readouterr().err
    assert "invalid choice: 'train'" in err and "'results'" in err and "'reproduce'" in err


def test_python_dash_m_experiments_prints_its_help():
    done = subprocess.run(
        [sys.executable, "-m", "experiments", "reproduce", "-h"],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    assert "usage: python -m experiments reproduce" in done.stdout
    assert "ch4" in done.stdout and "certified" in done.stdout


def test_experiments_are_not_shipped_in_the_installed_packages():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())
    find = config["tool"]["setuptools"]["packages"]["find"]
    assert not any(pattern.startswith("experiments") for pattern in find["include"])
    assert "experiments*" in find.get("exclude", [])
    for package in ("fdia_env", "baselines", "agents"):
        assert not (ROOT / package / "results").exists()
        assert not (ROOT / package / "reproduce").exists()
