"""fdia_env: Gymnasium and PettingZoo environments for false data injection on Kalman filters.

See the README and the documentation site (``docs/``, built by ``make docs``) for the
environments, the scenarios and the baselines.
"""

from fdia_env import scenarios
from fdia_env.episode import EpisodeSpec
from fdia_env.registration import EnvEntry, register_env, register_envs
from fdia_env.systems import LinearSystem, Sensor, position_sensor, pv_sensor, tracking_system

register_envs()

__version__ = "0.1.0"
__all__ = [
    "EnvEntry",
    "EpisodeSpec",
    "LinearSystem",
    "Sensor",
    "position_sensor",
    "pv_sensor",
    "register_env",
    "register_envs",
    "scenarios",
    "tracking_system",
]
