"""One seeding function for every source of randomness a training run uses."""

from __future__ import annotations

import random

import numpy as np
import torch


def seed_everything(seed: int, torch_threads: int | None = None) -> np.random.Generator:
    """Seed Python's ``random``, NumPy's global generator and torch; return a fresh Generator.

    The envs draw from their own ``np_random`` (seeded by ``reset(seed=...)``) and
    stable-baselines3 models take ``seed=`` for their action spaces; this covers the rest
    (network initialisation, minibatch shuffling, any library using the global generators).

    Args:
        seed: Non-negative integer seed.
        torch_threads: If given, ``torch.set_num_threads`` (one thread is fastest for these
            small networks and keeps CPU runs reproducible).

    Returns:
        ``np.random.default_rng(seed)`` for the caller's own draws.

    Raises:
        ValueError: For a seed that is not a non-negative integer.

    Example:
        >>> a = seed_everything(3).random(); b = seed_everything(3).random()
        >>> a == b
        True
    """
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise ValueError(f"seed must be a non-negative integer, got {seed!r}")
    seed = int(seed)
    random.seed(seed)
    np.random.seed(seed % 2**32)  # noqa: NPY002 - the legacy global some libraries still use
    torch.manual_seed(seed)
    if torch_threads is not None:
        torch.set_num_threads(torch_threads)
    return np.random.default_rng(seed)
