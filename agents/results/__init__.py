"""Learned against analytic where it is hard: the re-runnable result tables (issue 16).

Run ``python -m agents.results <table> [--quick] [--seed S] [--out DIR]`` or ``all``. Every table
is produced by one seeded command; ``--quick`` runs a reduced version in seconds to minutes (the
test suite runs each). A table module exposes ``run(quick, seed, out) -> str`` (Markdown) and, with
``out``, writes its rows as JSON (and its plots) there. Tables:

- ``detection`` (:mod:`agents.results.detection`): where the detection game separates policies.
- ``general`` (:mod:`agents.results.general`): one sparse attacker for many systems, on held-out
  systems against each one's optimum and SFS.
"""

from agents.results.cli import TABLES, main, run_table

__all__ = ["TABLES", "main", "run_table"]
