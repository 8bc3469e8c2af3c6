"""Learned against analytic where it is hard: the re-runnable result tables (issue 16).

Run ``python -m agents.results <table> [--quick] [--seed S] [--out DIR]`` or ``all``. Every table
is produced by one seeded command; ``--quick`` runs a reduced version in seconds to minutes (the
test suite runs each). A table module exposes ``run(quick, seed, out) -> str`` (Markdown) and, with
``out``, writes its rows as JSON (and its plots) there. Tables:

- ``detection`` (:mod:`agents.results.detection`): where the detection game separates policies.
- ``game`` (:mod:`agents.results.game`): PSRO with learned best responses on the sensor game at
  M = 10 and on grid-ieee14 against the exact (double-oracle and LP) equilibrium.
"""

from agents.results.cli import TABLES, main, run_table

__all__ = ["TABLES", "main", "run_table"]
