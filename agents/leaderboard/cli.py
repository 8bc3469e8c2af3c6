"""``fdia-leaderboard``: train and score learners across tasks and seeds, render.

The console script of an installed fdia-env; ``python -m experiments bench`` runs it in a
checkout. Examples::

    fdia-leaderboard --tasks hard --algo MaskablePPO --seeds 3 --timesteps 20000
    fdia-leaderboard --render-only        # the page from the rows already written

Rows go to ``--out`` (default ``results/bench/rows.json``; a rerun replaces the rows of the
same task, method and seed and keeps the others; ``--missing`` trains only the runs that have
no row at this budget yet, so an interrupted run is resumed by rerunning it). A run that fails
is reported on stderr and in the summary, and the others go on. ``--page`` (default
docs/benchmark.md) gets the leaderboard between its markers and ``--figures`` (default
docs/figures) one plot per task family; ``--no-render`` skips both. The page must exist and
hold the leaderboard's markers (the checkout's docs/benchmark.md does): outside a checkout give
``--page`` or ``--no-render``.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

DEFAULT_OUT = Path("results/bench/rows.json")
DEFAULT_PAGE = Path("docs/benchmark.md")
DEFAULT_FIGURES = Path("docs/figures")
DIFFICULTIES = ("easy", "medium", "hard")


def select_tasks(spec: str) -> list[Any]:
    """Tasks named by ``spec``: ``all``, a difficulty, a family, or comma-separated names.

    Raises:
        ValueError: Naming ``tasks`` for a name that is none of those.
    """
    from fdia_env.tasks import get, names

    if spec == "all":
        return [get(n) for n in names()]
    if spec in DIFFICULTIES:
        return [get(n) for n in names(difficulty=spec)]
    families = sorted({get(n).family for n in names()})
    if spec in families:
        return [get(n) for n in names(family=spec)]
    out = []
    for name in spec.split(","):
        try:
            out.append(get(name.strip()))
        except ValueError as exc:
            raise ValueError(
                f"tasks must be 'all', a difficulty ({', '.join(DIFFICULTIES)}), a family "
                f"({', '.join(families)}) or task names: {exc}"
            ) from None
    return out


def read_rows(path: Path) -> list[dict[str, Any]]:
    """The rows written so far ([] when none).

    Raises:
        ValueError: Naming ``--out`` when the file is not a rows file ``{"rows": [...]}``.
    """
    if not path.is_file():
        return []
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f'--out {path}: not a rows file {{"rows": [...]}} ({exc})') from None
    if not isinstance(data, dict) or not isinstance(data.get("rows", []), list):
        raise ValueError(f'--out {path}: not a rows file {{"rows": [...]}}')
    return list(data.get("rows", []))


def merge_rows(old: list[dict[str, Any]], new: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """``old`` with the rows of the same (task, method, seed) as a new one replaced."""
    keys = {(r["task"], r["method"], r["seed"]) for r in new}
    return [r for r in old if (r["task"], r["method"], r["seed"]) not in keys] + new


def has_row(rows: list[dict[str, Any]], task: str, method: str, seed: int, timesteps: int) -> bool:
    """Whether ``rows`` hold the run (task, method, seed) trained for ``timesteps`` steps."""
    return any(
        (r["task"], r["method"], r["seed"], r["timesteps"]) == (task, method, seed, timesteps)
        for r in rows
    )


def write_rows(path: Path, rows: list[dict[str, Any]]) -> None:
    """Write the rows as ``{"rows": [...]}``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps({"rows": rows}, indent=1) + "\n", encoding="utf-8")


def render(rows: list[dict[str, Any]], page: Path, figures: Path, tasks: list[Any]) -> None:
    """Write the leaderboard of ``tasks`` (with ``rows``) into ``page`` and its figures."""
    from agents.leaderboard.render import leaderboard, write_section

    budgets = sorted({r["timesteps"] for r in rows})
    seeds = sorted({r["seed"] for r in rows})
    header = (
        "Produced by `python -m experiments bench` "
        f"({len(rows)} learner runs, seeds {seeds}, training budgets "
        f"{', '.join(f'{b:,}' for b in budgets) or '–'} env steps; "
        f"rendered {time.strftime('%Y-%m-%d', time.gmtime())}). Learners: mean ± 95 % CI of "
        "the normalised score over the training seeds (each scored on its task's episodes); "
        "references: the task's stored values."
    )
    write_section(page, leaderboard(tasks, rows, figures, header))


def check_outputs(args: argparse.Namespace) -> None:
    """Check ``--out``, ``--page`` and ``--figures`` before any run is trained.

    ``--out`` is a file (its missing folders are created), ``--page`` an existing page that
    can be written, ``--figures`` a folder (created when missing).

    Raises:
        agents.bench.outputs.OutputPathError: Naming the option and the path.
    """
    from agents.bench.outputs import OutputPathError, check_existing_file, check_new_file

    if args.render_only:
        if Path(args.out).is_dir():
            raise OutputPathError(f"--out {args.out}: is a folder; give the rows file")
    else:
        check_new_file("--out", args.out)
    if not args.no_render:
        check_existing_file("--page", args.page)
        if Path(args.figures).exists() and not Path(args.figures).is_dir():
            raise OutputPathError(f"--figures {args.figures}: is a file; give a folder")


def main(argv: Sequence[str] | None = None, prog: str = "fdia-leaderboard") -> int:
    """Parse the command line, train and score, write the rows and the page.

    Args:
        argv: The arguments (``sys.argv[1:]`` when None).
        prog: The program's name in its help and messages.
    """
    from agents.config import parse_env_kwargs
    from agents.leaderboard.run import LEARNERS, applicable, check_hyperparameters, learner_row

    parser = argparse.ArgumentParser(prog=prog, description="Benchmark leaderboard runner.")
    parser.add_argument(
        "--tasks", default="hard", help="all, easy, medium, hard, a family or names"
    )
    parser.add_argument(
        "--algo",
        default="MaskablePPO,PPO",
        help=f"comma-separated learners ({', '.join(LEARNERS)}); those that do not fit a task's "
        "actions are skipped there",
    )
    parser.add_argument("--seeds", type=int, default=3, help="training seeds (default 3)")
    parser.add_argument(
        "--first-seed", type=int, default=0, help="the first training seed (default 0)"
    )
    parser.add_argument("--timesteps", type=int, default=20_000, help="training steps per run")
    parser.add_argument(
        "--hp",
        nargs=2,
        action="append",
        default=[],
        metavar=("NAME", "VALUE"),
        help="a stable-baselines3 hyperparameter over train.py's default (repeatable), e.g. "
        "--hp n_steps 64",
    )
    parser.add_argument("--episodes", type=int, default=None, help="evaluation episodes per run")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="JSON rows file")
    parser.add_argument("--page", type=Path, default=DEFAULT_PAGE, help="leaderboard page")
    parser.add_argument("--figures", type=Path, default=DEFAULT_FIGURES, help="figure folder")
    parser.add_argument(
        "--missing",
        action="store_true",
        help="train only the (task, learner, seed) runs without a row at this budget",
    )
    parser.add_argument("--no-render", action="store_true", help="write the rows only")
    parser.add_argument("--render-only", action="store_true", help="render the rows written")
    args = parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    if args.seeds < 1:
        parser.error(f"--seeds must be >= 1, got {args.seeds}")
    if args.first_seed < 0:
        parser.error(f"--first-seed must be >= 0, got {args.first_seed}")
    if args.timesteps < 1:
        parser.error(f"--timesteps must be >= 1, got {args.timesteps}")
    algos = [a.strip() for a in args.algo.split(",") if a.strip()]
    unknown = [a for a in algos if a not in LEARNERS]
    if unknown:
        parser.error(f"--algo must name learners of {', '.join(LEARNERS)}, got {unknown}")
    hp = parse_env_kwargs(dict(args.hp))
    if isinstance(hp.get("net_arch"), list):
        hp["net_arch"] = tuple(hp["net_arch"])
    try:
        check_hyperparameters(hp)
        tasks = select_tasks(args.tasks)
    except (TypeError, ValueError) as exc:
        parser.error(str(exc))
    try:
        check_outputs(args)
        rows = read_rows(args.out)
    except ValueError as exc:
        parser.error(str(exc))
    failed: list[str] = []
    if not args.render_only:
        for task in tasks:
            for algo in algos:
                if not applicable(task, algo):
                    print(f"{task.name}: {algo} does not fit its actions, skipped", flush=True)
                    continue
                for seed in range(args.first_seed, args.first_seed + args.seeds):
                    if args.missing and has_row(rows, task.name, algo, seed, args.timesteps):
                        continue
                    try:
                        row = learner_row(task, algo, seed, args.timesteps, args.episodes, hp)
                    except Exception as exc:  # one failed run must not stop the others
                        failed.append(
                            f"{task.name} {algo} seed {seed}: {type(exc).__name__}: {exc}"
                        )
                        print(f"FAILED {failed[-1]}", file=sys.stderr, flush=True)
                        continue
                    print(
                        f"{task.name} {algo} seed {seed}: normalised {row['normalised']:.4f} "
                        f"(raw {row['raw']:.6g}, {row['train_seconds']} s)",
                        flush=True,
                    )
                    rows = merge_rows(read_rows(args.out), [row])  # another run may have added
                    write_rows(args.out, rows)
    if not args.no_render:
        from fdia_env.tasks import get, names

        every = [get(n) for n in names()]
        render(rows, args.page, args.figures, every)
        print(f"wrote {args.page} and its figures in {args.figures}")
    if failed:
        print(f"{len(failed)} run(s) failed:", *failed, sep="\n  ", file=sys.stderr)
        return 1
    return 0
