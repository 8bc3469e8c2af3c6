"""A solver's attack plan as a policy for ``sparse_attack_v0`` (stable-baselines3 signature)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from fdia_env._validation import check_int
from fdia_env.attacks.sparse import subset_format
from fdia_env.envs.policy import PolicyBase, observation_array

if TYPE_CHECKING:  # a result builds its policy (SparseResult.policy): the import goes that way
    from baselines.sparse.result import SparseResult


class SparsePolicy(PolicyBase):
    """Plays a fixed open-loop plan: at window step k, attack the sensors of ``actions[k]``.

    The step is recovered from the observation: ``observation[0] = steps_left / N`` in
    ``sparse_attack_v0``, so ``k = N − round(observation[0] · N)``. Steps outside the window
    (the terminal observation) get action 0.

    Args:
        actions: (N,) bitmask per step (bit 0 = sensor 1), e.g. :meth:`SparseResult.actions`,
            for the ``Discrete(2**M)`` action; or an (N, M) 0/1 plan (:meth:`SparseResult.plan`)
            for the ``MultiBinary(M)`` action of envs with more than 16 sensors.
        sequential: Play the plan in the ``action="sequential"`` format (``Discrete(M + 1)``):
            at each decision, the lowest-numbered sensor of the step's row that is not yet in
            the set being built (read from the observation's set entries), else 0 (stop).
            Needs an (N, M) plan.

    Example:
        >>> policy = SparsePolicy([0, 0, 1, 1, 1, 3])
        >>> policy.predict({"observation": np.array([4 / 6, 0.0]), "action_mask": None})[0]
        np.int64(1)
    """

    def __init__(self, actions: Sequence[int] | np.ndarray, sequential: bool = False) -> None:
        arr = np.asarray(actions)
        if not isinstance(sequential, bool):
            raise TypeError(f"sequential must be a bool, got {type(sequential).__name__}")
        if sequential and arr.ndim != 2:
            raise ValueError(
                f"sequential=True needs an (N, M) 0/1 plan (SparseResult.plan()), got {actions!r}"
            )
        self.sequential = sequential
        ints = np.issubdtype(arr.dtype, np.integer) or arr.dtype == bool
        if arr.ndim not in (1, 2) or arr.size == 0 or not ints:
            raise ValueError(
                "actions must be a non-empty 1-D sequence of bitmasks or an (N, M) 0/1 plan, "
                f"got {actions!r}"
            )
        if arr.ndim == 2 and not np.isin(arr, (0, 1)).all():
            raise ValueError(f"an (N, M) plan must hold only 0 and 1, got {arr.tolist()}")
        if (arr < 0).any():
            raise ValueError(f"actions must be non-negative bitmasks, got {arr.tolist()}")
        self.actions = arr.astype(np.int64)
        self.actions.setflags(write=False)
        self.horizon = check_int("horizon", arr.shape[0], minimum=1)

    @classmethod
    def from_result(cls, result: SparseResult, action: str = "auto") -> SparsePolicy:
        """The policy that plays ``result.attacks`` in the env's ``action`` format.

        Args:
            result: A solver's answer.
            action: ``"auto"`` (bitmask up to 16 sensors, a 0/1 plan above, as the env's
                default), ``"bitmask"``, ``"multibinary"`` or ``"sequential"`` (see the class
                doc).

        Raises:
            ValueError: For another format, or ``"bitmask"`` above 16 sensors.
        """
        formats = ("auto", "bitmask", "multibinary", "sequential")
        if action not in formats:
            raise ValueError(
                f"action must be one of {formats} (the formats a plan can be played in; "
                f"'single' attacks at most one sensor a step), got {action!r}"
            )
        action = subset_format(action, result.num_sensors, "'multibinary' or 'sequential'")
        if action == "bitmask":
            return cls(result.actions())
        return cls(result.plan(), sequential=action == "sequential")

    def step_of(self, observation: Any) -> np.ndarray:
        """Window step(s) encoded in a (d,) or (B, d) observation (dict or plain Box)."""
        obs = observation_array(observation, dtype=np.float64)
        steps_left = np.rint(obs[..., 0] * self.horizon).astype(np.int64)
        return self.horizon - steps_left

    def act(self, observation: Any, deterministic: bool = False) -> Any:
        """The bitmask for the current step (the plan is open loop).

        Args:
            observation: The env's dict observation (``{"observation", "action_mask"}``) or the
                Gymnasium view's Box, unbatched (d,) or batched (B, d).
            deterministic: Ignored (the policy is deterministic).

        Returns:
            An ``np.int64`` action for one observation, a (B,) array for a batch; with an
            (N, M) plan an (M,) int8 MultiBinary action, (B, M) for a batch.
        """
        step = self.step_of(observation)
        inside = (step >= 0) & (step < self.horizon)
        if self.sequential:
            return self._sequential_action(observation, step, inside)
        if self.actions.ndim == 2:  # MultiBinary rows; zeros outside the window
            rows = self.actions[np.clip(step, 0, self.horizon - 1)]
            return np.where(np.asarray(inside)[..., None], rows, 0).astype(np.int8)
        action = np.where(inside, self.actions[np.clip(step, 0, self.horizon - 1)], 0)
        return np.int64(action) if action.ndim == 0 else action

    def _sequential_action(self, observation: Any, step: np.ndarray, inside: np.ndarray) -> Any:
        """Next sensor (1-based) of the step's row not yet in the set, else 0 (stop)."""
        M = self.actions.shape[1]
        chosen = observation_array(observation, dtype=np.float64)[..., -(M + 1) : -1] > 0.5
        todo = (self.actions[np.clip(step, 0, self.horizon - 1)] == 1) & ~chosen
        todo &= np.asarray(inside)[..., None]
        action = np.where(todo.any(-1), todo.argmax(-1) + 1, 0).astype(np.int64)
        return np.int64(action) if action.ndim == 0 else action
