"""Reproduce the literature's tables and figures, one subcommand per chapter.

Run ``python -m experiments reproduce ch4`` to print chapter 4's tables and write them, with the
command and the machine, into the "Chapter 4" section of ``docs/reproduction.md`` (figures go to
``docs/figures/``). ``--quick`` runs a smaller version and writes files only when ``--output``
is given. Add a chapter as a module ``chN.py`` with a ``chapterN(args) -> Section`` function
and register it in :data:`experiments.reproduce.cli.CHAPTERS`.
"""

import os

# The solvers' only LAPACK calls are tiny (the steady-state DARE solve); a multi-threaded OpenBLAS
# pool gains nothing there and, on a 2-core machine, spins against any other process and
# inflates the timings tenfold. Time single-threaded unless the caller says otherwise (this only
# takes effect when numpy is not imported yet, i.e. when run as
# ``python -m experiments reproduce``).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")


from experiments.reproduce.ch2 import CH2_LITERATURE
from experiments.reproduce.ch4 import CH4_LITERATURE_TIMES
from experiments.reproduce.cli import CHAPTERS, main, replace_section
from experiments.reproduce.common import Section, machine

__all__ = [
    "CH2_LITERATURE",
    "CH4_LITERATURE_TIMES",
    "CHAPTERS",
    "Section",
    "machine",
    "main",
    "replace_section",
]
