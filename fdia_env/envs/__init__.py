"""Environments: the simulation engine, the PettingZoo env and the Gymnasium view."""

from fdia_env.envs.grid_family import GridFamily
from fdia_env.envs.parallel import FdiaParallelEnv
from fdia_env.envs.policy import MaskedPolicyBase, PolicyBase, SampledPolicyBase
from fdia_env.envs.simulation import Simulation
from fdia_env.envs.single_agent import Policy, SingleAgentEnv, make_single_agent
from fdia_env.envs.system_family import SystemFamilyEnv, TrackingFamily

__all__ = [
    "FdiaParallelEnv",
    "GridFamily",
    "MaskedPolicyBase",
    "Policy",
    "PolicyBase",
    "SampledPolicyBase",
    "Simulation",
    "SingleAgentEnv",
    "SystemFamilyEnv",
    "TrackingFamily",
    "make_single_agent",
]
