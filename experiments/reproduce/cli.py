"""The command line: one subcommand per chapter, writing its section of the report."""

from __future__ import annotations

import argparse
import datetime
import re
import shlex
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from experiments.reproduce.certified import certified
from experiments.reproduce.ch2 import chapter2
from experiments.reproduce.ch3 import chapter3
from experiments.reproduce.ch4 import chapter4
from experiments.reproduce.ch5 import chapter5
from experiments.reproduce.common import DEFAULT_OUTPUT, DOC_INTRO, DOC_TITLE, Section, machine
from experiments.reproduce.stealth import stealth_chapter

CHAPTERS: dict[str, tuple[Callable[[argparse.Namespace], Section], str]] = {
    "ch2": (chapter2, "attack covariances: literature strategies, pv optima, ellipses, errata"),
    "ch3": (chapter3, "detection with minimum MSE: Bayes cost vs Monte-Carlo MSE, robustness"),
    "ch4": (chapter4, "sparse attacks: SFS order, solver table, pv cases, DP vs SFS"),
    "ch5": (chapter5, "sensor-selection game: payoffs, equilibria, incomplete information"),
    "certified": (certified, "certified optima by branch and bound: the heuristics' gaps"),
    "stealth": (stealth_chapter, "stealthy attacks: a = Hc, security indices, Mo-Sinopoli, Guo"),
}


# --- document -------------------------------------------------------------------------------


def _chapter_number(heading: str) -> float:
    """``"## Chapter 4: ..." -> 4``; headings without a number sort last."""
    match = re.match(r"## Chapter (\d+)", heading)
    return float(match.group(1)) if match else float("inf")


def replace_section(document: str, title: str, body: str) -> str:
    """``document`` with the ``## title`` section replaced by ``body`` (appended if absent)."""
    heading = f"## {title}"
    lines = document.splitlines()
    if not lines:
        lines = [DOC_TITLE, "", DOC_INTRO]
    start = next((i for i, line in enumerate(lines) if line.strip() == heading), None)
    new = [heading, "", *body.strip().splitlines(), ""]
    if start is None:  # insert in chapter order, before the first later chapter
        later = next(
            (
                i
                for i, line in enumerate(lines)
                if line.startswith("## ") and _chapter_number(line) > _chapter_number(heading)
            ),
            len(lines),
        )
        before, after = lines[:later], lines[later:]
        if before and before[-1].strip():
            before = [*before, ""]
        lines = [*before, *new, *after]
    else:
        end = next(
            (i for i in range(start + 1, len(lines)) if lines[i].startswith("## ")), len(lines)
        )
        lines = [*lines[:start], *new, *lines[end:]]
    return "\n".join(lines).rstrip() + "\n"


def main(argv: Sequence[str] | None = None) -> int:
    """Parse ``argv``, run the chapter, print it, and write the document section and figures."""
    parser = argparse.ArgumentParser(prog="python -m experiments reproduce", description=__doc__)
    sub = parser.add_subparsers(dest="chapter", required=True)
    for name, (_, help_text) in CHAPTERS.items():
        p = sub.add_parser(name, help=help_text)
        p.add_argument("--quick", action="store_true", help="smaller run (smoke test)")
        p.add_argument(
            "--output",
            type=Path,
            default=None,
            help=f"markdown file to update (default {DEFAULT_OUTPUT}; with --quick, "
            "nothing is written unless given)",
        )
    args = parser.parse_args(argv)
    run, _ = CHAPTERS[args.chapter]
    command = "python -m experiments reproduce " + shlex.join(
        list(sys.argv[1:] if argv is None else argv)
    )
    t0 = time.perf_counter()
    section = run(args)
    elapsed = time.perf_counter() - t0
    stamp = datetime.datetime.now().astimezone().strftime("%Y-%m-%d %H:%M %Z")
    header = f"Command: `{command}` ({elapsed:.0f} s)  \nMachine: {machine()}  \nGenerated: {stamp}"
    body = header + "\n\n" + section.body
    print(f"## {section.title}\n\n{body}")
    output = args.output if args.output is not None or args.quick else DEFAULT_OUTPUT
    if output is not None:
        output.parent.mkdir(parents=True, exist_ok=True)
        old = output.read_text() if output.exists() else ""
        output.write_text(replace_section(old, section.title, body))
        figures = output.parent / "figures"
        for filename, save in section.figures.items():
            figures.mkdir(parents=True, exist_ok=True)
            save(figures / filename)
        print(f"\nwrote {output} and {len(section.figures)} figure(s) in {figures}")
    return 0
