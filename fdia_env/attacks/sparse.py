"""Sparse attack: the attacker picks sensor-time pairs within a budget c (docs/math.md §4)."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from fdia_env._validation import check_choice, check_int
from fdia_env.attacks.base import (
    AttackModel,
    mask_array_to_bits,
    mask_to_bits,
)
from fdia_env.backend import NUMPY, ONE
from fdia_env.episode import EpisodeSpec
from fdia_env.systems import LinearSystem

MAX_SENSORS = 16
"""Largest M of the ``Discrete(2**M)`` bitmask action (``action="auto"`` switches above it)."""
ACTION_FORMATS = ("auto", "bitmask", "multibinary", "single")
ILLEGAL_ACTIONS = ("trim", "error", "noop")


def trim_to_budget(bits: int, remaining: int) -> int:
    """Over-budget rule: keep the lowest-numbered selected sensors that fit ``remaining``."""
    kept = 0
    while bits and remaining > 0:
        low = bits & -bits  # lowest set bit
        kept |= low
        bits ^= low
        remaining -= 1
    return kept


def subset_format(action: str, num_sensors: int, instead: str) -> str:
    """The format ``action`` names for ``num_sensors`` sensors (``"auto"`` resolved).

    ``"auto"`` is ``"bitmask"`` up to :data:`MAX_SENSORS` sensors and ``"multibinary"`` above;
    any other format is returned as it is.

    Args:
        action: A format name (``"auto"``, ``"bitmask"``, ...).
        num_sensors: M.
        instead: The formats the error suggests above :data:`MAX_SENSORS` sensors.

    Raises:
        ValueError: For ``"bitmask"`` above :data:`MAX_SENSORS` sensors.
    """
    if action == "auto":
        return "bitmask" if num_sensors <= MAX_SENSORS else "multibinary"
    if action == "bitmask" and num_sensors > MAX_SENSORS:
        raise ValueError(
            f"action='bitmask' takes at most {MAX_SENSORS} sensors (a subset per action), "
            f"got {num_sensors} sensors: use {instead}"
        )
    return action


class SparseAttack(AttackModel):
    """Attack up to ``budget`` sensor-time pairs over the window.

    Action formats (``action``):

    - ``"bitmask"``: ``Discrete(2**M)``; action ``a`` attacks the sensors whose bits are set in
      ``a`` (bit 0 = sensor 1), so 0 is "no attack". ``action_mask`` (2**M,) marks the subsets
      no larger than the remaining budget. At most :data:`MAX_SENSORS` sensors.
    - ``"multibinary"``: ``MultiBinary(M)``, entry i = 1 attacks sensor i; no action mask (the
      observation is a plain ``Box``): sb3-contrib's MaskablePPO masks a MultiBinary action
      per entry (a (2M,) mask of independent Bernoullis), so a mask could not say "at most r
      ones" anyway, and Gymnasium's own MultiBinary mask has another shape, (M,) with values
      0/1/2, so one mask could not serve both; the trimming rule below keeps the budget. Train
      it with PPO/A2C (SB3 supports MultiBinary), or use ``"single"`` with MaskablePPO.
    - ``"single"``: ``Discrete(M + 1)``, action 0 attacks nothing and action j attacks sensor
      j (1-based) alone; ``action_mask`` (M+1,) allows only 0 once the budget is spent.
    - ``"auto"`` (default): ``"bitmask"`` for M <= 16, ``"multibinary"`` above.

    Over-budget rule (every format, ``illegal_action``): an action that selects more sensors
    than the budget left is illegal (its ``action_mask`` entry is 0 where there is a mask).
    ``"trim"`` (default) keeps the lowest-numbered selected sensors that fit, ``"noop"``
    attacks nothing, ``"error"`` raises a ``ValueError`` naming the action and the budget left.
    No episode ever spends more than ``budget``.

    Features: the remaining budget as a fraction of ``budget`` (0 when ``budget`` is 0).

    Args:
        budget: c, the sensor-time pairs the attacker may corrupt over the window (>= 0).
        action: ``"auto"``, ``"bitmask"``, ``"multibinary"`` or ``"single"`` (see above).
        illegal_action: ``"trim"``, ``"noop"`` or ``"error"`` (see above).
    """

    name = "sparse"

    def __init__(self, budget: int, action: str = "auto", illegal_action: str = "trim") -> None:
        self.budget = check_int("budget", budget, minimum=0)
        if action == "sequential":
            raise ValueError(
                "action='sequential' is a wrapper of the sparse_attack_v0 env, not an attack "
                "model format: use sparse_attack_v0.parallel_env/env(action='sequential') or "
                "the Gymnasium view (not yet the native vector env); the model takes "
                f"action in {list(ACTION_FORMATS)}"
            )
        self.action_format = check_choice("action", action, ACTION_FORMATS)
        self.illegal_action = check_choice("illegal_action", illegal_action, ILLEGAL_ACTIONS)

    def bind(self, system: LinearSystem, spec: EpisodeSpec) -> None:
        """Build the action space for ``system`` and check the budget fits the window."""
        fmt = subset_format(self.action_format, system.M, "'multibinary' or 'single'")
        if self.budget > system.M * spec.horizon:
            raise ValueError(
                f"budget must be <= M * horizon = {system.M * spec.horizon} (every sensor-time "
                f"pair of the window: M = {system.M} sensors, horizon = {spec.horizon} steps, "
                f"which is max_cycles when only that is given), got {self.budget}"
            )
        self.M = system.M
        self.format = fmt
        self._b_xp = None  # the backend of the cached constants (see batch_reset)
        self.feature_low = np.zeros(1, dtype=np.float32)
        self.feature_high = np.ones(1, dtype=np.float32)
        if fmt != "bitmask":
            self._bind_large(fmt)
            return
        self.n_actions = 2**system.M
        self.action_space = spaces.Discrete(self.n_actions)
        self._sizes = np.array([a.bit_count() for a in range(self.n_actions)])
        self._trim_table: np.ndarray | None = None  # built on first use (see _tables)

    def _bind_large(self, fmt: str) -> None:
        """Spaces and masks of the ``"multibinary"`` and ``"single"`` formats."""
        M = self.M
        if fmt == "multibinary":
            self.action_space = spaces.MultiBinary(M)
        else:
            self.n_actions = M + 1
            self.action_space = spaces.Discrete(M + 1)
            # row min(budget left, 1): only "no attack" once the budget is spent, else all
            self._single_masks = np.ones((2, M + 1), dtype=np.int8)
            self._single_masks[0, 1:] = 0

    def _illegal(self, bits: int, remaining: int, action: Any) -> int:
        """What an over-budget action (sensor bitmask ``bits``) does, by ``illegal_action``."""
        if self.illegal_action == "error":
            shown = action if self.format != "multibinary" else np.asarray(action).tolist()
            raise ValueError(
                f"attacker action {shown} (sensors {_sensors(bits)}) is illegal: it attacks "
                f"{bits.bit_count()} sensors with {remaining} of the budget left; legal actions "
                f"are those with action_mask[a] = 1 (at most {remaining} sensors)"
            )
        return 0 if self.illegal_action == "noop" else trim_to_budget(bits, remaining)

    @property
    def remaining(self) -> int:
        """The budget left of the single env (member 0 of the batch)."""
        return int(self.xp.member(self.b_remaining, 0))

    # --- batched (see AttackModel; numpy or torch arrays of the backend ``xp``) -------------
    batch_backends = ("numpy", "torch")

    def batch_reset(self, batch: int, where: Any = None) -> None:
        """Restore the full budget of the members ``where``."""
        xp = self.xp
        if where is None or xp.all(where):  # every member (episodes of one length end together)
            self.b_remaining = xp.full(batch, self.budget, dtype=xp.int64)
            self.b_attacked = xp.zeros((batch, self.M), dtype=xp.int8)
            if self._b_xp is not xp:  # the backend's constants, once per backend change
                # a 0-d float64 array: int64 × it is float64 on numpy and torch alike (a
                # Python float would give torch's default float32)
                self._b_scale = xp.asarray(np.float64(1.0 / self.budget if self.budget else 0.0))
                if self.format == "bitmask":
                    self._b_tables = self._tables()  # read every step: kept as an attribute
                self._b_xp = xp
        else:  # fresh arrays: the infos handed out earlier never change afterwards
            self.b_remaining = xp.where(where, self.budget, self.b_remaining)
            self.b_attacked = xp.where(where[:, None], 0, self.b_attacked)

    def batch_features(self) -> Any:
        """(B, 1) remaining budget fraction."""
        return self.xp.col(self.b_remaining * self._b_scale)

    def _batch_tables(self) -> None:
        """Tables indexed by [action, min(budget left, M)]: the trimmed action, and masks."""
        actions = np.arange(self.n_actions)[:, None]
        left = np.arange(self.M + 1)[None, :]
        kept = np.zeros((self.n_actions, self.M + 1), dtype=np.int64)
        count = np.zeros_like(kept)
        for i in range(self.M):  # keep the lowest-numbered selected sensors that fit
            take = ((actions >> i) & 1) & (count < left)
            kept |= take << i
            count += take
        self._trim_table = kept.reshape(-1)  # flat: index action * (M + 1) + left
        self._mask_table = (self._sizes[None, :] <= left.T).astype(np.int8)
        self._bit_table = ((actions >> np.arange(self.M)) & 1).astype(np.int8)  # (A, M)

    def _tables(self) -> tuple[Any, Any, Any, Any]:
        """``(trim, mask, sizes, bits)`` tables on the backend (built once, moved once)."""
        if self._trim_table is None:  # bind() cleared it: new tables, nothing cached
            self._batch_tables()
            self._xp_tables = None
        xp = self.xp
        cached = self._xp_tables
        if cached is None or cached[0] is not xp:
            arrays = (self._trim_table, self._mask_table, np.asarray(self._sizes, np.int64))
            bits = self._bit_table
            if xp is NUMPY and self.M <= 8:  # each row as one 1/2/4/8-byte word (see _attacked)
                width = 1 << (self.M - 1).bit_length()
                padded = np.zeros((bits.shape[0], width), dtype=np.int8)
                padded[:, : self.M] = bits
                bits = padded.view(f"<u{width}").reshape(-1)
            self._xp_tables = (xp, *(xp.asarray(a) for a in arrays), xp.asarray(bits))
        return self._xp_tables[1:]

    def _attacked(self, a: Any) -> Any:
        """(B, M) int8 sensors attacked by the bitmasks ``a``, looked up in the bit table.

        On numpy with M <= 8 the table's rows are packed into one machine word each, so the
        lookup gathers B words (a gather of B rows of M bytes is several times slower); the
        result is a view of the words' first M bytes.
        """
        bits = self._b_tables[3]
        if bits.ndim == 2:
            return self.xp.take(bits, a, axis=0)
        width = bits.dtype.itemsize
        rows = np.take(bits, a).view(np.int8).reshape(a.shape[0], width)
        return rows if width == self.M else rows[:, : self.M]

    def batch_action_mask(self) -> Any:
        """(B, A) legal actions of each member for its budget left (see :meth:`action_mask`)."""
        xp = self.xp
        if self.format == "multibinary":
            return None
        if self.format == "single":
            return xp.take(xp.asarray(self._single_masks), xp.minimum(self.b_remaining, 1), axis=0)
        _, mask_table, _, _ = self._b_tables
        return xp.take(mask_table, xp.minimum(self.b_remaining, self.M), axis=0)

    def _batch_apply_large(self, actions: Any) -> tuple[Any, None]:
        """Batched ``"multibinary"`` / ``"single"`` actions: the same trimming rule."""
        xp = self.xp
        if self.format == "single":
            j = xp.astype(actions, xp.int64)  # checked by the vector env
            chosen = xp.arange(self.M) == xp.col(j - 1)  # j = 0 matches no sensor
        else:
            chosen = xp.astype(actions, xp.bool)  # 0/1 of any real dtype, checked
        over = xp.sum(chosen, 1) > self.b_remaining
        if self.illegal_action != "trim" and xp.any(over):
            i = int(xp.flatnonzero(over)[0])
            row, shown = xp.member(chosen, i), xp.member(actions, i)
            bits = int(mask_array_to_bits(xp.to_numpy(row)[None])[0])
            shown = xp.to_numpy(shown) if self.format == "multibinary" else int(shown)
            self._illegal(bits, int(xp.member(self.b_remaining, i)), shown)  # raises: "error"
            chosen = xp.where(xp.col(over), False, chosen)  # "noop"
        # keep the lowest-numbered chosen sensors that fit each member's budget left
        kept = chosen & (xp.cumsum(chosen, 1) <= xp.col(self.b_remaining))
        self.b_remaining = self.b_remaining - xp.sum(kept, 1)
        self.b_attacked = xp.astype(kept, xp.int8)
        if xp is ONE:
            return mask_to_bits(kept), None
        return (mask_array_to_bits(kept) if xp is NUMPY else kept), None

    def batch_apply(self, actions: Any) -> tuple[Any, None]:
        """Attack each member's subset, trimmed to its budget (same rule as :meth:`apply`)."""
        if self.format != "bitmask":
            return self._batch_apply_large(actions)
        xp = self.xp
        a = xp.astype(actions, xp.int64)  # checked by the vector env
        trim, _, sizes, _ = self._b_tables
        if self.illegal_action != "trim":
            over = xp.take(sizes, a) > self.b_remaining
            if xp.any(over):
                i = int(xp.flatnonzero(over)[0])
                shown = int(xp.member(a, i))
                self._illegal(shown, int(xp.member(self.b_remaining, i)), shown)  # "error" raises
                a = xp.where(over, 0, a)
        a = xp.take(trim, a * (self.M + 1) + xp.minimum(self.b_remaining, self.M))
        self.b_remaining = self.b_remaining - xp.take(sizes, a)
        self.b_attacked = self._attacked(a)
        return a, None

    def batch_info(self) -> dict[str, Any]:
        """Batched :meth:`info` (arrays of this step: the next step and resets make new ones)."""
        return {"attacked": self.b_attacked, "budget_left": self.b_remaining}


def _sensors(bits: int) -> list[int]:
    """The 1-based sensor numbers whose bits are set."""
    return [i + 1 for i in range(bits.bit_length()) if bits >> i & 1]
