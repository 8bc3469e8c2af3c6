"""Native batched vector environments (B envs as one numpy or torch computation), SB3 adapter."""

from fdia_env.envs.engine import BatchedSimulation
from fdia_env.vector.env import FdiaVectorEnv, make_vector

__all__ = ["BatchedSimulation", "FdiaVectorEnv", "make_vector"]
