"""A fixed attack as a policy for ``stealth_attack_v0`` (stable-baselines3 signature)."""

from __future__ import annotations

from typing import Any

import numpy as np


class StealthPolicy:
    """Plays one fixed action at every step (the static attack is the same on every snapshot).

    Args:
        action: For ``action="shift"``: the (n,) 0/1 bits of the states to shift; for
            ``action="free"``: the (m,) injection over ``a_max``, entries in [-1, 1].
        kind: ``"shift"`` or ``"free"``, the env's ``action`` option it plays.

    Example:
        >>> policy = StealthPolicy([0, 1, 1], kind="shift")
        >>> policy.predict(np.zeros(3, dtype=np.float32))[0].tolist()
        [0, 1, 1]
    """

    def __init__(self, action: Any, kind: str = "shift") -> None:
        if kind not in ("shift", "free"):
            raise ValueError(f"kind must be 'shift' or 'free', got {kind!r}")
        arr = np.asarray(action, dtype=np.float64).reshape(-1)
        if arr.size == 0 or not np.all(np.isfinite(arr)):
            raise ValueError(f"action must be a non-empty finite vector, got {action!r}")
        if kind == "shift":
            if not np.isin(arr, (0.0, 1.0)).all():
                raise ValueError(
                    "a 'shift' action holds 0/1 per state: this attack's state shift is not "
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

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """Return ``(action, state)``: the fixed action, (B, d) for a (B, 3) batch."""
        obs = observation["observation"] if isinstance(observation, dict) else observation
        obs = np.asarray(obs)
        if obs.ndim == 2:
            return np.tile(self.action, (obs.shape[0], 1)), state
        return self.action.copy(), state
