"""Covariance attack: the attacker picks the bias covariance Σ under a power budget.

The formulas are those of docs/math.md §2.

The action is a ``Box`` in [-1, 1] holding the lower-triangular entries of a factor ``L`` (row by
row, per block); the map to Σ is

    Σ̃ = L L' / tr(L L'),    Σ = p · Ω^{-1/2} Σ̃ Ω^{-1/2},    so that  tr(Ω Σ) = p  exactly,

where ``p`` is the power spent this step and Ω the power weighting. It covers every admissible
Σ: any PSD Σ̃ of unit trace has a lower-triangular factor of unit Frobenius norm (from the QR
decomposition of a square root), whose entries therefore lie in [-1, 1];
:meth:`CovarianceMap.to_action` computes it. The all-zero factor maps to the uniform
Σ̃ = I / d. With ``structure="diagonal"`` (independent biases across sensors) ``L`` is block
diagonal, one block per sensor, so Σ is block diagonal.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces

from fdia_env._validation import as_matrix, check_choice, check_power, check_psd
from fdia_env.attacks.base import AttackEffect, AttackModel, mask_array_to_bits
from fdia_env.backend import NUMPY, Backend, namespace
from fdia_env.episode import EpisodeSpec
from fdia_env.kalman.linalg import psd_sqrt, sym
from fdia_env.systems import LinearSystem, power_weight

STRUCTURES = ("full", "diagonal")
POWER_MODES = ("per_step", "budget")


class CovarianceMap:
    """The bijection-up-to-scale between factor entries in [-1, 1] and bias covariances.

    Args:
        blocks: Row slices of the stacked measurement, one per independent block.
        weight: (nz, nz) symmetric positive definite power weighting Ω.
    """

    def __init__(self, blocks: list[slice], weight: np.ndarray) -> None:
        self.blocks = blocks
        self.nz = weight.shape[0]
        w, v = np.linalg.eigh(weight)
        self.w_half = (v * np.sqrt(w)) @ v.T  # Ω^{1/2}
        self.w_inv_half = (v / np.sqrt(w)) @ v.T  # Ω^{-1/2}
        self._tril = [np.tril_indices(b.stop - b.start) for b in blocks]
        self.size = sum(len(t[0]) for t in self._tril)

    def to_sigma(self, entries: np.ndarray, power: float) -> np.ndarray:
        """Σ with ``tr(Ω Σ) = power`` from (size,) factor entries."""
        L = np.zeros((self.nz, self.nz))
        start = 0
        for block, (r, c) in zip(self.blocks, self._tril, strict=True):
            L[block.start + r, block.start + c] = entries[start : start + len(r)]
            start += len(r)
        shape = L @ L.T
        total = np.trace(shape)
        shape = np.eye(self.nz) / self.nz if total <= 0.0 else shape / total
        return sym(power * (self.w_inv_half @ shape @ self.w_inv_half))

    def to_sigma_batch(self, entries: Any, power: Any) -> Any:
        """(B, nz, nz) covariances from (B, size) entries and (B,) powers (as :meth:`to_sigma`).

        numpy arrays or torch tensors (:mod:`fdia_env.backend`).
        """
        xp = namespace(entries)
        tril, eye, w_inv_half = self._constants(xp)
        B = entries.shape[0]
        L = xp.zeros((B, self.nz, self.nz))
        start = 0
        for rows, cols in tril:
            L[:, rows, cols] = entries[:, start : start + len(rows)]
            start += len(rows)
        shape = L @ L.swapaxes(-1, -2)
        total = xp.trace(shape)
        empty = total <= 0.0
        shape = xp.where(empty[:, None, None], eye / self.nz, shape)
        shape = shape / xp.where(empty, 1.0, total)[:, None, None]
        return sym(power[:, None, None] * (w_inv_half @ shape @ w_inv_half))

    def _constants(self, xp: Backend) -> tuple[list, Any, Any]:
        """The factor's row/column indices, I and Ω^{-1/2} on the backend (moved once)."""
        cached = getattr(self, "_xp_constants", None)
        if cached is None or cached[0] is not xp:
            tril = [
                (xp.asarray(block.start + r), xp.asarray(block.start + c))
                for block, (r, c) in zip(self.blocks, self._tril, strict=True)
            ]
            self._xp_constants = (xp, tril, xp.eye(self.nz), xp.asarray(self.w_inv_half))
        return self._xp_constants[1:]

    def to_action(self, sigma: np.ndarray) -> np.ndarray:
        """Factor entries whose :meth:`to_sigma` is ``sigma`` (up to its power)."""
        shape = sym(self.w_half @ sigma @ self.w_half)
        total = np.trace(shape)
        if total <= 0.0:
            return np.zeros(self.size)
        shape = shape / total
        out = []
        for block, (r, c) in zip(self.blocks, self._tril, strict=True):
            # Σ̃_b = S S' with S = sqrt(Σ̃_b); S' = Q U (QR) gives Σ̃_b = U' U, U' lower triangular
            S = psd_sqrt(shape[block, block])
            U = np.linalg.qr(S.T, mode="r")
            out.append(U.T[r, c])
        return np.clip(np.concatenate(out), -1.0, 1.0)


class CovarianceAttack(AttackModel):
    """Choose the bias covariance Σ over the stacked measurement under power a².

    Args:
        power: a² (> 0): per step (``power_mode="per_step"``) or in total over the window
            (``"budget"``).
        structure: ``"full"`` (dependent biases) or ``"diagonal"`` (independent across sensors:
            Σ block diagonal, one block per sensor).
        power_mode: ``"per_step"`` spends a² every step; ``"budget"`` adds a first action entry
            ``f`` in [-1, 1] and spends the fraction ``(f + 1) / 2`` of the power left.
        weight: Power weighting Ω (nz, nz), symmetric PD; default :func:`power_weight` (1 on
            position rows, T² on velocity rows of position+velocity sensors).

    Action: ``Box(-1, 1, (d,), float32)`` with ``d`` the factor entries (+1 in budget mode).
    Features: power left / a² in budget mode, none per step.
    """

    name = "covariance"

    def __init__(
        self,
        power: float,
        structure: str = "full",
        power_mode: str = "per_step",
        weight: np.ndarray | None = None,
    ) -> None:
        self.power = check_power("power", power)
        self.structure = check_choice("structure", structure, STRUCTURES)
        self.power_mode = check_choice("power_mode", power_mode, POWER_MODES)
        self._weight = weight
        self.remaining = self.power
        self.last_sigma: np.ndarray | None = None

    def bind(self, system: LinearSystem, spec: EpisodeSpec) -> None:
        """Build the action map for ``system``'s stacked measurement."""
        if self._weight is None:
            weight = power_weight(system)
        else:
            weight = as_matrix("weight", self._weight)
            if weight.shape != (system.nz, system.nz):
                raise ValueError(
                    f"weight must be an (nz, nz) = ({system.nz}, {system.nz}) matrix matching the "
                    f"sensors' stacked measurement, got shape {weight.shape}"
                )
            check_psd("weight", weight, strict=True)
        if self.structure == "full":
            blocks = [slice(0, system.nz)]
        else:
            blocks = [system.sensor_slice(i) for i in range(system.M)]
        self.map = CovarianceMap(blocks, weight)
        self.weight = weight
        self._budget = self.power_mode == "budget"
        dim = self.map.size + int(self._budget)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(dim,), dtype=np.float32)
        self._row_sensor = system.row_sensor
        self._M = system.M
        n_feat = int(self._budget)
        self.feature_low = np.zeros(n_feat, dtype=np.float32)
        self.feature_high = np.ones(n_feat, dtype=np.float32)

    def reset(self) -> None:
        """Restore the full power."""
        self.remaining = self.power
        self.last_sigma = None
        self.last_power = 0.0

    def features(self) -> list[float]:
        """Power left / a² in budget mode."""
        return [self.remaining / self.power] if self._budget else []

    def action_to_sigma(self, action: Any) -> tuple[np.ndarray, float]:
        """Validate ``action`` and return ``(Σ, power spent)`` without changing the state."""
        a = np.asarray(action, dtype=np.float64) if _numeric(action) else None
        if a is None or a.shape != self.action_space.shape:
            raise ValueError(
                f"attacker action must be an array of shape {self.action_space.shape} in [-1, 1], "
                f"got {action!r}"
            )
        if not np.all(np.isfinite(a)):
            raise ValueError(f"attacker action must be finite (no NaN or inf), got {a.tolist()}")
        if np.any(np.abs(a) > 1.0 + 1e-6):
            raise ValueError(f"attacker action must lie in [-1, 1], got {a.tolist()}")
        if self._budget:
            spend = 0.5 * (float(np.clip(a[0], -1.0, 1.0)) + 1.0) * self.remaining
            entries = a[1:]
        else:
            spend, entries = self.power, a
        return self.map.to_sigma(np.clip(entries, -1.0, 1.0), spend), spend

    def sigma_to_action(self, sigma: np.ndarray, fraction: float | None = None) -> np.ndarray:
        """The action whose covariance is ``sigma`` (scaled to the power), float32.

        Args:
            sigma: (nz, nz) target bias covariance (its scale is ignored: the power sets it).
            fraction: Budget mode only: fraction of the power left to spend now (default 1).
        """
        entries = self.map.to_action(np.asarray(sigma, dtype=np.float64))
        if self._budget:
            f = 1.0 if fraction is None else float(fraction)
            entries = np.concatenate([[2.0 * f - 1.0], entries])
        return entries.astype(np.float32)

    def apply(self, action: Any) -> AttackEffect:
        """Spend power on the covariance the action maps to."""
        sigma, spend = self.action_to_sigma(action)
        self.remaining = max(self.remaining - spend, 0.0) if self._budget else self.power
        self.last_sigma, self.last_power = sigma, spend
        diag = np.diag(sigma) > 0.0
        attacked = sum(1 << int(i) for i in set(self._row_sensor[diag].tolist()))
        return AttackEffect(attacked=attacked, sigma=sigma)

    def info(self) -> dict[str, Any]:
        """Power spent this step and power left."""
        return {"power": float(self.last_power), "power_left": float(self.remaining)}

    # --- batched (see AttackModel; numpy or torch arrays of the backend ``xp``) -------------
    batch_backends = ("numpy", "torch")

    def batch_reset(self, batch: int, where: Any = None) -> None:
        """Restore the full power of the members ``where``."""
        xp = self.xp
        if where is None:
            self.b_remaining = xp.full(batch, self.power, dtype=xp.float64)
            self.b_power = xp.zeros(batch)
        else:
            self.b_remaining[where] = self.power
            self.b_power[where] = 0.0

    def batch_features(self) -> Any:
        """(B, 1) power left / a² in budget mode, (B, 0) per step."""
        if self._budget:
            return (self.b_remaining / self.power)[:, None]
        return self.xp.zeros((self.b_remaining.shape[0], 0))

    def batch_apply(self, actions: Any) -> tuple[Any, Any]:
        """Map (B, d) actions to covariances, spending power as :meth:`apply` does."""
        xp = self.xp
        a = xp.astype(actions, xp.float64)  # checked by the vector env (shape, finite, in Box)
        a = xp.clip(a, -1.0, 1.0)
        if self._budget:
            spend = 0.5 * (a[:, 0] + 1.0) * self.b_remaining
            entries = a[:, 1:]
            self.b_remaining = xp.maximum(self.b_remaining - spend, 0.0)
        else:
            spend, entries = xp.full(a.shape[0], self.power, dtype=xp.float64), a
        self.b_power = xp.copy(spend)
        sigma = self.map.to_sigma_batch(entries, spend)
        rows = xp.diagonal(sigma) > 0.0  # (B, nz)
        # a sensor is attacked when any of its rows carries bias
        owner = np.zeros((self._row_sensor.size, self._M))
        owner[np.arange(self._row_sensor.size), self._row_sensor] = 1.0
        attacked = xp.astype(rows, xp.float64) @ xp.asarray(owner) > 0.0
        return (mask_array_to_bits(attacked) if xp is NUMPY else attacked), sigma

    def batch_info(self) -> dict[str, Any]:
        """Batched :meth:`info`."""
        return {"power": self.xp.copy(self.b_power), "power_left": self.xp.copy(self.b_remaining)}


def _numeric(action: Any) -> bool:
    try:
        np.asarray(action, dtype=np.float64)
    except (TypeError, ValueError):
        return False
    return action is not None
