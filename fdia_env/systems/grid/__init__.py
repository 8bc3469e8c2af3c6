"""Power-grid DC dynamic state estimation (docs/math.md §7); needs the ``[grid]`` extra."""

from fdia_env.systems.grid.cases import GRID_CASES, GridCase, GridPreset
from fdia_env.systems.grid.dc14 import dc_grid14
from fdia_env.systems.grid.measurements import (
    DEFAULT_Q,
    DEFAULT_SIGMA_FLOW,
    DEFAULT_SIGMA_INJECTION,
    GridModel,
    Meter,
    grid_model,
    grid_system,
)
from fdia_env.systems.grid.network import CASES, DCNetwork, dc_network

__all__ = [
    "CASES",
    "DEFAULT_Q",
    "DEFAULT_SIGMA_FLOW",
    "DEFAULT_SIGMA_INJECTION",
    "GRID_CASES",
    "DCNetwork",
    "GridCase",
    "GridModel",
    "GridPreset",
    "Meter",
    "dc_grid14",
    "dc_network",
    "grid_model",
    "grid_system",
]
