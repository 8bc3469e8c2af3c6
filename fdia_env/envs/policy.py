"""Stable-baselines3's ``predict`` for the suite's own policies, written once.

Every policy the suite ships (the baselines' plans and mixes, the fixed opponents, the random
and RLlib players of ``agents``) answers ``predict(observation, state, episode_start,
deterministic)`` like an SB3 model, so the evaluators and the single-agent views take them
interchangeably. A policy subclasses :class:`PolicyBase` (or :class:`MaskedPolicyBase` when it
reads action masks) and writes only :meth:`PolicyBase.act`: the action for an unbatched (d,)
or batched (B, d) observation. The policies have no memory, so ``predict`` hands ``state``
back as given and ignores ``episode_start``.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol

import numpy as np


class Policy(Protocol):
    """Anything with stable-baselines3's ``predict`` signature (SB3 models, baseline policies)."""

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = False,
    ) -> tuple[Any, Any]:
        """Return ``(action, state)``."""
        ...


def observation_array(observation: Any, dtype: Any = None) -> np.ndarray:
    """The array of an observation: a dict's ``"observation"`` entry, None as an empty array.

    Args:
        observation: A Box observation (unbatched (d,) or batched (B, d)), a dict observation
            (``{"observation", "action_mask"}``) or None.
        dtype: Passed to :func:`numpy.asarray` (None keeps the observation's own).

    Returns:
        The observation as an array; ``np.zeros(0)`` for None.

    Example:
        >>> observation_array({"observation": [0.5, 1.0], "action_mask": [1, 0]}).tolist()
        [0.5, 1.0]
        >>> observation_array(None).shape
        (0,)
    """
    if isinstance(observation, Mapping):
        observation = observation["observation"]
    if observation is None:
        return np.zeros(0)
    return np.asarray(observation, dtype=dtype)


def batch_size(observation: Any) -> int | None:
    """B for a batched (B, d) observation, None for an unbatched (d,) one (dict or Box)."""
    obs = observation_array(observation)
    return int(obs.shape[0]) if obs.ndim >= 2 else None


def repeat_action(action: np.ndarray, observation: Any) -> np.ndarray:
    """``action`` for every member of a batched observation, a copy of it for an unbatched one.

    Example:
        >>> repeat_action(np.array([1, 0]), np.zeros((3, 4))).shape
        (3, 2)
    """
    batch = batch_size(observation)
    if batch is None:
        return action.copy()
    return np.repeat(action[None], batch, axis=0)


def check_action_masks(action_masks: Any, batch: int | None, size: int | None = None) -> Any:
    """``action_masks`` as a 0/1 bool array, or a ``ValueError`` naming what is wrong.

    Args:
        action_masks: None, one (n,) mask (an unbatched observation) or (B, n) masks.
        batch: B for a batched observation, None for an unbatched one.
        size: n when the policy knows its number of actions (None: any).

    Returns:
        None for None, else the masks as a bool array of shape (n,) or (B, n).

    Raises:
        ValueError: Naming ``action_masks``: not numeric, not 0/1, the wrong shape for the
            observation (or for ``size`` actions), or a mask with no legal action.

    Example:
        >>> check_action_masks([1, 0, 1], None).tolist()
        [True, False, True]
        >>> check_action_masks([[0, 0]], 1)
        Traceback (most recent call last):
        ...
        ValueError: action_masks: mask 0 allows no action (every entry is 0)
    """
    if action_masks is None:
        return None
    try:
        masks = np.asarray(action_masks)
    except (TypeError, ValueError):
        masks = np.asarray(None)
    if masks.dtype == object or not (masks.dtype == bool or np.issubdtype(masks.dtype, np.number)):
        raise ValueError(f"action_masks must be a 0/1 (or bool) array, got {action_masks!r}")
    want = 1 if batch is None else 2
    if masks.ndim != want or (batch is not None and masks.shape[0] != batch):
        shape = "(n,)" if batch is None else f"({batch}, n)"
        raise ValueError(
            f"action_masks must have shape {shape} for this observation, got {masks.shape}"
        )
    if size is not None and masks.shape[-1] != size:
        raise ValueError(f"action_masks must have {size} entries per mask, got {masks.shape[-1]}")
    if not np.isin(masks, (0, 1)).all():
        raise ValueError("action_masks must hold only 0 and 1 (or booleans)")
    legal = masks.astype(bool)
    empty = np.flatnonzero(~legal.reshape(-1, legal.shape[-1]).any(axis=-1))
    if empty.size:
        raise ValueError(f"action_masks: mask {int(empty[0])} allows no action (every entry is 0)")
    return legal


class PolicyBase:
    """A memoryless policy with stable-baselines3's ``predict``; subclasses write :meth:`act`."""

    def act(self, observation: Any, deterministic: bool = False) -> Any:
        """The action for ``observation`` (unbatched (d,) or batched (B, d); dict or Box)."""
        raise NotImplementedError(f"{type(self).__name__} must implement act()")

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = False,
    ) -> tuple[Any, Any]:
        """Return ``(action, state)``: :meth:`act`'s action and ``state`` as given.

        Args:
            observation: Unbatched (d,) or batched (B, d) observation, a dict observation (its
                ``"observation"`` entry is used) or, where the policy ignores it, None.
            state: Returned as given (the policy has no memory).
            episode_start: Ignored.
            deterministic: Passed to :meth:`act` (the class docstring says whether it is read).

        Returns:
            ``(action, state)``, the action batched like ``observation``.
        """
        return self.act(observation, deterministic), state


class MaskedPolicyBase(PolicyBase):
    """A :class:`PolicyBase` that reads action masks (``predict(..., action_masks=...)``).

    The evaluators pass masks to a policy whose ``predict`` takes ``action_masks``, as
    sb3-contrib's MaskablePPO does; :meth:`act` gets them checked (a bool array, None when the
    env has none). ``mask_size`` is the number of actions a mask must have (None: any).
    """

    mask_size: int | None = None

    def act(self, observation: Any, deterministic: bool = False, action_masks: Any = None) -> Any:
        """The action for ``observation``, legal under ``action_masks`` when given."""
        raise NotImplementedError(f"{type(self).__name__} must implement act()")

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = False,
        action_masks: Any = None,
    ) -> tuple[Any, Any]:
        """Return ``(action, state)``: :meth:`act`'s action (under ``action_masks``), ``state``.

        Raises:
            ValueError: Naming ``action_masks`` when they are malformed
                (:func:`check_action_masks`; ``mask_size`` is the policy's number of actions).
        """
        masks = check_action_masks(action_masks, batch_size(observation), self.mask_size)
        return self.act(observation, deterministic, masks), state


class SampledPolicyBase(PolicyBase):
    """A :class:`PolicyBase` that draws from its own seeded generator ``rng``.

    The single-agent views call :meth:`reset` with a seed on a seeded ``reset``, so seeded
    episodes replay the same draws.

    Args:
        seed: Seed of the policy's own generator.
    """

    def __init__(self, seed: int | None = None) -> None:
        self.rng = np.random.default_rng(seed)

    def reset(self, seed: int | None = None) -> None:
        """Restart the generator from ``seed`` (nothing happens without one)."""
        if seed is not None:
            self.rng = np.random.default_rng(seed)
