"""A fixed attack as a policy for ``stealth_attack_v0`` (stable-baselines3 signature)."""

from __future__ import annotations

from typing import Any

import numpy as np

from fdia_env.envs.opponents import FixedMix
from fdia_env.envs.policy import PolicyBase, repeat_action


class StealthPolicy(PolicyBase):
    """Plays one fixed action at every step (the static attack is the same on every snapshot).

    Args:
        action: For ``action="shift"`` or ``"box_shift"``: the (n,) 0/1 bits of the states to
            shift; for ``action="free"``: the (m,) injection over ``a_max``, entries in [-1, 1].
        kind: ``"shift"``, ``"box_shift"`` or ``"free"``, the env's ``action`` option it plays.

    Example:
        >>> policy = StealthPolicy([0, 1, 1], kind="shift")
        >>> policy.predict(np.zeros(3, dtype=np.float32))[0].tolist()
        [0, 1, 1]
    """

    def __init__(self, action: Any, kind: str = "shift") -> None:
        if kind not in ("shift", "box_shift", "free"):
            raise ValueError(f"kind must be 'shift', 'box_shift' or 'free', got {kind!r}")
        arr = np.asarray(action, dtype=np.float64).reshape(-1)
        if arr.size == 0 or not np.all(np.isfinite(arr)):
            raise ValueError(f"action must be a non-empty finite vector, got {action!r}")
        if kind in ("shift", "box_shift"):
            if not np.isin(arr, (0.0, 1.0)).all():
                raise ValueError(
                    f"a {kind!r} action holds 0/1 per state: this attack's state shift is not "
                    "0/1 (use kind='free' with the injection over a_max)"
                )
            self.action = arr.astype(np.int8)
        else:
            if np.abs(arr).max() > 1.0 + 1e-12:
                raise ValueError(
                    f"a 'free' action is the injection over a_max, in [-1, 1]; got entries up "
                    f"to {np.abs(arr).max():.6g}: raise a_max"
                )
            self.action = np.clip(arr, -1.0, 1.0).astype(np.float32)
        self.kind = kind
        self.action.setflags(write=False)

    def act(self, observation: Any, deterministic: bool = False) -> np.ndarray:
        """The fixed action, (B, d) for a (B, 3) batch."""
        return repeat_action(self.action, observation)


class MixedActionPolicy(PolicyBase):
    """Plays row ``i`` of a fixed action table with probability ``probs[i]``, every step anew.

    An equilibrium's mixed strategy as a policy (the protection game's attacker over its
    attacks, its defender over protected meter sets). Sampling is by
    :class:`~fdia_env.envs.opponents.FixedMix` (own seeded generator, ``reset(seed)``,
    ``deterministic`` ignored on purpose: a mixed equilibrium is one only when sampled).

    Args:
        actions: (K, d) the actions (one per pure strategy).
        probs: (K,) probabilities ≥ 0 summing to 1.
        seed: Seed of the policy's generator.
        dtype: The actions' dtype (the action space's: float32 for a ``Box``, int8 for a
            ``MultiBinary``).

    Example:
        >>> policy = MixedActionPolicy([[1, 0], [0, 1]], [0.0, 1.0], seed=0, dtype=np.int8)
        >>> policy.predict(np.zeros(3))[0].tolist()
        [0, 1]
    """

    def __init__(
        self, actions: Any, probs: Any, seed: int | None = None, dtype: Any = np.float32
    ) -> None:
        table = np.array(actions, dtype=np.float64)
        if table.ndim != 2 or 0 in table.shape or not np.all(np.isfinite(table)):
            raise ValueError(f"actions must be a finite (K, d) table, got shape {table.shape}")
        table = table.astype(dtype)
        self.mix = FixedMix(probs, seed)
        if self.mix.n_actions != table.shape[0]:
            raise ValueError(
                f"probs must have one entry per action ({table.shape[0]}), got {self.mix.n_actions}"
            )
        table.setflags(write=False)
        self.actions = table

    @property
    def probs(self) -> np.ndarray:
        """(K,) the mix's probabilities."""
        return self.mix.probs

    def reset(self, seed: int | None = None) -> None:
        """Restart the generator from ``seed`` (nothing happens without one)."""
        self.mix.reset(seed)

    def act(self, observation: Any, deterministic: bool = False) -> np.ndarray:
        """A drawn row, or (B, d) rows for a (B, ...) batch."""
        return self.actions[np.asarray(self.mix.act(observation))].copy()
