"""Systems: linear Gaussian models, sensors and the target-tracking helper."""

from fdia_env.systems.grid import grid_system
from fdia_env.systems.system import (
    LinearSystem,
    Sensor,
    check_detectable,
    check_system,
    noise_factor,
    pbh_defects,
)
from fdia_env.systems.tracking import position_sensor, power_weight, pv_sensor, tracking_system

__all__ = [
    "LinearSystem",
    "Sensor",
    "check_detectable",
    "check_system",
    "grid_system",
    "noise_factor",
    "pbh_defects",
    "position_sensor",
    "power_weight",
    "pv_sensor",
    "tracking_system",
]
