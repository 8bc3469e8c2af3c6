"""Native batched vector environments (B envs as one numpy or torch computation), SB3 adapter."""

from fdia_env.envs.engine import BatchedSimulation
from fdia_env.vector.env import FdiaVectorEnv, make_vector
from fdia_env.vector.sequential import SequentialVectorEnv  # registers its make_vec format

__all__ = ["BatchedSimulation", "FdiaVectorEnv", "SequentialVectorEnv", "make_vector"]
