"""The sensor-selection game's payoff (docs/math.md §5) in factorised form.

Both players pick a non-empty sensor subset, in :func:`fdia_env.attacks.subsets.subsets` order.
The defender's filter runs in steady state on its subset D (gain ``W_D``, zero columns for the
sensors it ignores); the attacker spends power a² on its subset A with a fixed rule, so its bias
covariance is rank one, ``Σ_A = a² u_A u_A'``; only the biases on A ∩ D reach the filter:

    L[D, A] = tr(P_D + W_D Σ_{A∩D} W_D') = tr P_D + ⟨W_D' W_D, Σ_A⟩

(``W_D' W_D`` is already zero outside D × D, which restricts Σ_A to A ∩ D). The whole matrix is
therefore one (m, nz²) × (nz², n) product, and the best responses the double oracle needs are
linear in a mixed opponent's expected ``Σ`` or expected ``W' W``.

Allocation rules (docs/math.md §2.2), for scalar sensors with noise variance ``σ_i² = R_i``:

- ``"independent"`` (Prop. 2): all power on the smallest-σ sensor of A (ties: the lowest index),
  ``u_A = e_i``.
- ``"dependent"`` (Prop. 3): correlation 1 over A, ``σ_b,i = c_i a / ||c||``,
  ``c_i = (1/σ_i²) / Σ_{j∈A} 1/σ_j²``, i.e. ``u_A ∝ (1/σ_i²)_{i∈A}``.

Both rules are the literature's for position sensors (identical ``H_i``), where the gain columns
are proportional to 1/σ_i². For scalar sensors with different ``H_i`` they are applied as stated
(by σ_i alone) and are then a fixed rule, not necessarily the trace-optimal attack; sensors with
more than one measurement component are rejected.

>>> L = payoff_matrix("ch5-game")
>>> L.shape, round(float(L[0, 0]), 4), round(float(L[4, 1]), 4)
((7, 7), 25.3906, 3.7479)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from baselines._inputs import resolve_system
from fdia_env._validation import check_choice, check_positive
from fdia_env.attacks.subset import (
    ALLOCATIONS,
    allocation_covariance,
    attack_directions,
    sensor_sigmas,
)
from fdia_env.attacks.subsets import game_sizes, subset_count, subsets
from fdia_env.kalman import steady_state, steady_state_iterate
from fdia_env.scenarios import Scenario, scenario_default
from fdia_env.systems import LinearSystem, check_system

# The allocation rules live with the env's attack model (one implementation for both):
attack_covariance = allocation_covariance
__all__ = ["ALLOCATIONS", "attack_covariance", "attack_directions", "sensor_sigmas"]

# payoff_matrix refuses larger games: M = 14 is already a 2 GiB matrix.
MAX_MATRIX_SENSORS = 13

# Up to this many subsets (M ≤ 6) the steady states come from the cached per-subset DARE solve;
# above it from one batched fixed-point iteration (both agree to ~1e-15 relative).
_DARE_MAX_SUBSETS = 63


def subset_masks(
    M: int, max_subset_size: int | None = None, player: str = "attacker"
) -> np.ndarray:
    """Boolean masks of a player's subsets (:func:`~fdia_env.attacks.subsets.game_subsets`).

    ``max_subset_size=None``: all 2^M − 1 subsets (M ≤ 20); else the subsets of the game with
    that k (at most 2^20 of them).
    """
    if max_subset_size is None and M > 20:
        raise ValueError(
            f"M must be <= 20 for an explicit list of subsets, got {M}; pass max_subset_size"
        )
    lo, hi = game_sizes(M, max_subset_size, player)
    if subset_count(M, hi, lo) > 2**20:
        raise ValueError(
            f"max_subset_size={max_subset_size} gives the {player} "
            f"{subset_count(M, hi, lo):,} subsets of {M} sensors; at most 2**20 are supported"
        )
    subs = subsets(M, max_size=hi, min_size=lo)
    masks = np.zeros((len(subs), M), dtype=bool)
    for row, s in enumerate(subs):
        masks[row, list(s)] = True
    return masks


def subset_steady_states(system: LinearSystem, masks: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Steady-state ``tr P[k|k]`` (k,) and gain ``W`` (k, n, nz) of each defender subset.

    Per-subset DAREs (cached) for few subsets or a large state (n ≥ 32, where one batched
    fixed-point iteration over hundreds of subsets costs more); otherwise the batched iteration.
    """
    masks = np.asarray(masks, dtype=bool)
    if len(masks) <= _DARE_MAX_SUBSETS or system.n >= 32:
        states = [steady_state(system, m) for m in masks]
        P = np.stack([s[1] for s in states])
        W = np.stack([s[2] for s in states])
    else:
        _, P, W = steady_state_iterate(system, masks)
    return np.trace(P, axis1=-2, axis2=-1), W


@dataclass(frozen=True, eq=False)
class SensorGame:
    """The game's ingredients for every subset, from which any block of L is a matrix product.

    Attributes:
        system: The system (scalar sensors).
        power: Attack power a².
        allocation: ``"independent"`` or ``"dependent"``.
        max_subset_size: None (every non-empty subset for both players) or k: the attacker's
            subsets of at most k sensors and the defender's that leave out at most k
            (:func:`~fdia_env.attacks.subsets.game_sizes`), as in ``sensor_game_v0``.
        M: Number of sensors (this and the fields below are derived in ``__post_init__``);
            ``size = 2^M − 1`` strategies per player (the defender's count with
            ``max_subset_size``; ``attacker_size`` the attacker's).
        masks: (size, M) the defender's subsets in size-then-lexicographic order.
        attacker_masks: (attacker_size, M) the attacker's subsets (``masks`` itself when both
            players have every subset).
        trace_P: (size,) ``tr P_D``, steady-state filtered covariance of each defender subset.
        W: (size, n, M) steady-state gain of each defender subset (zero columns outside D).
        U: (attacker_size, M) attack direction of each attacker subset, ``Σ_A = a² u_A u_A'``.
    """

    system: LinearSystem
    power: float
    allocation: str = "independent"
    max_subset_size: int | None = None
    M: int = field(init=False)
    size: int = field(init=False)
    attacker_size: int = field(init=False)
    masks: np.ndarray = field(init=False, repr=False)
    attacker_masks: np.ndarray = field(init=False, repr=False)
    trace_P: np.ndarray = field(init=False, repr=False)
    W: np.ndarray = field(init=False, repr=False)
    U: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        check_system(self.system)
        power = check_positive("power", self.power)
        check_choice("allocation", self.allocation, ALLOCATIONS)
        sensor_sigmas(self.system)
        k = self.max_subset_size
        masks = subset_masks(self.system.M, k, "defender")
        attacker_masks = masks if k is None else subset_masks(self.system.M, k, "attacker")
        trace_P, W = subset_steady_states(self.system, masks)
        U = attack_directions(self.system, attacker_masks, self.allocation)
        for name, value in (
            ("power", power),
            ("M", self.system.M),
            ("size", len(masks)),
            ("attacker_size", len(attacker_masks)),
            ("masks", masks),
            ("attacker_masks", attacker_masks),
            ("trace_P", trace_P),
            ("W", W),
            ("U", U),
        ):
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    def payoff(self, rows: np.ndarray | None = None, cols: np.ndarray | None = None) -> np.ndarray:
        """The block ``L[rows, cols]`` (defender subsets × attacker subsets; default all).

        ``L = tr P_D 1' + G Σ'`` with ``G[D] = vec(W_D' W_D)`` and ``Σ[A] = vec(a² u_A u_A')``:
        one (r, M²) × (M², c) matrix product.
        """
        rows = np.arange(self.size) if rows is None else np.asarray(rows, dtype=np.intp)
        cols = np.arange(self.attacker_size) if cols is None else np.asarray(cols, dtype=np.intp)
        W = self.W[rows]
        G = np.einsum("dki,dkj->dij", W, W).reshape(len(rows), -1)  # vec(W_D' W_D)
        u = self.U[cols]
        sigma = self.power * np.einsum("ai,aj->aij", u, u).reshape(len(cols), -1)  # vec(Σ_A)
        return self.trace_P[rows, None] + G @ sigma.T

    def defender_values(self, cols: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(size,) expected payoff of every defender subset against the attacker mix ``y``.

        Linear in the mix: ``tr P_D + tr(W_D Σ̄ W_D')`` with ``Σ̄ = Σ_A y_A Σ_A``.
        """
        u = self.U[np.asarray(cols, dtype=np.intp)]
        sigma_bar = self.power * (u.T * np.asarray(y)) @ u  # a² Σ_A y_A u_A u_A'
        WS = (self.W.reshape(-1, self.M) @ sigma_bar).reshape(self.W.shape)
        return self.trace_P + np.einsum("dkj,dkj->d", WS, self.W)  # tr(W Σ̄ W')

    def attacker_values(self, rows: np.ndarray, x: np.ndarray) -> np.ndarray:
        """(attacker_size,) expected payoff of every attacker subset against the defender mix ``x``.

        Linear in the mix: ``Σ_D x_D tr P_D + a² u_A' Ḡ u_A`` with ``Ḡ = Σ_D x_D W_D' W_D``.
        """
        rows = np.asarray(rows, dtype=np.intp)
        x = np.asarray(x)
        W = self.W[rows]
        G_bar = np.einsum("d,dki,dkj->ij", x, W, W)
        return float(x @ self.trace_P[rows]) + self.power * np.einsum(
            "ai,ij,aj->a", self.U, G_bar, self.U
        )


def make_game(
    system_or_scenario: str | Scenario | LinearSystem,
    power: float | None = None,
    allocation: str = "independent",
    max_subset_size: int | None = None,
) -> SensorGame:
    """Build a :class:`SensorGame`; ``power`` defaults to the scenario's (100 for ch5-game).

    ``max_subset_size`` defaults to the scenario's (``extra["max_subset_size"]``: the power-grid
    presets), else every subset.
    """
    sc = resolve_system(system_or_scenario)
    power = scenario_default(sc, "power", power)
    if max_subset_size is None:
        max_subset_size = sc.extra.get("max_subset_size")
    return SensorGame(sc.system, power, allocation, max_subset_size)


def payoff_matrix(
    system_or_scenario: str | Scenario | LinearSystem,
    power: float | None = None,
    allocation: str = "independent",
    max_subset_size: int | None = None,
) -> np.ndarray:
    """The full (2^M − 1) × (2^M − 1) payoff ``L[D, A] = tr(P_D + W_D Σ_{A∩D} W_D')``.

    Rows are the defender's subsets, columns the attacker's, both in
    :func:`~fdia_env.attacks.subsets.subsets` order (z1, z2, z3, z1z2, z1z3, z2z3, z1z2z3 for
    M = 3). The filter of each row is in steady state at the attack time.

    Args:
        system_or_scenario: Preset name, :class:`~fdia_env.scenarios.Scenario` or system, with
            scalar sensors.
        power: Attack power a² (> 0); defaults to the scenario's.
        allocation: ``"independent"`` (Prop. 2) or ``"dependent"`` (Prop. 3).
        max_subset_size: k of the restricted strategy sets (default the scenario's, else
            every subset): rows the defender's subsets leaving out at most k sensors, columns
            the attacker's subsets of at most k sensors.

    Returns:
        (m, m) payoff to the attacker (the defender minimises it), m = 2^M − 1 (with k: the
        two players' subset counts).

    Raises:
        ValueError: Naming the parameter: power ≤ 0 or missing, an unknown allocation or
            scenario, a sensor with more than one measurement component, M > 13 (use
            :func:`~baselines.game.double_oracle.solve_double_oracle`).
    """
    sc = resolve_system(system_or_scenario)
    k = max_subset_size if max_subset_size is not None else sc.extra.get("max_subset_size")
    if k is None and sc.system.M > MAX_MATRIX_SENSORS:
        size = 2**sc.system.M - 1
        raise ValueError(
            f"payoff_matrix builds the full {size:,} × {size:,} matrix for M = {sc.system.M} "
            f"sensors ({size**2 * 8 / 2**30:.0f} GiB); M must be <= {MAX_MATRIX_SENSORS}. "
            "Use solve_double_oracle, which never builds it, or pass max_subset_size"
        )
    if k is not None:
        rows = subset_count(sc.system.M, *game_sizes(sc.system.M, k, "defender")[::-1])
        cols = subset_count(sc.system.M, *game_sizes(sc.system.M, k, "attacker")[::-1])
        if rows * cols > 2**28:
            raise ValueError(
                f"payoff_matrix with max_subset_size={k} is {rows:,} × {cols:,} "
                f"({rows * cols * 8 / 2**30:.0f} GiB); use solve_double_oracle"
            )
    return make_game(sc, power, allocation, k).payoff()
