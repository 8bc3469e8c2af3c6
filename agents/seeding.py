"""One seeding function for every source of randomness a training run uses."""

from __future__ import annotations

import random

import numpy as np
import torch

SEED_LIMIT = 2**32 - 1


def seed_everything(seed: int, torch_threads: int | None = None) -> np.random.Generator:
    """Seed Python's ``random``, NumPy's global generator and torch; return a fresh Generator.

    The envs draw from their own ``np_random`` (seeded by ``reset(seed=...)``) and
    stable-baselines3 models take ``seed=`` for their action spaces; this covers the rest
    (network initialisation, minibatch shuffling, any library using the global generators).

    Args:
        seed: Integer seed in [0, 2**32 - 1] (NumPy's legacy generator and SB3 take no more).
        torch_threads: If given, ``torch.set_num_threads`` (one thread is fastest for these
            small networks and keeps CPU runs reproducible).

    Returns:
        ``np.random.default_rng(seed)`` for the caller's own draws.

    Raises:
        ValueError: For a seed that is not an integer in [0, 2**32 - 1].

    Example:
        >>> a = seed_everything(3).random(); b = seed_everything(3).random()
        >>> a == b
        True
    """
    if (
        isinstance(seed, bool)
        or not isinstance(seed, int | np.integer)
        or not 0 <= seed <= SEED_LIMIT
    ):
        raise ValueError(f"seed must be an integer in [0, {SEED_LIMIT}], got {seed!r}")
    if torch_threads is not None and (
        isinstance(torch_threads, bool) or not isinstance(torch_threads, int) or torch_threads < 1
    ):
        raise ValueError(f"torch_threads must be an integer >= 1, got {torch_threads!r}")
    seed = int(seed)
    random.seed(seed)
    np.random.seed(seed)  # noqa: NPY002 - the legacy global some libraries still use
    torch.manual_seed(seed)
    if torch_threads is not None:
        torch.set_num_threads(torch_threads)
    return np.random.default_rng(seed)


def derived_seed(seed: int, offset: int) -> int:
    """``seed + offset`` wrapped into [0, 2**32 - 1], the seeds SB3 and NumPy accept.

    Runs draw several streams from one seed (evaluation, final evaluation, each self-play best
    response) by offsets; wrapping keeps a seed near the top of the range usable.

    >>> derived_seed(2**32 - 1, 10_000)
    9999
    """
    return (int(seed) + int(offset)) % (SEED_LIMIT + 1)
