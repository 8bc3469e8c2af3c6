"""``general_grid``: one sparse attacker for many power grids, scored on held-out systems.

The grid counterpart of :mod:`experiments.results.general`: the family is
:class:`fdia_env.envs.grid_family.GridFamily` (the pandapower IEEE 14-bus DC state estimation of
the ``grid-ieee14`` preset, n = 13 angles, M = 34 meters, with every load scaled by ``U(0.5,
1.5)`` and every meter's σ by a log-uniform factor on [0.5, 2]), the attack c = 3 sensor-time
pairs over N = 2 steps. The same training (MaskablePPO, sequential picks over effect-sorted
slots, the description of the system in the observation), the same held-out scoring against
each system's own optimum (branch and bound, proved) and against SFS, the same comparison rows
(:data:`experiments.results.general.POLICY_NAMES`), as :mod:`experiments.results.general`,
which this module calls with another :class:`~experiments.results.general.Settings`.
"""

from __future__ import annotations

from pathlib import Path

from experiments.results.general import Settings, report
from fdia_env.envs.grid_family import GridFamily

FAMILY = GridFamily(
    case="ieee14", load_scale=(0.5, 1.5), noise_scale=(0.5, 2.0), budget=3, horizon=2
)
"""The grid family of both runs (the full and the quick one differ in training only)."""

PPO = {"n_steps": 64, "batch_size": 256}
"""Shorter rollouts than the tracking table's (episodes here are c + N = 5 decisions)."""
FULL = Settings(FAMILY, 100_000, 10_000, 100, 10_000, PPO)
QUICK = Settings(FAMILY, 8_192, 2_048, 100, 8_192, PPO)


def run(quick: bool = False, seed: int = 0, out: Path | None = None) -> str:
    """The ``general_grid`` table (Markdown); ``quick``: short training."""
    settings = QUICK if quick else FULL
    fam = settings.family
    family = (
        f"pandapower {fam.case}, M = {fam.num_sensors} meters, n = {fam.state_size} angles, "
        f"loads × U{fam.load_scale}, meter σ × log-uniform on {fam.noise_scale}, "
        f"c = {fam.budget}, N = {fam.horizon}"
    )
    return report(settings, seed, out, "general_grid", family)
