"""``python -m experiments results``: run one result table, or all of them."""

from __future__ import annotations

import argparse
import importlib
import time
from collections.abc import Sequence
from pathlib import Path

# table name -> module with ``run(quick, seed, out) -> str`` (imported when the table runs)
TABLES: dict[str, str] = {
    "sparse_grid": "experiments.results.sparse_grid",
    "general": "experiments.results.general",
    "general_grid": "experiments.results.general_grid",
    "game": "experiments.results.game",
    "detection": "experiments.results.detection",
    "detection_learned": "experiments.results.detection_learned",
    "stealth": "experiments.results.stealth",
}


def run_table(name: str, quick: bool = False, seed: int = 0, out: Path | None = None) -> str:
    """Run one table and return it as Markdown.

    Args:
        name: A key of :data:`TABLES`.
        quick: The reduced run.
        seed: Base seed of the table's training and evaluation.
        out: Folder for the table's JSON rows and plots (none written when None).

    Raises:
        ValueError: For an unknown table (naming the known ones).
    """
    if name not in TABLES:
        raise ValueError(f"table must be one of {sorted(TABLES)}, got {name!r}")
    module = importlib.import_module(TABLES[name])
    return module.run(quick=quick, seed=seed, out=out)


def main(argv: Sequence[str] | None = None) -> int:
    """Parse the command line, print the table(s) with their wall time."""
    parser = argparse.ArgumentParser(
        prog="python -m experiments results",
        description="Learned-vs-analytic result tables.",
    )
    parser.add_argument("table", choices=[*TABLES, "all"], help="which result table")
    parser.add_argument("--quick", action="store_true", help="reduced run")
    parser.add_argument("--seed", type=int, default=0, help="base seed")
    parser.add_argument("--out", type=Path, default=None, help="folder for JSON rows and plots")
    args = parser.parse_args(argv)
    names = list(TABLES) if args.table == "all" else [args.table]
    for name in names:
        start = time.perf_counter()
        table = run_table(name, quick=args.quick, seed=args.seed, out=args.out)
        print(f"## {name}\n\n{table}\n\n({time.perf_counter() - start:.1f} s)\n", flush=True)
    return 0
