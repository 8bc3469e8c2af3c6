"""Defense models: which data the filter trusts."""

from fdia_env.defenses.base import DefenseModel, FilterInput
from fdia_env.defenses.perfect_detection import PerfectDetection
from fdia_env.defenses.unaware import UnawareFilter

__all__ = ["DefenseModel", "FilterInput", "PerfectDetection", "UnawareFilter"]
