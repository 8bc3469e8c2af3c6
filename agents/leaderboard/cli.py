"""``fdia-leaderboard``: train and score learners across tasks and seeds, render.

The console script of an installed fdia-env; ``python -m experiments bench`` runs it in a
checkout. Examples::

    fdia-leaderboard --tasks hard --algo MaskablePPO --seeds 3 --out runs/board/rows.json
    fdia-leaderboard --out runs/board/rows.json --render-only  # the page of the rows written

The runner writes only where it is told. Rows go to ``--out`` (required), replaced atomically
after every run; the page goes to ``--page`` (default ``leaderboard.md`` beside ``--out``; a
missing page is created, an existing one must hold the leaderboard's markers) and one plot per
task family to ``--figures`` (default ``figures/`` beside the page); ``--no-render`` writes
neither. Missing parent folders are created, and every output is checked before any run is
trained: a path that cannot serve is an error naming the option.

A rerun with the same ``--out`` resumes: it skips the (task, learner, seed) runs that already
have a row there at the same budget and hyperparameters (and ``--episodes``, where given), so a
killed run loses at most the run in progress; ``--retrain`` trains them again. ``--hp NAME
VALUE`` sets a hyperparameter of every learner named by ``--algo`` (each must take it) and
``--hp ALGO:NAME VALUE`` one learner's; the names are checked against each learner's
hyperparameters before any training. A run that fails is written as a failed row with its
error, the others go on, the final table lists it and the exit status is 1.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from agents.leaderboard.rows import is_done, merge_rows, read_rows, write_rows

DIFFICULTIES = ("easy", "medium", "hard")
PAGE_NAME = "leaderboard.md"
FIGURES_NAME = "figures"


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


def learner_hyperparameters(
    pairs: Sequence[Sequence[str]], algos: Sequence[str], timesteps: int
) -> dict[str, dict[str, Any]]:
    """``--hp`` pairs as each learner's hyperparameters, checked against what it takes.

    ``NAME VALUE`` applies to every learner of ``algos`` and ``ALGO:NAME VALUE`` to that one
    (over the former); values are read as JSON where they parse.

    >>> learner_hyperparameters([("n_steps", "64"), ("PPO:n_steps", "32")], ["PPO", "A2C"], 64)
    {'PPO': {'n_steps': 32}, 'A2C': {'n_steps': 64}}

    Raises:
        ValueError: Naming ``--hp``: for a learner not in ``algos``, a name a learner does not
            take (with the names it takes) or a value it refuses.
    """
    from agents.config import parse_env_kwargs
    from agents.leaderboard.run import check_hyperparameters, hyperparameter_names

    common: dict[str, str] = {}
    own: dict[str, dict[str, str]] = {algo: {} for algo in algos}
    for name, value in pairs:
        algo, sep, field = name.rpartition(":")
        if not sep:
            common[name] = value
        elif algo in own:
            own[algo][field] = value
        else:
            raise ValueError(
                f"--hp {name}: {algo!r} is not a learner of --algo ({', '.join(algos)})"
            )
    for algo in algos:
        takes = hyperparameter_names(algo)
        for name in common:
            if name not in takes and len(algos) > 1:
                raise ValueError(
                    f"--hp {name}: not a hyperparameter of {algo}; {algo} takes "
                    f"{', '.join(takes)} (--hp ALGO:{name} VALUE sets it for one learner)"
                )
    out = {}
    for algo in algos:
        hp = parse_env_kwargs({**common, **own[algo]})
        if isinstance(hp.get("net_arch"), list):
            hp["net_arch"] = tuple(hp["net_arch"])
        check_hyperparameters(algo, hp, timesteps, option="--hp")
        out[algo] = hp
    return out


def _probe_folder(option: str, folder: Path) -> None:
    """Create ``folder`` (and its parents) and check that a file can be written in it."""
    from agents.bench.outputs import OutputPathError

    if folder.exists() and not folder.is_dir():
        raise OutputPathError(f"{option} {folder}: is a file; give a folder")
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=folder, prefix=".probe.")
        os.close(fd)
        os.unlink(probe)
    except (FileExistsError, NotADirectoryError):
        raise OutputPathError(f"{option} {folder}: a parent is not a folder") from None
    except OSError as exc:
        raise OutputPathError(f"{option} {folder}: cannot be written ({exc.strerror})") from None


def check_outputs(args: argparse.Namespace) -> None:
    """Check ``--out``, ``--page`` and ``--figures`` before any run is trained.

    ``--out`` is a file, ``--page`` a page with the leaderboard's markers or a new file,
    ``--figures`` a folder; missing parent folders are created.

    Raises:
        agents.bench.outputs.OutputPathError: Naming the option and the path.
    """
    from agents.bench.outputs import OutputPathError, check_existing_file, check_new_file
    from agents.leaderboard.render import END, START

    if args.render_only:
        if Path(args.out).is_dir():
            raise OutputPathError(f"--out {args.out}: is a folder; give the rows file")
    else:
        check_new_file("--out", args.out)
    if args.no_render:
        return
    if Path(args.page).resolve() == Path(args.out).resolve():
        raise OutputPathError(f"--page {args.page}: is the --out rows file; give another path")
    if Path(args.page).exists():
        check_existing_file("--page", args.page)
        text = Path(args.page).read_text(encoding="utf-8", errors="replace")
        if START not in text or END not in text:
            raise OutputPathError(
                f"--page {args.page}: has no {START} … {END} markers for the leaderboard; "
                "give a page with them, a new file, or --no-render"
            )
    else:
        check_new_file("--page", args.page)
    _probe_folder("--figures", Path(args.figures))


def render(
    rows: list[dict[str, Any]], page: Path, figures: Path, tasks: list[Any], prog: str
) -> None:
    """Write the leaderboard of ``tasks`` (with ``rows``) into ``page`` and its figures."""
    from agents.leaderboard.render import leaderboard, write_section
    from agents.leaderboard.rows import failed

    budgets = sorted({r["timesteps"] for r in rows})
    seeds = sorted({r["seed"] for r in rows})
    broken = sum(failed(r) for r in rows)
    header = (
        f"Produced by `{prog}` "
        f"({len(rows)} learner runs, {f'{broken} of them failed, ' if broken else ''}"
        f"seeds {seeds}, training budgets "
        f"{', '.join(f'{b:,}' for b in budgets) or '–'} env steps; "
        f"rendered {time.strftime('%Y-%m-%d', time.gmtime())}). Learners: mean ± 95 % CI of "
        "the normalised score over the training seeds (each scored on its task's episodes); "
        "references: the task's stored values."
    )
    link = Path(os.path.relpath(Path(figures).resolve(), Path(page).resolve().parent))
    write_section(page, leaderboard(tasks, rows, Path(figures), header, link.as_posix()))


def page_tasks(rows: list[dict[str, Any]], selected: list[Any]) -> list[Any]:
    """The tasks the page shows: those with rows and those selected, in the registry's order."""
    from fdia_env.tasks import get, names

    wanted = {r["task"] for r in rows} | {t.name for t in selected}
    return [get(n) for n in names() if n in wanted]


def summary_table(results: list[tuple[str, str, int, str, str]]) -> str:
    """This invocation's runs as a text table: task, learner, seed, status, result."""
    head = ("task", "learner", "seed", "status", "result")
    lines = [head, *[(t, a, str(s), st, r) for t, a, s, st, r in results]]
    widths = [max(len(line[i]) for line in lines) for i in range(4)]
    return "\n".join(
        "  ".join(cell.ljust(w) for cell, w in zip(line[:4], widths, strict=True)) + "  " + line[4]
        for line in lines
    )


def _result(row: dict[str, Any]) -> str:
    """A row in one line: its score, or its error."""
    from agents.leaderboard.rows import failed

    if failed(row):
        return row.get("error", "")
    norm, raw = row.get("normalised"), row.get("raw", row.get("mean"))
    norm = "–" if norm is None else f"{norm:.4f}"
    raw = "–" if raw is None else f"{raw:.6g}"
    return f"normalised {norm} (raw {raw}, {row.get('train_seconds')} s)"


def build_parser(prog: str) -> argparse.ArgumentParser:
    """The runner's command line."""
    from agents.leaderboard.run import LEARNERS

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
    parser.add_argument(
        "--timesteps", type=int, default=20_000, help="training env steps per run (default 20,000)"
    )
    parser.add_argument(
        "--hp",
        nargs=2,
        action="append",
        default=[],
        metavar=("NAME", "VALUE"),
        help="a hyperparameter over train.py's default for every learner of --algo, or "
        "ALGO:NAME for one learner (repeatable), e.g. --hp n_steps 64 --hp torch-ppo:num_envs "
        "256; torch-ppo's num_envs defaults to min(256, timesteps / (8 n_steps))",
    )
    parser.add_argument("--episodes", type=int, default=None, help="evaluation episodes per run")
    parser.add_argument("--out", type=Path, required=True, help="the JSON rows file (required)")
    parser.add_argument(
        "--page",
        type=Path,
        default=None,
        help=f"the leaderboard page (default: {PAGE_NAME} beside --out); created when missing, "
        "else it must hold the leaderboard's markers",
    )
    parser.add_argument(
        "--figures",
        type=Path,
        default=None,
        help=f"the figures folder (default: {FIGURES_NAME}/ beside the page)",
    )
    resume = parser.add_mutually_exclusive_group()
    resume.add_argument(
        "--resume",
        "--missing",
        dest="retrain",
        action="store_false",
        help="skip the runs that already have a row in --out at this budget and these "
        "hyperparameters (the default)",
    )
    resume.add_argument(
        "--retrain",
        dest="retrain",
        action="store_true",
        help="train those runs again and replace their rows",
    )
    parser.set_defaults(retrain=False)
    parser.add_argument("--no-render", action="store_true", help="write the rows only")
    parser.add_argument("--render-only", action="store_true", help="render the rows written")
    return parser


def main(argv: Sequence[str] | None = None, prog: str = "fdia-leaderboard") -> int:
    """Parse the command line, train and score, write the rows and the page.

    Args:
        argv: The arguments (``sys.argv[1:]`` when None).
        prog: The program's name in its help and messages.

    Returns:
        0, or 1 when a run failed, 130 when interrupted (the finished runs' rows are kept).
    """
    from agents.leaderboard import run

    parser = build_parser(prog)
    args = parser.parse_args(list(sys.argv[1:] if argv is None else argv))
    if args.seeds < 1:
        parser.error(f"--seeds must be >= 1, got {args.seeds}")
    if args.first_seed < 0:
        parser.error(f"--first-seed must be >= 0, got {args.first_seed}")
    if args.timesteps < 1:
        parser.error(f"--timesteps must be >= 1, got {args.timesteps}")
    if args.episodes is not None and args.episodes < 1:
        parser.error(f"--episodes must be >= 1, got {args.episodes}")
    if args.render_only and args.no_render:
        parser.error("--render-only and --no-render exclude each other")
    args.page = args.out.parent / PAGE_NAME if args.page is None else args.page
    args.figures = args.page.parent / FIGURES_NAME if args.figures is None else args.figures
    algos = [a.strip() for a in args.algo.split(",") if a.strip()]
    unknown = [a for a in algos if a not in run.LEARNERS]
    if unknown or not algos:
        parser.error(f"--algo must name learners of {', '.join(run.LEARNERS)}, got {unknown}")
    try:
        hps = learner_hyperparameters(args.hp, algos, args.timesteps)
        tasks = select_tasks(args.tasks)
        check_outputs(args)
        rows = read_rows(args.out)
    except (TypeError, ValueError) as exc:
        parser.error(str(exc))
    results: list[tuple[str, str, int, str, str]] = []
    if not args.render_only:
        try:
            rows = train_all(args, tasks, algos, hps, rows, results)
        except KeyboardInterrupt:
            print(summary_table(results), flush=True)
            print(
                f"interrupted: the finished runs' rows are in {args.out}; rerun the same "
                "command to resume",
                file=sys.stderr,
            )
            return 130
        print(summary_table(results), flush=True)
    if not args.no_render:
        render(rows, args.page, args.figures, page_tasks(rows, tasks), prog)
        print(f"wrote {args.page} and its figures in {args.figures}")
    failures = [r for r in results if r[3] == "FAILED"]
    if failures:
        print(
            f"{len(failures)} run(s) failed:",
            *(f"{t} {a} seed {s}: {e}" for t, a, s, _, e in failures),
            sep="\n  ",
            file=sys.stderr,
        )
        return 1
    return 0


def train_all(
    args: argparse.Namespace,
    tasks: list[Any],
    algos: list[str],
    hps: dict[str, dict[str, Any]],
    rows: list[dict[str, Any]],
    results: list[tuple[str, str, int, str, str]],
) -> list[dict[str, Any]]:
    """Train and score every (task, learner, seed) not done yet, writing each row as it ends.

    Appends each run's (task, learner, seed, status, result) to ``results``; returns the rows.
    """
    from agents.leaderboard import run

    seeds = range(args.first_seed, args.first_seed + args.seeds)
    for task in tasks:
        for algo in algos:
            if not run.applicable(task, algo):
                print(f"{task.name}: {algo} does not fit its actions, skipped", flush=True)
                continue
            hp = hps[algo]
            recorded = run.recorded_hyperparameters(algo, hp, args.timesteps)
            for seed in seeds:
                ident = (task.name, algo, seed)
                done = [
                    r for r in rows if is_done(r, ident, args.timesteps, recorded, args.episodes)
                ]
                if done and not args.retrain:
                    results.append((*ident, "skipped", "already in --out: " + _result(done[0])))
                    continue
                start = time.perf_counter()
                try:
                    row = run.learner_row(task, algo, seed, args.timesteps, args.episodes, hp)
                    status = "trained"
                except Exception as exc:  # one failed run must not stop the others
                    row = run.failed_row(
                        task, algo, seed, args.timesteps, hp, exc, time.perf_counter() - start
                    )
                    status = "FAILED"
                    print(f"FAILED {task.name} {algo} seed {seed}: {row['error']}", file=sys.stderr)
                results.append((*ident, status, _result(row)))
                print(f"{task.name} {algo} seed {seed}: {_result(row)}", flush=True)
                rows = merge_rows(read_rows(args.out), [row])  # another run may have added
                write_rows(args.out, rows)
    return rows
