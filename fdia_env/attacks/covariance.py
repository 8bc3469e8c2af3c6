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
from fdia_env.attacks.base import AttackModel, check_space, mask_array_to_bits, mask_to_bits
from fdia_env.backend import NUMPY, ONE, Backend, namespace
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
        """Σ with ``tr(Ω Σ) = power`` from (size,) factor entries (one :meth:`to_sigma_batch`)."""
        return self.to_sigma_batch(np.asarray(entries, dtype=np.float64), power)

    def to_sigma_batch(self, entries: Any, power: Any) -> Any:
        """(B, nz, nz) covariances with ``tr(Ω Σ) = power`` from (B, size) entries, (B,) powers.

        numpy arrays or torch tensors (:mod:`fdia_env.backend`). One member's (size,) entries
        and scalar power (the batch of one, :mod:`fdia_env.backend.one`) give its (nz, nz) Σ.
        """
        if entries.ndim == 1:  # one member: the batch of one
            return self.to_sigma_batch(entries[None], np.array([float(power)]))[0]
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
        self._b_xp = None  # the backend of the cached constant (see batch_reset)
        n_feat = int(self._budget)
        self.feature_low = np.zeros(n_feat, dtype=np.float32)
        self.feature_high = np.ones(n_feat, dtype=np.float32)

    @property
    def remaining(self) -> float:
        """The power left of the single env (member 0 of the batch)."""
        return float(self.xp.member(self.b_remaining, 0))

    def action_to_sigma(self, action: Any) -> tuple[np.ndarray, float]:
        """Validate ``action`` and return ``(Σ, power spent)`` without changing the state.

        The power left is the single env's (the full power before its first reset).
        """
        action = check_space(self.action_space, action, "attacker")
        remaining = self.remaining if hasattr(self, "b_remaining") else self.power
        a = np.clip(np.asarray(action, dtype=np.float64), -1.0, 1.0)
        spend, entries = self._spend(ONE, a, remaining)
        return self.map.to_sigma(entries, spend), float(spend)

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

    # --- batched (see AttackModel; numpy or torch arrays of the backend ``xp``) -------------
    batch_backends = ("numpy", "torch")

    def batch_reset(self, batch: int, where: Any = None) -> None:
        """Restore the full power of the members ``where``."""
        xp = self.xp
        if where is None:
            self._batch = batch
            self.b_remaining = xp.full(batch, self.power, dtype=xp.float64)
            self.b_power = xp.zeros(batch)
            if self._b_xp is not xp:  # the backend's constant, once per backend change
                # owner[row, sensor] = 1: a sensor is attacked when any of its rows has bias
                owner = np.zeros((self._row_sensor.size, self._M))
                owner[np.arange(self._row_sensor.size), self._row_sensor] = 1.0
                self._b_owner, self._b_xp = xp.asarray(owner), xp
        else:
            self.b_remaining[where] = self.power
            self.b_power[where] = 0.0

    def batch_features(self) -> Any:
        """(B, 1) power left / a² in budget mode, (B, 0) per step."""
        if self._budget:
            return self.xp.col(self.b_remaining / self.power)
        return self.xp.zeros((self._batch, 0))

    def _spend(self, xp: Backend, a: Any, remaining: Any) -> tuple[Any, Any]:
        """(B,) power spent and (B, size) factor entries of clipped (B, d) actions."""
        if self._budget:
            return 0.5 * (a[..., 0] + 1.0) * remaining, a[..., 1:]
        return xp.full(self._batch, self.power, dtype=xp.float64), a

    def batch_apply(self, actions: Any) -> tuple[Any, Any]:
        """Map (B, d) actions to covariances, spending power (the budget mode's fraction)."""
        xp = self.xp
        a = xp.astype(actions, xp.float64)  # checked by the env (shape, finite, in Box)
        spend, entries = self._spend(xp, xp.clip(a, -1.0, 1.0), self.b_remaining)
        if self._budget:
            self.b_remaining = xp.maximum(self.b_remaining - spend, 0.0)
        self.b_power = xp.copy(spend)
        sigma = self.map.to_sigma_batch(entries, spend)
        rows = xp.diagonal(sigma) > 0.0  # (B, nz)
        attacked = xp.astype(rows, xp.float64) @ self._b_owner > 0.0  # (B, M)
        if xp is ONE:
            return mask_to_bits(attacked), sigma
        return (mask_array_to_bits(attacked) if xp is NUMPY else attacked), sigma

    def batch_info(self) -> dict[str, Any]:
        """``power`` spent this step and ``power_left``."""
        return {"power": self.xp.copy(self.b_power), "power_left": self.xp.copy(self.b_remaining)}
