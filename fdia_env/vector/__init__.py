"""Native batched vector environments (B envs as one numpy or torch computation), SB3 adapter."""

from fdia_env.envs.engine import BatchedSimulation
from fdia_env.vector.env import FdiaVectorEnv, make_vector
from fdia_env.vector.sequential import SequentialVectorEnv  # registers its make_vec format
from fdia_env.vector.sequential_game import SequentialGameVectorEnv  # the same, sensor game

__all__ = [
    "BatchedSimulation",
    "FdiaVectorEnv",
    "SequentialGameVectorEnv",
    "SequentialVectorEnv",
    "make_vector",
]
