"""Native batched vector environments (B envs as one numpy or torch computation), SB3 adapter."""

from fdia_env.vector.env import FdiaVectorEnv, make_vector
from fdia_env.vector.sequential import SequentialVectorEnv  # registers its make_vec format
from fdia_env.vector.simulation import BatchedSimulation

__all__ = ["BatchedSimulation", "FdiaVectorEnv", "SequentialVectorEnv", "make_vector"]
