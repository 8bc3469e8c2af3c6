"""``python -m agents.bench {verify,compute,score}``: the benchmark's command line.

- ``verify [--task T ...] [--cheap]``: recompute the stored references and compare (exit 1 on a
  difference);
- ``compute [--task T ...] [--pending] [--all]``: compute references and write them to
  ``fdia_env/tasks/references.json`` (and its SHA-256 to ``fdia_env/tasks/digests.py``); the
  other tasks' entries are kept, so the stored file must pass its checks, except with ``--all``,
  which rewrites every entry;
- ``payoff --task T``: build a sensor-game task's payoff matrix and store it with the task
  references (``fdia_env.tasks.payoffs``; scoring then reads it instead of rebuilding it);
- ``table [--page docs/benchmark.md]``: rewrite the page's table of tasks from the stored
  references;
- ``score --task T --agent ...``: score an agent on a task (``agents.bench.score``; its own
  ``--help`` lists the options).
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m agents.bench", description=__doc__.split("\n")[0]
    )
    sub = parser.add_subparsers(dest="command", required=True)
    verify = sub.add_parser("verify", help="recompute the stored references and compare them")
    verify.add_argument("--task", action="append", help="a task name (repeatable; default all)")
    verify.add_argument(
        "--cheap", action="store_true", help="only the tasks whose references take < 5 s"
    )
    compute = sub.add_parser("compute", help="compute references and write the JSON file")
    compute.add_argument("--task", action="append", help="a task name (repeatable)")
    compute.add_argument(
        "--pending", action="store_true", help="the tasks without stored references"
    )
    compute.add_argument("--all", action="store_true", help="every defined task")
    payoff = sub.add_parser("payoff", help="store a sensor-game task's payoff matrix")
    payoff.add_argument("--task", action="append", required=True, help="a task (repeatable)")
    table = sub.add_parser("table", help="write the tasks table of docs/benchmark.md")
    table.add_argument(
        "--page", default="docs/benchmark.md", help="the page to update (an existing file)"
    )
    sub.add_parser("score", help="score an agent on a task (see score --help)", add_help=False)
    return parser


def _names(given: list[str] | None) -> list[str]:
    from fdia_env import tasks

    if not given:
        return list(tasks.TASKS)
    for name in given:
        tasks.get(name)  # an unknown name: ValueError naming `task`
    return given


def _verify(args: argparse.Namespace) -> int:
    from agents.bench.verify import CHEAP_SECONDS, stored_seconds, verify

    names = _names(args.task)
    if args.cheap:
        names = [n for n in names if stored_seconds(n) < CHEAP_SECONDS]
    failed = 0
    for check in verify(names):
        status = "ok" if check.ok else "DIFFERS"
        print(f"{check.task:55s} {status:8s} {check.seconds:7.2f} s")
        for line in check.mismatches:
            print(f"    {line}")
        failed += not check.ok
    print(f"{len(names) - failed}/{len(names)} tasks match their stored references")
    return 1 if failed else 0


def _compute(args: argparse.Namespace) -> int:
    from agents.bench.verify import write
    from fdia_env import tasks

    if args.all:
        names = [s.name for s in tasks.SPECS]
    elif args.pending:
        names = tasks.pending()
    elif args.task:
        names = [tasks.spec(n).name for n in args.task]
    else:
        print("compute: give --task T, --pending or --all", file=sys.stderr)
        return 2
    for name, seconds in write(names, keep=not args.all).items():
        print(f"{name:55s} {seconds:7.2f} s")
    return 0


def _score(argv: Sequence[str]) -> int:
    try:
        module = importlib.import_module("agents.bench.score")
    except ModuleNotFoundError as error:
        if error.name != "agents.bench.score":
            raise
        print(
            "score: agents.bench.score is not installed in this checkout "
            "(the scoring command is missing)",
            file=sys.stderr,
        )
        return 2
    return int(module.main(list(argv)) or 0)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the command line; returns the exit status."""
    argv = list(sys.argv[1:] if argv is None else argv)
    if argv and argv[0] == "score":
        return _score(argv[1:])
    args = _parser().parse_args(argv)
    try:
        if args.command == "table":
            from pathlib import Path

            from agents.bench.outputs import check_existing_file
            from agents.bench.verify import write_table

            changed = write_table(check_existing_file("--page", Path(args.page)))
            print(f"{args.page}: {'updated' if changed else 'unchanged'}")
            return 0
        if args.command == "payoff":
            from agents.bench.references import write_stored_payoff
            from fdia_env import tasks

            for name in args.task:
                print(f"{name}: wrote {write_stored_payoff(tasks.spec(name))}")
            return 0
        return _verify(args) if args.command == "verify" else _compute(args)
    except ValueError as error:
        print(f"error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
