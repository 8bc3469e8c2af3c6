"""Learned against analytic where it is hard: the re-runnable result tables.

Run ``python -m experiments results <table> [--quick] [--seed S] [--out DIR]`` or ``all``.
Every table is produced by one seeded command; ``--quick`` runs a reduced version in seconds to
minutes (the test suite runs each). A table module exposes ``run(quick, seed, out) -> str``
(Markdown) and, with ``out``, writes its rows as JSON (and its plots) there. Tables:

- ``detection`` (:mod:`experiments.results.detection`): where the detection game separates
  policies.
- ``detection_learned`` (:mod:`experiments.results.detection_learned`): learned defenders and
  attackers (p, Σ) of the detection game against the analytic detectors, best responses and
  each other, under the Bayes cost and the true MSE.
- ``sparse_grid`` (:mod:`experiments.results.sparse_grid`): sparse attacks on power grids,
  MaskablePPO and torch PPO against SFS, SBS, SFS-SS, DP and the certified optimum (or bound).
- ``general`` (:mod:`experiments.results.general`): one sparse attacker for many systems, on
  held-out systems against each one's optimum and SFS.
- ``general_grid`` (:mod:`experiments.results.general_grid`): the same over random IEEE 14-bus
  grids (random loads and meter noise).
- ``game`` (:mod:`experiments.results.game`): PSRO with learned best responses on the sensor
  game at M = 10 and on grid-ieee14 against the exact (double-oracle and LP) equilibrium.
"""

from experiments.results.cli import TABLES, main, run_table

__all__ = ["TABLES", "main", "run_table"]
