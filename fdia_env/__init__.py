"""fdia_env: Gymnasium and PettingZoo environments for false data injection on Kalman filters.

See the README and the documentation site (``docs/``, built by ``make docs``) for the
environments, the scenarios and the baselines.

Every environment module of the table of environments (:data:`fdia_env.registration.ENVS`)
imports as ``from fdia_env import <name>``, those that live in a subpackage too (the stealth
envs of :mod:`fdia_env.stealth`):

>>> from fdia_env import sparse_attack_v0, stealth_attack_v0
>>> stealth_attack_v0.__name__
'fdia_env.stealth.stealth_attack_v0'
"""

import importlib
from types import ModuleType

from fdia_env import scenarios
from fdia_env.episode import EpisodeSpec
from fdia_env.registration import ENVS, EnvEntry, register_env, register_envs
from fdia_env.systems import LinearSystem, Sensor, position_sensor, pv_sensor, tracking_system

register_envs()

__version__ = "0.1.0"  # the one place: pyproject.toml reads it ([tool.setuptools.dynamic])
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


def __getattr__(name: str) -> ModuleType:
    """``from fdia_env import <env>``: the module of a registered environment, imported lazily."""
    entry = ENVS.get(name)
    if entry is None:
        raise AttributeError(f"module 'fdia_env' has no attribute {name!r}")
    module = importlib.import_module(entry.module)
    globals()[name] = module
    return module


def __dir__() -> list[str]:
    return sorted({*globals(), *ENVS})
