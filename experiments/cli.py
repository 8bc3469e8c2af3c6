"""``python -m experiments``: one command line over the experiment drivers."""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

# subcommand -> module with ``main(argv) -> int`` (imported only when its subcommand runs, so
# ``experiments.reproduce`` can set the BLAS threads before numpy is loaded)
COMMANDS: dict[str, tuple[str, str]] = {
    "results": ("experiments.results.cli", "learned-against-analytic result tables"),
    "reproduce": ("experiments.reproduce.cli", "the literature's tables and figures, by chapter"),
    "bench": ("experiments.bench.cli", "train and score learners on the benchmark tasks"),
}


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``python -m experiments <command> ...``: the rest of ``argv`` goes to the command.

    Args:
        argv: The arguments after the program name (``sys.argv[1:]`` when None).

    Returns:
        The command's exit status.
    """
    parser = argparse.ArgumentParser(
        prog="python -m experiments",
        description="Experiment drivers: "
        + "; ".join(f"{name}: {text}" for name, (_, text) in COMMANDS.items())
        + ". Run `python -m experiments COMMAND -h` for a command's options.",
    )
    parser.add_argument("command", choices=list(COMMANDS), help="which driver")
    parser.add_argument("args", nargs=argparse.REMAINDER, help="the driver's own arguments")
    args = parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    module = importlib.import_module(COMMANDS[args.command][0])
    return module.main(args.args)
